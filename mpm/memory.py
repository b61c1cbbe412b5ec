"""Device memory held by a run: the bytes of every Warp array reachable from
the model, the state and the solver (particles, grids, caches, scratch).

This counts allocations, not the allocator's overhead or Warp's kernel
modules; an array and views of it are counted once (a view counts as the
array it was taken from).
"""

from typing import Any

import warp as wp

from .types import StructInstance


def _children(obj):
    if isinstance(obj, (list, tuple, set)):
        return list(obj)
    if isinstance(obj, dict):
        return list(obj.values())
    if isinstance(obj, (StructInstance, wp.Mesh)) or type(obj).__module__.split(".")[0] == "mpm":
        return list(vars(obj).values()) if hasattr(obj, "__dict__") else []
    return []


def array_bytes(*roots) -> int:
    """Bytes of the distinct Warp arrays reachable from ``roots`` through
    attributes of mpm objects, Warp structs and meshes, lists, tuples and dicts."""
    seen, pointers, total = set(), set(), 0
    stack = list(roots)
    while stack:
        obj = stack.pop()
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, wp.array):
            array: Any = obj  # Warp's private _ref: the array a view views
            while isinstance(getattr(array, "_ref", None), wp.array):
                array = array._ref
            if array.ptr and array.ptr not in pointers:
                pointers.add(array.ptr)
                total += array.capacity
            continue
        stack.extend(_children(obj))
    return total
