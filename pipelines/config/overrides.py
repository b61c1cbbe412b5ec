"""Checks of the command line's overrides that the composed config cannot
make: a config group given something other than an option's name, a
number given to a true-or-false key (OmegaConf reads 2 as true), a kind
changed by its key (``material.model=fluid``) that keeps the keys of the
kind it replaces; and the replacement of a body's own material, a shape or
a collider by an inline mapping."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from typing import Any

from omegaconf import OmegaConf
from omegaconf.nodes import BooleanNode

from .fields import ConfigError

GROUPS = ("scheme", "integrator", "kernel", "material", "scene", "scale", "experiment")
INLINE_MATERIAL = re.compile(r"^(scene\.bodies\.\d+\.material)=\s*\{")
SHAPE = r"scene\.(?:bodies\.\d+\.shape|regions\.\d+\.select|loads\.\d+\.select)"
PART = SHAPE + r"(?:\.parts\.\d+)+"  # a compound's part: an untyped mapping in a list
COLLIDER = r"scene\.colliders\.\d+"
INLINE_KIND = re.compile(rf"^({PART}|{SHAPE}|{COLLIDER})=\s*\{{")


def _reset(key: str) -> str:
    """The override that empties a typed shape or collider node: every key
    but the kind back to its default (null where the kinds differ)."""
    from .colliders import ColliderConfig
    from .fields import default_of
    from .shapes import ShapeConfig

    flat = ColliderConfig if re.fullmatch(COLLIDER, key) else ShapeConfig
    items = [(f.name, default_of(f)) for f in dataclasses.fields(flat) if f.name != "type"]

    def text(v) -> str:  # Hydra's grammar: null, true, inf, quoted text
        return repr(v) if isinstance(v, float) and not math.isfinite(v) else json.dumps(v)

    return f"{key}={{{', '.join(f'{k}: {text(v)}' for k, v in items)}}}"


def _mapping_with(arg: str, kind_key: str) -> bool:
    """Whether the override's value is a mapping with ``kind_key``."""
    parsed = _parse([arg])
    return bool(parsed) and not parsed[0].is_sweep_override() and isinstance(parsed[0].value(), dict) \
        and kind_key in parsed[0].value()


def replace_inline_mappings(argv: list[str]) -> list[str]:
    """A mapping that names its kind replaces what the scene has there: Hydra
    would merge it into the scene's (keeping the keys of the kind it
    replaces, so that ``scene.bodies.0.shape={type: compound, parts: [...]}``
    kept the sphere's centre and radius). ``scene.bodies.<i>.material={...}``:
    the body's material is first set to null; a shape (``...shape={type: ...}``,
    ``...select={type: ...}``) or a collider (``scene.colliders.<i>={type:
    ...}``): first emptied (every key but the kind at its default); a
    compound's part (``...parts.<j>={type: ...}``): first set to null. A
    mapping without its kind still merges (``...shape={radius: 0.2}``)."""
    out = []
    for arg in argv:
        m = INLINE_MATERIAL.match(arg)
        if m:
            out.append(f"{m.group(1)}=null")
        m = INLINE_KIND.match(arg)
        if m and _mapping_with(arg, "type"):
            key = m.group(1)
            out.append(f"{key}=null" if re.fullmatch(PART, key) else _reset(key))
        out.append(arg)
    return out


def _full(key: str) -> str:
    """``scene.bodies.0.shape`` -> ``scene.bodies[0].shape`` (the keys of the messages)."""
    return re.sub(r"\.(\d+)(?=\.|$)", r"[\1]", key)


def _kind_node(path: str):
    """The family whose kind key ends ``path`` (``material.model``,
    ``scene.bodies.0.shape.type``), and the node's path; None if none."""
    from .colliders import COLLIDERS
    from .physics import GROUPS as FAMILIES, MATERIAL
    from .shapes import SHAPES

    node, _, last = path.rpartition(".")
    for pattern, family in [*((re.escape(g), f) for g, f in FAMILIES.items()),
                            (r"scene\.bodies\.\d+\.material", MATERIAL), (PART, SHAPES), (SHAPE, SHAPES),
                            (COLLIDER, COLLIDERS)]:
        if re.fullmatch(pattern, node) and last == family.key:
            return family, node
    return None


def check_kinds(cfg, overrides: list[str]) -> None:
    """A kind chosen by its key (``material.model=fluid``,
    ``scene.bodies.0.shape.type=compound``) keeps the keys of the option or
    shape it replaces; refuse one that keeps keys the new kind does not use
    (not set by the command line itself: those are refused as such), naming
    how to choose the kind whole."""
    parsed = [o for o in _parse(overrides) if not o.is_delete() and not o.is_sweep_override()]
    given = {o.key_or_group.lstrip("+~") for o in parsed}
    for o in parsed:
        found = _kind_node(o.key_or_group)
        if found is None:
            continue
        family, node = found
        try:
            values: Any = OmegaConf.to_container(OmegaConf.select(cfg, node), resolve=False)
        except Exception:  # noqa: BLE001 - not a mapping: refused by the config's checks
            continue
        kind = values.get(family.key) if isinstance(values, dict) else None
        if not isinstance(kind, str) or kind not in family.variants:  # refused by the config's checks
            continue
        names = family.names(kind)
        kept = [k for k, v in values.items() if k not in names and (v is not None or not family.flat_node)
                and f"{node}.{k}" not in given]
        if not kept:
            continue
        whole = (f"choose the option with the group, {family.selector(node, kind)}" if node == family.name else
                 f"the whole {family.name} given with its {family.key}, {family.selector(node, kind)}, which "
                 f"replaces the scene's")
        raise ConfigError(f"{_full(node)}.{family.key}",
                          f"{kind} set by key keeps {', '.join(kept)} of the {family.name} it replaces, "
                          f"{family.unused.format(kind=kind)}; accepted: {whole} (its keys: {', '.join(names)})")


def _parse(overrides: list[str]) -> list:
    """The overrides Hydra's parser reads (options, flags and what it cannot
    parse left out: Hydra reports those)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    out = []
    for text in overrides:
        if text.startswith(("-", "hydra")):
            continue
        try:
            out += parser.parse_overrides([text])
        except Exception:  # noqa: BLE001 - Hydra says what it cannot parse
            continue
    return out


def check_groups(overrides: list[str]) -> None:
    """A config group's override names options (``scene=1`` or
    ``scheme=null`` would fail inside Hydra without naming the group)."""
    from .schema import options

    for o in _parse(overrides):
        group = o.key_or_group.split("@")[0]
        if group not in GROUPS or o.is_delete() or o.package is not None:
            continue
        value = o.value()
        if o.is_sweep_override():  # -m scene=a,b: each choice (a glob names options; a range none)
            if type(value).__name__ == "Glob":
                continue
            names = list(getattr(value, "list", None) or [None])
        else:
            names = value if isinstance(value, list) else [value]
        if not all(isinstance(v, str) and v for v in names):
            accepted = ", ".join(options(group)) or "an option's name"
            given = (o.input_line or "").split("=", 1)[-1] if o.is_sweep_override() else o.get_value_element_as_str()
            raise ConfigError(group, f"{given!r} is not an option's name; accepted: {accepted}")


def check_stability_map(overrides: list[str]) -> None:
    """``stability_map`` is empty (null) until ``+experiment=stability`` fills
    it, and Hydra cannot merge a mapping or a key into an empty node (it
    failed with an internal message): without the experiment, an override of
    it is refused, naming the way in."""
    parsed = _parse(overrides)
    if any(o.key_or_group.lstrip("+~") == "experiment" and "stability" in str(o.value()) for o in parsed):
        return
    for o in parsed:
        if o.key_or_group.lstrip("+~").split(".")[0] == "stability_map" and not o.is_delete():
            raise ConfigError("stability_map", f"{o.input_line}: set by +experiment=stability, not on its own; "
                                               "accepted: -m +experiment=stability [stability_map.<key>=<value>]")


def check_literals(cfg, overrides: list[str]) -> None:
    """A true-or-false key given a number (OmegaConf converts 0 and 2 alike)."""
    for o in _parse(overrides):
        if o.is_delete() or o.is_sweep_override():
            continue
        value = o.value()
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        parent, _, last = o.key_or_group.rpartition(".")
        try:
            node = OmegaConf.select(cfg, parent) if parent else cfg
            child = node._get_node(int(last) if last.isdigit() else last) if node is not None else None
        except Exception:  # noqa: BLE001 - a key the composed config does not have: refused elsewhere
            continue
        if isinstance(child, BooleanNode):
            raise ConfigError(o.key_or_group, f"{value!r} is not true or false; accepted: true, false")
