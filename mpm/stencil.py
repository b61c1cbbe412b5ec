"""Locating a particle in the grid and walking its stencil; shared by every
transfer.

``locate`` gives the flat index of the first stencil node, the local
coordinate ``fx = X / dx - base`` and the per-axis kernel weights ``W``
(row d: the 1-D weights along axis d). ``node(a, b, c, ...)`` gives, for the
stencil node at offset (a, b[, c]), its weight ``w``, its offset from the
particle ``r = X_i - X_p`` [m] and its flat index. Loops over
``range(kernel.support)`` have compile-time bounds and are unrolled.
"""

import functools

import warp as wp

from .kernels import Kernel
from .types import Types


@functools.cache
def weight_matrix_type(t: Types, kernel: Kernel):
    return wp.types.matrix((t.dim, kernel.support), t.scalar)


@functools.cache
def make_locate(t: Types, kernel: Kernel):
    """``locate(X, inv_dx, cells, strides) -> (flat, fx, W)``.

    The base node is clamped to the grid so that a runaway particle never
    addresses memory outside it (G2P flags such particles)."""
    S = t.scalar
    vec = t.vec
    Wm = weight_matrix_type(t, kernel)
    weights = kernel.weights(t)
    last = kernel.support - 1
    offset = kernel.offset
    support = kernel.support

    @wp.func
    def locate(X: t.vec, inv_dx: S, cells: t.ivec, strides: t.ivec):
        g = X * inv_dx
        fx = vec()
        W = Wm()
        flat = int(0)
        for d in range(wp.static(t.dim)):
            b = wp.clamp(int(wp.floor(g[d] - S(offset))), 0, cells[d] - last)
            flat += b * strides[d]
            fx[d] = g[d] - S(b)
            w = weights(fx[d])
            for s in range(wp.static(support)):
                W[d, s] = w[s]
        return flat, fx, W

    return locate


@functools.cache
def make_node(t: Types, kernel: Kernel):
    """``node(a, b, c, flat, fx, W, strides, dx) -> (w, r, i)``; c is ignored in 2D."""
    S = t.scalar
    vec = t.vec
    Wm = weight_matrix_type(t, kernel)

    @wp.func
    def node(a: int, b: int, c: int, flat: int, fx: t.vec, W: Wm, strides: t.ivec, dx: S):
        if wp.static(t.dim == 2):
            w = W[0, a] * W[1, b]
            r = (vec(S(a), S(b)) - fx) * dx
            i = flat + a * strides[0] + b
        else:
            w = W[0, a] * W[1, b] * W[2, c]
            r = (vec(S(a), S(b), S(c)) - fx) * dx
            i = flat + a * strides[0] + b * strides[1] + c
        return w, r, i

    return node
