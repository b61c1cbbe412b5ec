"""Warp function factories, checked by calling them.

Materials and kernels give their Warp functions as factories ``types ->
function`` (specialised per dimension and precision, mpm.types); a factory
defined outside ``mpm`` is called once when it is registered
(mpm.materials.registry, mpm.kernels.registry), so that a mistake shows then,
in one line, rather than in the middle of a run's compilation.
"""

from __future__ import annotations

import warp as wp

from .types import make_types


def probe(obj, factories: list[tuple[str, tuple]]) -> str | None:
    """Call each factory of ``obj`` (its name and the arguments after the
    types) for 2D float32: what goes wrong, in words, or None when each gives
    a Warp function. Nothing is compiled."""
    t = make_types(2, "float32")
    for name, extra in factories:
        try:
            f = getattr(obj, name)(t, *extra)
        except Exception as e:  # noqa: BLE001 - said in the message
            first = next((ln for ln in str(e).splitlines() if ln.strip()), "")
            hint = ("; a file that defines Warp functions cannot use `from __future__ import annotations`"
                    if isinstance(e, NameError) else "")
            return f"{name}(types) fails ({type(e).__name__}: {first}){hint}"
        if not isinstance(f, wp.Function):
            return f"{name}(types) gives a {type(f).__name__}; accepted: a Warp function (@wp.func)"
    return None
