"""Checkpoints: a driver's whole state in one file, and a run resumed from it bit for bit.

:func:`save` walks everything a :class:`mpm.Driver` can reach through
``mpm`` objects, Warp structs, lists, tuples and dicts, and keeps each Warp
array and each host value (numbers, bools, strings, NumPy arrays, containers
of them, Warp scalars and vectors, random generator states) under its
attribute path (``state.x``, ``solver.layout.lo``). What every step
recomputes before reading it (:data:`SCRATCH`: the grid's nodal fields) and
what is not the run's progress (:data:`SKIP`: the observers, the scene as
given, a captured graph) is left out. An array reached twice (a struct's
field aliasing a state's array) is kept once, at its first path.

The file is an ``npz`` written atomically (a temporary file in the same
folder, flushed and synced, then renamed over the target): the arrays, and a
pickled header with the format version (:data:`FORMAT`), the
:func:`signature` (every array's path, shape and dtype), the step, the time
[s], the host values and the caller's ``meta`` (a configuration hash, a code
version). :func:`resume` takes a fresh driver built from the same scene,
options and policy, prepares it as :meth:`mpm.Driver.start` would without
telling the observers, grows or builds what is made at first use
(:data:`CAPACITY`, :data:`LAZY`), refuses a checkpoint of another
configuration (another signature: :class:`CheckpointError`, one line),
copies every array in place (a struct or a recorded launch holding one sees
it), sizes the grid (:meth:`mpm.Solver.restored`) and tells the observers
(:meth:`mpm.Observer.on_resume`).
"""

from __future__ import annotations

import os
import pickle
import random
import tempfile
from pathlib import Path

import numpy as np
import warp as wp

FORMAT = 1
"""the file format's version; a file of another version is refused"""
HEADER = "__header__"
"""the npz entry holding the pickled header"""
SCRATCH = ("GridArrays",)
"""classes whose contents every step recomputes before reading them (mpm.reference_grids.GridArrays:
the nodal fields, sized lazily to the layout; mpm.Solver.restored reserves them)"""
SKIP = ("observers", "scene", "given", "Solver.step_time", "Solver.dt", "ImplicitSolve._backup", "_graph",
        "_graph_key", "_views", "_wanted", "_recorded")
"""attributes (``name``, or ``Class.name`` for one class's) that are not the run's state: the observers
(outside mpm), the scene and the options as given (the configuration the caller builds again), the
solver's step and clock of an attempt (set before each), the implicit solve's copy of the plastic
state for a retry (taken before each step), a captured CUDA graph, cached views and
recorded launches (rebuilt or repacked as needed), the observers' last wants (asked again)"""
CAPACITY = (("solver.implicit", "_capacity", "_grow"),)
"""(owner's path, its size attribute, the method that grows it): parts sized lazily to the largest grid
seen so far (mpm.implicit.solve.ImplicitSolve's per-node arrays), grown to the checkpoint's size before
the values are restored, so that every array is there with the checkpoint's shape"""
LAZY = (("solver.fracture", "_pairs"),)
"""(owner's path, the method that builds it): parts built at their first use (the fracture measure's
neighbour pairs, from the positions prepared at the start), built before the restore when the
checkpoint holds arrays of theirs that a fresh driver lacks"""
PLAIN = (bool, int, float, str, bytes, type(None), np.generic)


class CheckpointError(ValueError):
    """A checkpoint that cannot be used here: missing, damaged, another format or another configuration."""


# ------------------------------------------------------------------ the walk
def _is_struct(obj) -> bool:
    return hasattr(obj, "_cls") and hasattr(obj._cls, "vars") and hasattr(obj, "numpy_value")


def _is_mpm(obj) -> bool:
    module = type(obj).__module__ or ""
    return (module == "mpm" or module.startswith("mpm.")) and hasattr(obj, "__dict__") and not isinstance(obj, type)


def _plain(value) -> bool:
    """A number, bool, string or None, or a list, tuple or dict of them (any length: a step's list grows)."""
    if isinstance(value, PLAIN):
        return True
    if isinstance(value, (list, tuple, set, frozenset)) and not hasattr(value, "_fields"):
        return all(_plain(v) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, PLAIN) and _plain(v) for k, v in value.items())
    return False


def _children(obj) -> list[tuple[str, object, object]]:
    """(path step, key, child) of a container, a struct or an mpm object; [] for anything else."""
    if isinstance(obj, (list, tuple)):
        return [(f"[{i}]", i, v) for i, v in enumerate(obj)]
    if isinstance(obj, dict):
        return [(f"[{k!r}]", k, v) for k, v in obj.items()]
    if _is_struct(obj):
        return [(f".{name}", name, getattr(obj, name)) for name in obj._cls.vars]
    if _is_mpm(obj) and type(obj).__name__ not in SCRATCH:
        cls = type(obj).__name__
        return [(f".{name}", name, v) for name, v in vars(obj).items() if name not in SKIP
                and f"{cls}.{name}" not in SKIP]
    return []


def _leaf(obj) -> str | None:
    """The kind of a value kept as it is: array, numpy, generator, random, warp (a Warp scalar, vector or
    matrix), value; None: walk into it."""
    if isinstance(obj, wp.array):
        return "array"
    if (type(obj).__module__ or "").startswith("warp") and (wp.types.type_is_composite(type(obj))
                                                           or wp.types.type_is_scalar(type(obj))):
        return "warp"
    if isinstance(obj, np.ndarray):
        return "numpy"
    if isinstance(obj, np.random.Generator):
        return "generator"
    if isinstance(obj, random.Random):
        return "random"
    if _plain(obj):
        return "value"
    return None


def walk(root, visit, path: str = "", seen: set | None = None):
    """Call ``visit(path, kind, value)`` for every leaf below ``root``
    (depth first, in attribute order; an array or object reached twice only
    at its first path) and put back what it returns where it differs (a
    tuple is rebuilt); ``root`` or its replacement."""
    seen = set() if seen is None else seen
    kind = _leaf(root)
    if kind != "value":  # (a number or a string may be one object in many places)
        if id(root) in seen:
            return root
        seen.add(id(root))
    if kind is not None:
        return visit(path, kind, root)
    changed = {}
    for step, key, child in _children(root):
        new = walk(child, visit, (path + step) if path else step.lstrip("."), seen)
        if new is not child:
            changed[key] = new
    if not changed:
        return root
    if isinstance(root, tuple):
        items = [changed.get(i, v) for i, v in enumerate(root)]
        return type(root)(*items) if hasattr(root, "_fields") else tuple(items)
    for key, new in changed.items():
        if isinstance(root, (list, dict)):
            root[key] = new
        else:
            setattr(root, key, new)
    return root


def signature(driver) -> dict[str, tuple]:
    """Path -> (kind, shape, dtype) of every array kept (Warp's or NumPy's): what a checkpoint of another
    configuration differs in (a host value set only once a step ran may be absent from a fresh driver)."""
    out = {}

    def visit(path, kind, value):
        if kind == "array":
            out[path] = (kind, tuple(value.shape), str(np.dtype(wp.dtype_to_numpy(value.dtype)))
                         if _scalar_dtype(value.dtype) else f"{value.dtype.__name__}")
        elif kind == "numpy":
            out[path] = (kind, value.shape, str(value.dtype))
        return value

    walk(driver, visit)
    return out


def _warp_numbers(value):
    """A Warp scalar's number, or a vector's or matrix's numbers (row by row), as Python numbers."""
    return np.array(value).ravel().tolist() if wp.types.type_is_composite(type(value)) else value.value


def _scalar_dtype(dtype) -> bool:
    try:
        wp.dtype_to_numpy(dtype)
        return True
    except Exception:  # a vector, matrix or struct type
        return False


# ------------------------------------------------------------------ the file
def save(driver, path, meta: dict | None = None) -> Path:
    """Write ``driver``'s checkpoint to ``path`` atomically (the previous file
    stays whole if anything fails); ``meta``: the caller's own values (a
    configuration hash, a code version), kept in the header. Only after
    :meth:`mpm.Driver.start`, where the device holds the state of ``driver.step``
    (``driver.current``; RuntimeError, one line, otherwise)."""
    if driver.initial is None:
        raise RuntimeError("save: the driver has not started; accepted: after start() (or run()), between steps")
    if not driver.current:
        raise RuntimeError(f"save: the device holds a later step than step {driver.step} (inside a batch); "
                           "accepted: between advance() calls, or at a step an observer wants()")
    path = Path(path)
    arrays, values = {}, {}

    def visit(p, kind, value):
        if kind == "array":
            arrays[p] = value.numpy()
        elif kind == "numpy":
            arrays[p] = value
        elif kind == "generator":
            values[p] = value.bit_generator.state
        elif kind == "random":
            values[p] = value.getstate()
        elif kind == "warp":
            values[p] = _warp_numbers(value)
        else:
            values[p] = value
        return value

    walk(driver, visit)
    header = {"format": FORMAT, "signature": signature(driver), "step": driver.step, "time": driver.time,
              "meta": dict(meta or {}), "values": values}
    arrays[HEADER] = np.frombuffer(pickle.dumps(header, protocol=pickle.HIGHEST_PROTOCOL), np.uint8)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


class Checkpoint:
    """A checkpoint read back: ``header`` (format, signature, step, time [s], meta, values) and ``arrays``."""

    def __init__(self, path: Path, header: dict, arrays: dict[str, np.ndarray]):
        self.path, self.header, self.arrays = path, header, arrays

    @property
    def step(self) -> int:
        return self.header["step"]

    @property
    def time(self) -> float:
        """[s]"""
        return self.header["time"]

    @property
    def meta(self) -> dict:
        return self.header["meta"]


def read(path) -> Checkpoint:
    """The checkpoint at ``path``; CheckpointError (one line) when it is missing,
    damaged or of another format version. The header is a pickle: read only
    checkpoints you (or your runs) wrote."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path}: no such file")
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        header = pickle.loads(arrays.pop(HEADER).tobytes())
    except Exception as e:  # a truncated zip, a missing entry, a broken pickle: all one thing to the reader
        said = str(e).splitlines()[0] if str(e) else "unreadable"
        raise CheckpointError(f"checkpoint {path}: damaged ({type(e).__name__}: {said})") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        found = header.get("format") if isinstance(header, dict) else None
        raise CheckpointError(f"checkpoint {path}: format version {found!r}; accepted: {FORMAT}")
    return Checkpoint(path, header, arrays)


def check(driver, data: Checkpoint) -> None:
    """CheckpointError (one line, the first difference) unless ``data`` is of ``driver``'s configuration."""
    mine, theirs = signature(driver), data.header["signature"]
    if mine == theirs:
        return
    missing, extra = sorted(set(mine) - set(theirs)), sorted(set(theirs) - set(mine))
    if missing or extra:
        which = f"{missing[0]} absent from it" if missing else f"{extra[0]} not in this run"
    else:
        p = next(p for p in sorted(mine) if mine[p] != theirs[p])
        which = f"{p} is {theirs[p][1:]} there, {mine[p][1:]} here"
    raise CheckpointError(f"checkpoint {data.path}: another configuration ({which})")


def _at(root, path: str):
    """The object at a dotted attribute ``path`` below ``root`` (None: there is none)."""
    for name in path.split(".") if path else ():
        root = getattr(root, name, None)
    return root


def reserve(driver, data: Checkpoint) -> None:
    """Grow the lazily sized parts (:data:`CAPACITY`) to the sizes they had in ``data``, and build the
    parts built at first use (:data:`LAZY`) that ``data`` has built."""
    for owner, size, grow in CAPACITY:
        part, n = _at(driver, owner), data.header["values"].get(f"{owner}.{size}")
        if part is not None and n is not None and n > getattr(part, size):
            getattr(part, grow)(n)
    mine, theirs = signature(driver), data.header["signature"]
    for owner, build in LAZY:
        part = _at(driver, owner)
        if part is not None and any(p.startswith(f"{owner}.") and p not in mine for p in theirs):
            getattr(part, build)()


def restore(driver, data: Checkpoint) -> None:
    """Put every value of ``data`` into ``driver`` (arrays copied in place), after :func:`check`."""
    check(driver, data)
    values, restored = data.header["values"], set()

    def visit(p, kind, value):
        restored.add(p)
        if kind == "array":
            saved = data.arrays[p]
            if saved.shape == tuple(value.shape) + tuple(getattr(value.dtype, "_shape_", ())):
                if saved.size:
                    value.assign(saved)  # in place: every struct and launch holding it sees it
                return value
            raise CheckpointError(f"checkpoint {data.path}: {p} has {saved.shape[:value.ndim]} entries there, "
                                  f"{value.shape} here (mpm.checkpoint.CAPACITY names what grows)")
        if kind == "numpy":
            saved = data.arrays[p]
            if saved.shape == value.shape and value.flags.writeable:
                value[...] = saved
                return value
            return saved.copy()
        if kind == "generator":
            value.bit_generator.state = values[p]
            return value
        if kind == "random":
            value.setstate(values[p])
            return value
        if kind == "warp":
            saved = values[p]
            if saved == _warp_numbers(value):
                return value
            return type(value)(*saved) if isinstance(saved, list) else type(value)(saved)
        return value if _same(value, values[p]) else values[p]

    walk(driver, visit)
    for p in sorted(set(values) - restored):  # a host value a fresh driver sets only once a step ran
        owner, _, name = p.rpartition(".")
        part = _at(driver, owner) if "[" not in p else None
        if part is not None and _is_mpm(part) and isinstance(values[p], PLAIN):
            setattr(part, name, values[p])


def _same(a, b) -> bool:
    """Equal values of one type (NaN equal to NaN): kept as they are (a frozen dataclass's field included)."""
    if type(a) is not type(b):
        return False
    try:
        return bool(a == b) or a != a and b != b
    except (TypeError, ValueError):
        return False


def resume(driver, path) -> Checkpoint:
    """Continue ``driver`` (fresh, built from the same scene, options and policy)
    from the checkpoint at ``path``: read, prepare, restore, the solver's lazily
    sized parts, the observers told; the checkpoint read."""
    data = read(path)
    if driver.initial is not None:
        raise RuntimeError("resume: the driver has started; accepted: a fresh Driver")
    driver.prepare()
    reserve(driver, data)
    restore(driver, data)
    driver.solver.restored(driver.state)
    for o in driver.observers:
        o.on_resume(driver)
    return data
