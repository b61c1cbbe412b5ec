"""Warp function factories, checked by calling them.

Materials and kernels give their Warp functions as factories ``types ->
function`` (specialised per dimension and precision, mpm.types); a factory
defined outside ``mpm`` is called once when it is registered
(mpm.materials.registry, mpm.kernels.registry) for every dimension and
precision, and the values its function returns counted from its source, so
that a mistake shows then, in one line naming the class or kernel, rather
than in the middle of a run's compilation.
"""

from __future__ import annotations

import ast

import warp as wp

from .types import make_types

TYPES = [(2, "float32"), (3, "float32"), (2, "float64"), (3, "float64")]
"""the dimensions and precisions a factory is called for"""


def returned(f) -> set[int]:
    """How many values the ``return`` statements of Warp function ``f`` give
    that can be counted from its parsed source (a tuple: its length; a name,
    a constant or an arithmetic expression: one; a call: unknown, left out).
    Nothing is compiled."""
    tree = getattr(getattr(f, "adj", None), "tree", None)
    body = next((n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)), None) if tree else None
    counts: set[int] = set()
    stack: list[ast.AST] = list(body.body) if body is not None else []
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(node, ast.Return) and node.value is not None:
            if isinstance(node.value, ast.Tuple):
                counts.add(len(node.value.elts))
            elif not isinstance(node.value, ast.Call):
                counts.add(1)
        stack.extend(ast.iter_child_nodes(node))
    return counts


def probe(obj, factories: list[tuple]) -> str | None:
    """Call each factory of ``obj`` (its name, the arguments after the
    types and, optionally, how many values its function returns, with
    their names) for 2D and 3D in float32 and float64: what goes wrong, in
    words, or None when each gives a Warp function returning what it
    should. Nothing is compiled."""
    for dim, precision in TYPES:
        t = make_types(dim, precision)
        where = "" if (dim, precision) == TYPES[0] else f" in {dim}D {precision}"  # (the first: said as before)
        for name, extra, *want in factories:
            try:
                f = getattr(obj, name)(t, *extra)
            except Exception as e:  # noqa: BLE001 - said in the message
                first = next((ln for ln in str(e).splitlines() if ln.strip()), "")
                hint = ("; a file that defines Warp functions cannot use `from __future__ import annotations`"
                        if isinstance(e, NameError) else "")
                return f"{name}(types) fails{where} ({type(e).__name__}: {first}){hint}"
            if not isinstance(f, wp.Function):
                return f"{name}(types) gives a {type(f).__name__}{where}; accepted: a Warp function (@wp.func)"
            if want:
                count, names = want[0]
                wrong = sorted(returned(f) - {count})
                if wrong:
                    return (f"{name}(types) gives a Warp function returning {wrong[0]} value(s); accepted: "
                            f"{count} ({names})")
    return None
