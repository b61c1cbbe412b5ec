"""Checks of the command line's overrides that the composed config cannot
make: a config group given something other than an option's name, a
number given to a true-or-false key (OmegaConf reads 2 as true), and the
replacement of a body's own material by an inline mapping."""

from __future__ import annotations

import re

from omegaconf import OmegaConf
from omegaconf.nodes import BooleanNode

from .fields import ConfigError

GROUPS = ("scheme", "integrator", "kernel", "material", "scene", "scale", "experiment")
INLINE_MATERIAL = re.compile(r"^(scene\.bodies\.\d+\.material)=\s*\{")


def replace_inline_materials(argv: list[str]) -> list[str]:
    """``scene.bodies.<i>.material={...}`` replaces the body's material: Hydra
    would merge the mapping into a material the scene gives the body (keeping
    its keys, refusing new ones), so the body's material is first set to null."""
    out = []
    for arg in argv:
        m = INLINE_MATERIAL.match(arg)
        if m:
            out.append(f"{m.group(1)}=null")
        out.append(arg)
    return out


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
