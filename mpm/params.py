"""Declared parameter ranges for plain dataclasses.

A field made with :func:`param` carries its unit, its doc and its accepted
range (or accepted names); :func:`violations` lists the fields whose values fall outside. The
solver calls it before allocating anything, the pipeline turns each violation
into a one-line message naming the configuration key.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterator, Mapping


def param(default: Any, doc: str, *, gt=None, ge=None, lt=None, le=None, inf=False, choices=None):
    """A dataclass field with a documented, checked range (bounds may be None;
    ``inf``: +infinity is accepted; None values are not checked) or, for a
    name, the tuple of accepted ``choices``."""
    return dataclasses.field(
        default=default,
        metadata={"doc": doc, "gt": gt, "ge": ge, "lt": lt, "le": le, "inf": inf, "choices": choices},
    )


def accepted_range(name: str, meta: Mapping) -> str:
    """Human-readable range, e.g. ``-1 < nu < 0.5``."""
    lo = f"{meta['gt']} < " if meta.get("gt") is not None else (
        f"{meta['ge']} <= " if meta.get("ge") is not None else "")
    hi = f" < {meta['lt']}" if meta.get("lt") is not None else (
        f" <= {meta['le']}" if meta.get("le") is not None else "")
    text = f"{lo}{name}{hi}" if (lo or hi) else f"{name} finite"
    return text + (" (inf allowed)" if meta.get("inf") else "")


def in_range(value: float, meta: Mapping) -> bool:
    if value is None or math.isnan(value):
        return False
    if math.isinf(value) and not (meta.get("inf") and value > 0):
        return False
    if meta.get("gt") is not None and not value > meta["gt"]:
        return False
    if meta.get("ge") is not None and not value >= meta["ge"]:
        return False
    if meta.get("lt") is not None and not value < meta["lt"]:
        return False
    if meta.get("le") is not None and not value <= meta["le"]:
        return False
    return True


def violations(obj: Any) -> Iterator[tuple[str, Any, str]]:
    """Yield ``(field, value, accepted)`` for every ranged field out of range."""
    for f in dataclasses.fields(obj):
        meta = f.metadata
        if "doc" not in meta:
            continue
        if not any(meta.get(k) is not None for k in ("gt", "ge", "lt", "le")):
            continue
        value = getattr(obj, f.name)
        if value is None:
            continue
        try:
            ok = in_range(float(value), meta)
        except (TypeError, ValueError):
            ok = False
        if not ok:
            yield f.name, value, accepted_range(f.name, meta)


class UnknownName(KeyError, ValueError):
    """A name a registry does not hold; its message is one line naming the
    kind and the accepted names (a KeyError that prints without quotes)."""

    def __str__(self) -> str:
        return str(self.args[0])


class Names(dict):
    """A registry by name (``mpm.KERNELS``, ``mpm.SCHEMES``, ...): a dict whose
    missing key raises :class:`UnknownName` naming what is accepted."""

    def __init__(self, kind: str, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.kind = kind

    def __missing__(self, key):
        raise UnknownName(f"{self.kind} {key!r}; accepted: {', '.join(sorted(map(str, self)))}")


def instance_problem(value, cls, what: str, example: str) -> str | None:
    """Why ``value`` is not an instance of ``cls`` (None: it is): a class
    given for its instance, or another type."""
    return None if isinstance(value, cls) else refusal(value, what, example)


def refusal(value, what: str, example: str) -> str:
    """Why ``value`` is refused where ``what`` is accepted: a class given for
    its instance, nothing (None), or another type."""
    if isinstance(value, type):
        return f"the class {value.__name__}, not an instance; accepted: {what}, e.g. {example}"
    if value is None:
        return f"None; accepted: {what}, e.g. {example}"
    return f"{type(value).__name__} {value!r:.60}; accepted: {what}, e.g. {example}"
