"""How a config group is defined, and the checks derived from the definition.

Each group is one dataclass (one per option where the options differ); each
field carries its type, its default, its doc and what it accepts: the
solver's physics classes through :func:`mpm.params.param`, the settings of a
run through :func:`setting` (the same metadata plus list sizes and parsers).
:func:`check` reads a plain mapping against such a dataclass: it refuses
unknown keys, converts and checks every value from the field's type and
metadata, builds the dataclass and asks its ``problems()`` (the constraints
between fields). A :class:`Family` is a mapping whose kind (``type``,
``model`` or ``name``) picks the dataclass that defines its keys.

Mechanism: Hydra structured configs, with the checks read from the same
dataclasses, rather than pydantic or a second hand-written schema. Why:

* Hydra composes the run from dataclasses anyway: registered in its
  ConfigStore (:mod:`pipelines.config.schema`), they put every default into
  the composed config that a run records and hashes, and they refuse a
  misspelt key or a mistyped value while composing;
* the physics ranges are already declared once, on the solver's dataclasses
  (``mpm.params.param``); one checker that reads that metadata checks the
  physics and the run settings alike, with nothing restated;
* every message must be one line naming the full key, the value and what is
  accepted. The checker writes those lines from the metadata directly;
  pydantic (a ``TypeAdapter`` over the same dataclasses, a discriminated
  union, ``extra="forbid"``) would pick the variants and refuse unknown keys
  too, but its errors would have to be translated back into these lines
  through the same metadata, vectors sized by the scene's dimension would
  need the scene passed as validation context, and the run would depend on a
  second schema library beside Hydra's;
* OmegaConf 2.3 has no unions of dataclasses, so a group whose options
  differ (material, scheme, integrator) is one ConfigStore node per option,
  and a mapping whose kinds differ inside a scene (a shape, a collider) is
  typed by one flat dataclass derived from its family (:meth:`Family.flat`).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence, TypeVar

from omegaconf import OmegaConf

from mpm.params import accepted_range, in_range

BOUNDS = (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))


class ConfigError(ValueError):
    """A configuration value that cannot be used; ``key`` is its full path."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


def setting(default: Any, doc: str, *, gt=None, ge=None, lt=None, le=None, choices=None, size=None,
            nonempty: str | None = None, required: bool = False, parse: Callable | None = None,
            family: "Family | None" = None) -> Any:
    """A field of a run setting, like :func:`mpm.params.param` (doc, range,
    ``choices``) with: ``size`` the length of a list of numbers (``"dim"``:
    the scene's dimension; None: any); ``nonempty`` what an empty list is
    refused with; ``required``: null is refused (a field one kind of a family
    needs); ``parse(key, value, context)`` for a value no type states (an
    angle or three angles); ``family`` for a mapping whose kind picks its
    keys. A range is worded with the full key (``run.cfl > 0.0``)."""
    meta = {"doc": doc, "gt": gt, "ge": ge, "lt": lt, "le": le, "inf": False, "choices": choices,
            "size": size, "nonempty": nonempty, "required": required, "parse": parse, "family": family,
            "keyed": True}
    if isinstance(default, (list, dict)) or dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=functools.partial(copy.deepcopy, default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@dataclass
class Context:
    """What a value's check may depend on: the scene's dimension and the
    random generator of shape rotations (None: random rotations refused)."""

    dim: int = 3
    rng: Any = None


T = TypeVar("T")
N = TypeVar("N", int, float)


def given(v: T | None) -> T:
    """A required key's value (``setting(..., required=True)``): :func:`check` refused null for it."""
    assert v is not None
    return v


def coords(v: Sequence[float] | None) -> tuple[float, ...]:
    """A required list of numbers as the solver takes it (a tuple: what :func:`vector` made)."""
    return tuple(given(v))


def plain(node) -> Any:
    """A config node as plain Python values, interpolations resolved."""
    return OmegaConf.to_container(node, resolve=True) if OmegaConf.is_config(node) else node


@functools.cache
def hints(cls) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def unwrap(tp) -> tuple[bool, Any]:
    """(optional, the type without None)."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return True, rest[0] if len(rest) == 1 else Any
    return False, tp


def default_of(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return f.default


def describe_type(tp, meta: Mapping) -> str:
    """What a field accepts, in words (for docs and messages)."""
    optional, base = unwrap(tp)
    if meta.get("choices"):
        text = "one of " + ", ".join(map(str, meta["choices"]))
    elif base is bool:
        text = "true or false"
    elif base in (int, float):
        text = "an integer" if base is int else "a number"
    elif base is str:
        text = "text"
    elif typing.get_origin(base) in (list, tuple):
        size = meta.get("size")
        text = "a list" if size is None else f"a list of {'d' if size == 'dim' else size} numbers"
    elif dataclasses.is_dataclass(base) or meta.get("family"):
        text = "a mapping"
    else:
        text = "a value"
    return text + (", or null" if optional else "")


# ------------------------------------------------------------------ single values
def bounds(key: str, name: str, meta: Mapping) -> str:
    """The accepted range: ``run.cfl > 0.0, run.cfl <= 1.0`` for a run
    setting, the solver's wording ``0.0 < E`` for a physics parameter."""
    if not any(meta.get(b) is not None for b, _ in BOUNDS):
        return ""
    if meta.get("keyed"):
        return ", ".join(f"{key} {op} {meta[b]}" for b, op in BOUNDS if meta.get(b) is not None)
    return accepted_range(name, meta)


def number(key: str, value, kind: type[N] = float, meta: Mapping | None = None, name: str = "") -> N:
    """``value`` as ``kind`` (int or float), finite (or +inf where the field
    accepts it) and within the field's range."""
    meta = meta or {}
    if value is None:
        raise ConfigError(key, "missing; accepted: a number")
    try:
        if isinstance(value, bool) or (kind is int and float(value) != int(value)):
            raise ValueError
        v = kind(value)
    except (TypeError, ValueError, OverflowError):
        text = "an integer" if kind is int else "a number"
        accepted = bounds(key, name or key.rsplit(".", 1)[-1], meta)
        raise ConfigError(key, f"{value!r} is not {text}; accepted: {text}"
                               + (f", {accepted}" if accepted else "")) from None
    accepted = bounds(key, name or key.rsplit(".", 1)[-1], meta)
    if not math.isfinite(v) and not (meta.get("inf") and v == math.inf):
        raise ConfigError(key, f"{v} is not finite; accepted: a finite number" + (f", {accepted}" if accepted else ""))
    if accepted and not in_range(v, dict(meta)):
        raise ConfigError(key, f"{v} out of range; accepted: {accepted}")
    return v


def choice(key: str, value, accepted):
    if value not in accepted:
        raise ConfigError(key, f"{value!r} unknown; accepted: {', '.join(map(str, accepted))}")
    return value


def flag(key: str, value) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(key, f"{value!r} is not true or false; accepted: true, false")
    return value


def vector(key: str, value, n: int | None, meta: Mapping | None = None, name: str = "") -> tuple:
    """A list of ``n`` numbers (any number when None), each checked like a
    number of the field."""
    if not isinstance(value, (list, tuple)) or (n is not None and len(value) != n):
        raise ConfigError(key, f"{value!r}; accepted: a list of {'' if n is None else f'{n} '}numbers")
    return tuple(number(f"{key}[{i}]", v, float, meta, name) for i, v in enumerate(value))


def value(key: str, v, f: dataclasses.Field, tp, ctx: Context):
    """One field's value, converted and checked."""
    meta = f.metadata
    optional, base = unwrap(tp)
    if v is None and (optional or (base is Any and not meta.get("parse"))):
        return None
    if v is None and not meta.get("parse"):
        raise ConfigError(key, f"missing; accepted: {describe_type(tp, meta)}")
    if meta.get("parse"):
        return meta["parse"](key, v, ctx)
    if meta.get("family") and typing.get_origin(base) not in (list, tuple):
        return meta["family"].check(v, key, ctx)
    if base is bool:
        return flag(key, v)
    if base in (int, float):
        x = number(key, v, base, meta, f.name)
        return x if not meta.get("choices") else choice(key, x, meta["choices"])
    if base is str:
        if meta.get("choices"):
            return choice(key, v, meta["choices"])
        if not isinstance(v, str):
            raise ConfigError(key, f"{v!r}; accepted: text")
        return v
    if typing.get_origin(base) in (list, tuple):
        item = (typing.get_args(base) or (Any,))[0]
        if not isinstance(v, (list, tuple)):
            raise ConfigError(key, f"{v!r}; accepted: {describe_type(tp, meta)}")
        if meta.get("nonempty") and not v:
            raise ConfigError(key, f"empty; accepted: {meta['nonempty']}")
        if meta.get("family"):
            return [meta["family"].check(x, f"{key}[{i}]", ctx) for i, x in enumerate(v)]
        if item in (int, float):
            size = ctx.dim if meta.get("size") == "dim" else meta.get("size")
            return vector(key, v, size, meta, f.name)
        if dataclasses.is_dataclass(item):
            return [check(item, x, f"{key}[{i}]", ctx) for i, x in enumerate(v)]
        return list(v)
    if dataclasses.is_dataclass(base):
        return check(base, v, key, ctx)
    return v


def check(cls, d, key: str, ctx: Context | None = None, missing: str = "missing"):
    """An instance of dataclass ``cls`` from mapping ``d``: every key known,
    every value checked against its field, then ``cls.problems()``."""
    ctx = ctx or Context()
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if not isinstance(d, Mapping):
        raise ConfigError(key, f"{d!r}; accepted: a mapping of {', '.join(fields)}")
    for k in d:
        if k not in fields:
            raise ConfigError(f"{key}.{k}", f"unknown key; accepted: {', '.join(sorted(fields))}")
    tps = hints(cls)
    values = {}
    for name, f in fields.items():
        if d.get(name) is None and f.metadata.get("required"):
            raise ConfigError(f"{key}.{name}", f"{missing}; accepted: {wanted(f, tps[name], ctx)}")
        if name in d:
            values[name] = value(f"{key}.{name}", d[name], f, tps[name], ctx)
    obj = cls(**values)
    for name, message in obj.problems() if hasattr(obj, "problems") else ():
        raise ConfigError(f"{key}.{name}", message)
    return obj


def wanted(f: dataclasses.Field, tp, ctx: Context) -> str:
    """What a required field takes, in words: its type and its doc."""
    text = describe_type(unwrap(tp)[1], f.metadata).replace("a list of d numbers", f"a list of {ctx.dim} numbers")
    doc = f.metadata.get("doc")
    return f"{text} ({doc})" if doc else text


def override_key(key: str) -> str:
    """A full key as the command line writes it: ``scene.bodies[0].shape`` -> ``scene.bodies.0.shape``."""
    return re.sub(r"\[(\d+)\]", r".\1", key)


# ------------------------------------------------------------------ families
@dataclass(frozen=True)
class Family:
    """Mappings whose kind, the value of ``key``, picks the dataclass that
    defines their keys. ``unused`` and ``missing`` word a key the kind does
    not use and a required one left null (``{kind}`` filled in). A ``flat``
    family's mappings arrive typed by :meth:`flat` (every kind's keys, null
    where unset); a key no kind knows is then unknown. ``dims``: the scene
    dimensions a kind accepts (the class attribute ``dims``, default 2 and 3)."""

    name: str
    key: str
    variants: Mapping[str, type]
    unused: str = "not a parameter of {kind}"
    missing: str = "missing for {kind}"
    flat_node: bool = False
    example: str = ""

    def keys(self) -> list[str]:
        """Every key of every kind, in order of first appearance."""
        out = {}
        for cls in self.variants.values():
            out.update((f.name, None) for f in dataclasses.fields(cls))
        return list(out)

    def check(self, d, key: str, ctx: Context):
        """The variant instance for mapping ``d``."""
        if not isinstance(d, Mapping):
            raise ConfigError(key, f"{d!r}; accepted: a {self.name} mapping with a {self.key} key"
                                   + (f", e.g. {self.example}" if self.example else ""))
        kind = choice(f"{key}.{self.key}", d.get(self.key), list(self.variants))
        cls = self.variants[kind]
        dims = getattr(cls, "dims", (2, 3))
        if ctx.dim not in dims:
            ok = [k for k, c in self.variants.items() if ctx.dim in getattr(c, "dims", (2, 3))]
            raise ConfigError(f"{key}.{self.key}", f"{kind} is {' or '.join(map(str, dims))}D only; accepted in "
                                                   f"{ctx.dim}D: {', '.join(ok)}")
        names = [f.name for f in dataclasses.fields(cls)]
        every = self.keys()
        for k, v in d.items():
            if k in names or (self.flat_node and v is None and k in every):
                continue
            if self.flat_node and k not in every:
                raise ConfigError(f"{key}.{k}", f"unknown key; accepted: {', '.join(sorted(every))}")
            raise ConfigError(f"{key}.{k}", self.elsewhere(key, k, kind, ctx.dim)
                              or f"{self.unused.format(kind=kind)}; accepted: {', '.join(names)}")
        return check(cls, {k: v for k, v in d.items() if k in names}, key, ctx,
                     missing=self.missing.format(kind=kind))

    def names(self, kind: str) -> list[str]:
        """The keys of one kind."""
        return [f.name for f in dataclasses.fields(self.variants[kind])]

    def selector(self, key: str, kind: str) -> str:
        """How the command line chooses ``kind`` at ``key``: a config group
        by its option (``integrator=implicit``: the group's node then has the
        option's keys), a mapping inside the scene given whole, with its kind
        (``scene.bodies.0.shape={type: compound, ...}``)."""
        if key == self.name:
            return f"{key}={kind}"
        return f"{override_key(key)}={{{self.key}: {kind}, ...}}"

    def elsewhere(self, key: str, k: str, kind: str, dim: int | None = None) -> str | None:
        """The message for key ``k`` that ``kind`` does not use but other
        kinds do (those of a ``dim``-D scene): the kinds that take it and how
        to choose one (None: no kind takes it)."""
        others = [n for n, c in self.variants.items() if n != kind and k in self.names(n)
                  and (dim is None or dim in getattr(c, "dims", (2, 3)))]
        if not others:
            return None
        mine = ", ".join(self.names(kind))
        if len(others) == 1:
            which = f"{self.selector(key, others[0])} (its keys: {', '.join(self.names(others[0]))})"
        else:
            which = f"{self.selector(key, others[0])} (or {', '.join(others[1:])})"
        if key == self.name:
            return (f"{self.unused.format(kind=kind)} (its keys: {mine}); accepted: choose the option that takes "
                    f"{k} with the group, {which}, then set {key}.{k} ({key}.{self.key}=... does not change the "
                    f"group's keys)")
        return (f"{self.unused.format(kind=kind)}; accepted: {mine}; or {k} with a {' or '.join(others)}, the "
                f"whole {self.name} given as {which}")

    def flat(self, name: str, module: str, doc: str) -> type:
        """The one dataclass Hydra types these mappings with: every key of
        every kind; a key's type and default are the kinds' own where they all
        agree, else any value and null; the kind defaults to the first."""
        found: dict[str, list] = {}
        for cls in self.variants.values():
            tps = hints(cls)
            for f in dataclasses.fields(cls):
                found.setdefault(f.name, []).append((f, tps[f.name]))
        specs = []
        for fname, items in found.items():
            f, tp = items[0]
            if fname == self.key:
                tp, default = str, next(iter(self.variants))
            else:
                shared = len(items) == len(self.variants) and all(
                    t == tp and default_of(g) == default_of(f) for g, t in items)
                same = all(t == tp for _, t in items)
                default = default_of(f) if shared else None
                tp = tp if same else Any
                if not shared and not unwrap(tp)[0] and tp is not Any:
                    tp = Optional[tp]
            meta = dict(f.metadata)
            field = dataclasses.field(default_factory=functools.partial(copy.deepcopy, default), metadata=meta) \
                if isinstance(default, (list, dict)) else dataclasses.field(default=default, metadata=meta)
            specs.append((fname, tp, field))
        cls = dataclasses.make_dataclass(name, specs)
        cls.__module__, cls.__qualname__, cls.__doc__ = module, name, doc
        return cls
