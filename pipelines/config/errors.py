"""One-line messages for configuration errors (exit code 2, no traceback)."""

from __future__ import annotations

import dataclasses
import re

from hydra.errors import MissingConfigException, OverrideParseException
from omegaconf.errors import (ConfigAttributeError, ConfigKeyError, ConfigTypeError, OmegaConfBaseException,
                              ValidationError)

from . import plugins
from .fields import ConfigError, override_key

EXIT_CONFIG = 2
EXIT_CODES = {"completed": 0, "failed": 1, "unstable": 3, "interrupted": 130,
              "preempted": 75}  # of a run, by status (preempted: a checkpoint left; EX_TEMPFAIL)


def _first_line(text: object) -> str:
    return next((ln.strip() for ln in str(text).splitlines() if ln.strip()), str(text))


def _accepted_keys(object_type) -> str:
    if object_type is not None and dataclasses.is_dataclass(object_type):
        return ", ".join(f.name for f in dataclasses.fields(object_type))
    return ""


def _inner_list(key: str, value: str, cause) -> tuple[str, str] | None:
    """A mapping merged into a mapping node (a shape, a collider) that gives
    one of its list keys a mapping (``shape={type: compound, parts: {...}}``):
    that key and its value, not the whole mapping's."""
    import yaml

    from .colliders import ColliderConfig
    from .schema import group_fields
    from .shapes import ShapeConfig

    ref = re.search(r"reference_type=(\w+)", str(cause))
    try:
        given = yaml.safe_load(value)
    except yaml.YAMLError:
        return None
    cls = next((c for c in [ShapeConfig, ColliderConfig, *group_fields()] if ref and c.__name__ == ref.group(1)),
               None)
    if cls is None or not isinstance(given, dict):
        return None
    for f in dataclasses.fields(cls):
        if isinstance(given.get(f.name), dict) and "List" in str(f.type):
            return f"{override_key(key)}.{f.name}", yaml.safe_dump(
                given[f.name], default_flow_style=True, width=10**6).strip()
    return None


def _other_kind(key: str, cause) -> str | None:
    """An unknown key of a group's option that another option of the group
    takes (``integrator.newton_max`` with integrator=explicit), or of a body's
    own material that another model takes: which option or model, and how to
    choose it (None: no option takes the key, or the node is of no group)."""
    from .physics import GROUPS, MATERIAL

    parent, _, k = key.rpartition(".")
    family = GROUPS.get(parent)
    if family is not None:
        kind = next((n for n, c in family.variants.items() if c is cause.object_type), None)
        return family.elsewhere(parent, k, kind) if kind else None
    if re.fullmatch(r"scene\.bodies\[\d+\]\.material", parent):
        node = getattr(cause, "parent_node", None)
        model = node.get("model") if node is not None and hasattr(node, "get") else None
        if isinstance(model, str) and model in MATERIAL.variants:
            return MATERIAL.elsewhere(parent, k, model) or (f"{MATERIAL.unused.format(kind=model)}; accepted: "
                                                            f"{', '.join(MATERIAL.names(model))}")
        if k == MATERIAL.key:
            return (f"unknown key: the body has no material of its own (it takes the material group's); accepted: "
                    f"the body's own, given whole as {override_key(parent)}={{model: <model>, ...}}, or the group's "
                    f"option, material=<model> ({', '.join(MATERIAL.variants)})")
        owner = [n for n in MATERIAL.variants if k in MATERIAL.names(n)]
        if owner:
            return (f"unknown key: the body has no material of its own (it takes the material group's); accepted: "
                    f"the body's own, given whole as {MATERIAL.selector(parent, owner[0])}, or the group's option "
                    f"that takes {k}, {MATERIAL.selector('material', owner[0])} material.{k}=...")
    return None


def describe(exc: BaseException) -> str | None:
    """A one-line description of a configuration error, or None if ``exc`` is
    not one."""
    if isinstance(exc, ConfigError):
        return str(exc)
    if isinstance(exc, MissingConfigException):
        missing = exc.missing_cfg_file or ""
        if "/" in missing and exc.options is not None:
            group, option = missing.rsplit("/", 1)
            options = sorted(exc.options)
            more = f", or {plugins.dotted(group)}" if group in plugins.GROUPS else ""
            return f"{group}={option}: unknown option; accepted: {', '.join(options)}{more}"
        return _first_line(exc)
    if isinstance(exc, OverrideParseException):
        return f"cannot parse the command line: {_first_line(exc)}"
    merging = re.match(r"Error merging override ([^=]+)=(.*)", _first_line(exc))
    if merging and isinstance(exc.__cause__, ConfigTypeError):
        key, value = merging.groups()
        kind = {"ListConfig": "a list", "DictConfig": "a mapping"}
        m = re.match(r"Cannot merge (\w+) with (\w+)", _first_line(exc.__cause__))
        if m:
            key, value = _inner_list(key, value, exc.__cause__) or (key, value)
            return (f"{key}: {value} is {kind.get(m.group(1), m.group(1))}; accepted: "
                    f"{kind.get(m.group(2), m.group(2))}")
    cause = exc.__cause__ if exc.__cause__ is not None else exc
    located = re.search(r"\n\s*full_key: (\S+)\n\s*reference_type=(\S+)", str(cause))
    if located and not isinstance(cause, (ConfigKeyError, ConfigAttributeError, ValidationError)):
        key, kind = located.groups()
        return f"{key}: cannot take this value ({_first_line(cause)}); accepted: {kind}"
    if isinstance(cause, (ConfigKeyError, ConfigAttributeError)):
        key = cause.full_key or getattr(cause, "key", "")
        other = _other_kind(key, cause)
        if other:
            return f"{key}: {other}"
        accepted = _accepted_keys(cause.object_type)
        return f"{key}: unknown key" + (f"; accepted: {accepted}" if accepted else "")
    if isinstance(cause, ValidationError):
        key = cause.full_key or ""
        msg = _first_line(cause.msg if hasattr(cause, "msg") else cause)
        m = re.match(r"Value '(.*)' of type '.*' could not be converted to (\w+)", msg)
        if m:
            kind = {"Float": "a number", "Integer": "an integer", "Boolean": "true or false"}
            text = kind.get(m.group(2), m.group(2))
            return f"{key}: {m.group(1)!r} is not {text}; accepted: {text}"
        m = re.match(r"Value '(.*)' is not a valid bool", msg)
        if m:
            return f"{key}: {m.group(1)!r} is not true or false; accepted: true, false"
        if msg.startswith("Invalid type assigned") and re.search(r"\[\d+\]$", key):
            return (f"{key}: no such element, the index is past the end of the list; accepted: an existing "
                    f"element's index, or the whole list")
        return f"{key}: {msg}"
    if isinstance(cause, OmegaConfBaseException):
        return _first_line(cause)
    if type(exc).__module__.startswith("hydra"):
        msg = _first_line(exc)
        m = re.match(r"Could not override '([^']+)'", msg)
        if m:
            return f"{m.group(1)}: unknown key"
        return msg
    return None
