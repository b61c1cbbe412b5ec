"""Locating a particle in its body's reference grid and walking its stencil.

``locate`` (used when a configuration is updated) gives the flat index of the
first stencil node in the body's box, the local coordinate
``fx = X / dx - base`` and the per-axis kernel weights ``W`` (row d: the 1-D
weights along axis d); the transfers read these from the cache and call
``node(a, b, c, ...)`` for the weight ``w``, the offset ``r = X_i - X_p`` [m]
and the flat index of the stencil node at offset (a, b[, c]). Loops over
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
def make_strides(t: Types):
    """Strides of a C-ordered box of ``shape`` nodes."""
    ivec = t.ivec

    @wp.func
    def strides(shape: t.ivec):
        if wp.static(t.dim == 2):
            return ivec(shape[1], 1)
        else:
            return ivec(shape[1] * shape[2], shape[2], 1)

    return strides


@functools.cache
def make_locate(t: Types, kernel: Kernel):
    """``locate(X, inv_dx, lo, shape, offset) -> (flat, fx, W)`` in a body's box.

    The stencil is clamped to the box, so that a runaway particle never
    addresses memory outside it (G2P flags such particles)."""
    S = t.scalar
    Wm = weight_matrix_type(t, kernel)
    weights = kernel.weights(t)
    strides = make_strides(t)
    k_offset = kernel.offset
    support = kernel.support
    vec = t.vec

    @wp.func
    def locate(X: t.vec, inv_dx: S, lo: t.ivec, shape: t.ivec, offset: int):
        g = X * inv_dx
        st = strides(shape)
        fx = vec()
        W = Wm()
        flat = offset
        for d in range(wp.static(t.dim)):
            b = wp.clamp(int(wp.floor(g[d] - S(k_offset))), lo[d], lo[d] + shape[d] - support)
            flat += (b - lo[d]) * st[d]
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
