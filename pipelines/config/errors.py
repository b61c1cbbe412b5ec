"""One-line messages for configuration errors (exit code 2, no traceback)."""

from __future__ import annotations

import dataclasses
import re

from hydra.errors import MissingConfigException, OverrideParseException
from omegaconf.errors import (ConfigAttributeError, ConfigKeyError, ConfigTypeError, OmegaConfBaseException,
                              ValidationError)

from .fields import ConfigError

EXIT_CONFIG = 2
EXIT_CODES = {"completed": 0, "failed": 1, "unstable": 3, "interrupted": 130}  # of a run, by status


def _first_line(text: str) -> str:
    return next((ln.strip() for ln in str(text).splitlines() if ln.strip()), str(text))


def _accepted_keys(object_type) -> str:
    if object_type is not None and dataclasses.is_dataclass(object_type):
        return ", ".join(f.name for f in dataclasses.fields(object_type))
    return ""


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
            return f"{group}={option}: unknown option; accepted: {', '.join(options)}"
        return _first_line(exc)
    if isinstance(exc, OverrideParseException):
        return f"cannot parse the command line: {_first_line(exc)}"
    merging = re.match(r"Error merging override ([^=]+)=(.*)", _first_line(exc))
    if merging and isinstance(exc.__cause__, ConfigTypeError):
        key, value = merging.groups()
        kind = {"ListConfig": "a list", "DictConfig": "a mapping"}
        m = re.match(r"Cannot merge (\w+) with (\w+)", _first_line(exc.__cause__))
        if m:
            return (f"{key}: {value} is {kind.get(m.group(1), m.group(1))}; accepted: "
                    f"{kind.get(m.group(2), m.group(2))}")
    cause = exc.__cause__ if exc.__cause__ is not None else exc
    located = re.search(r"\n\s*full_key: (\S+)\n\s*reference_type=(\S+)", str(cause))
    if located and not isinstance(cause, (ConfigKeyError, ConfigAttributeError, ValidationError)):
        key, kind = located.groups()
        return f"{key}: cannot take this value ({_first_line(cause)}); accepted: {kind}"
    if isinstance(cause, (ConfigKeyError, ConfigAttributeError)):
        key = cause.full_key or getattr(cause, "key", "")
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
