"""Locating a particle in its body's reference grids and walking its stencil.

A kernel has one grid (B-splines) or two staggered ones (the compact kernel);
grid g of body b is box ``b * G + g`` of the layout (mpm.reference_grids). ``origin``
computes once per particle what all grids share (grid 0's coordinate and the
compact kernel's sines); ``locate`` (used when a configuration is updated)
gives from it, on one grid, the flat index of
the first stencil node, the local coordinate ``fx = X / dx - o_g - base`` and
the per-axis kernel weights ``W`` (row d: the 1-D weights along axis d) and,
for gradient-based transfers, their t-derivatives ``dW``; the transfers read
these from the cache (entry ``p * G + g``) and call ``node(a, b, c, ...)``
for the weight ``w``, the offset ``r = X_i - X_p`` [m] and the flat index of
the stencil node at offset (a, b[, c]), and ``node_gradient`` for the
reference-space weight gradient. Loops over ``range(kernel.support)`` and
over the grids have compile-time bounds and are unrolled.
``node_position`` places a flat grid node on the lattice (the Eulerian grid).
"""

import functools

import numpy as np
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
def make_origin(t: Types, kernel: Kernel, with_gradients: bool):
    """``origin(X, inv_dx, grid_offsets) -> (u0, P)``: the coordinate of X on
    grid 0 in cells, ``u0 = X / dx - o_0``, and per axis (row d) what the
    kernel's grids share (its ``phase``; zero when it has none). Every grid's
    stencil is located from these (:func:`make_locate`)."""
    S = t.scalar
    Pm = wp.types.matrix((t.dim, 3), S)
    Gv = wp.types.vector(kernel.n_grids, S)
    phase = kernel.phase(t, with_gradients) if kernel.phase is not None else None

    @wp.func
    def origin(X: t.vec, inv_dx: S, grid_offsets: Gv):
        u0 = X * inv_dx
        P = Pm()
        for d in range(wp.static(t.dim)):
            u0[d] = u0[d] - grid_offsets[0]
            if wp.static(phase is not None):
                ph = phase(u0[d] - wp.floor(u0[d]))  # periodic: the fraction keeps the argument small  # pyright: ignore[reportOptionalCall]
                for k in range(3):
                    P[d, k] = ph[k]
        return u0, P

    return origin


@functools.cache
def make_locate(t: Types, kernel: Kernel, with_gradients: bool):
    """``locate(u0, P, shift, g, lo, shape, offset) -> (flat, fx, W, dW)`` in
    grid g's box, from :func:`make_origin`'s ``(u0, P)`` and the grid's shift
    from grid 0 in cells, ``o_g - o_0`` (0 or 1/2: exact in floating point, so
    the grids' coordinates differ by exactly that); dW left zero unless
    ``with_gradients``. The stencil is clamped to the box, so that a runaway
    particle never addresses memory outside it (G2P flags such particles).
    :func:`make_weigh` is its part that needs no box."""
    weigh = make_weigh(t, kernel, with_gradients, clamped=True)
    strides = make_strides(t)

    @wp.func
    def locate(u0: t.vec, P: wp.types.matrix((t.dim, 3), t.scalar), shift: t.scalar, g: int, lo: t.ivec,
               shape: t.ivec, offset: int):
        first, fx, W, dW = weigh(u0, P, shift, g, lo, shape)
        st = strides(shape)
        flat = offset
        for d in range(wp.static(t.dim)):
            flat += (first[d] - lo[d]) * st[d]
        return flat, fx, W, dW

    return locate


@functools.cache
def make_weigh(t: Types, kernel: Kernel, with_gradients: bool, clamped: bool):
    """``weigh(u0, P, shift, g, lo, shape) -> (first, fx, W, dW)``: grid g's
    stencil as :func:`make_locate` finds it, without a box's flat index:
    its first node (lattice index), ``clamped`` to the box (lo, shape) or
    not (lo and shape unused; mpm.reference_update computes K_p at a position
    this way)."""
    S = t.scalar
    Wm = weight_matrix_type(t, kernel)
    Pm = wp.types.matrix((t.dim, 3), S)
    shared = kernel.phase is not None
    if shared:
        assert kernel.weights_at is not None and kernel.gradients_at is not None, "kernel_problem() checks"
        weights, gradients = kernel.weights_at(t), kernel.gradients_at(t)
    else:
        assert kernel.weights is not None and kernel.gradients is not None, "kernel_problem() checks"
        weights, gradients = kernel.weights(t), kernel.gradients(t)
    fill_weights = make_fill_row(t, kernel, weights, shared)
    fill_gradients = make_fill_row(t, kernel, gradients, shared)
    k_offset = kernel.offset
    support = kernel.support
    vec = t.vec

    @wp.func
    def weigh(u0: t.vec, P: Pm, shift: S, g: int, lo: t.ivec, shape: t.ivec):
        first = t.ivec()
        fx = vec()
        W = Wm()
        dW = Wm()
        for d in range(wp.static(t.dim)):
            u = u0[d] - shift
            b = int(wp.floor(u - S(k_offset)))
            if wp.static(clamped):
                b = wp.clamp(b, lo[d], lo[d] + shape[d] - support)
            first[d] = b
            fx[d] = u - S(b)
            W = fill_weights(W, d, fx[d], P[d], g)
            if wp.static(with_gradients):
                dW = fill_gradients(dW, d, fx[d], P[d], g)
        return first, fx, W, dW

    return weigh


@functools.cache
def make_fill_row(t: Types, kernel: Kernel, f, shared: bool):
    """``fill(M, d, u, P_d, g) -> M`` with row d set to the 1-D values f(u)
    (``shared``: f(u, P_d, g) on grid g, from the shared phase P_d)."""
    S = t.scalar
    Wm = weight_matrix_type(t, kernel)
    support = kernel.support

    @wp.func
    def fill(M: Wm, d: int, u: S, Pd: wp.types.vector(3, S), g: int):
        if wp.static(shared):
            w = f(u, Pd, g)
        else:
            w = f(u)
        out = M
        for s in range(wp.static(support)):
            out[d, s] = w[s]
        return out

    return fill


@functools.cache
def make_stencil_cache(t: Types, kernel: Kernel):
    """The stencil cache (mpm.model.State.stencils): per particle p and kernel
    grid g (entry ``p * G + g``) what :func:`make_locate` gives at the last
    configuration update, and per particle the MLS/APIC moment inverse K_p
    (one unused entry when the kernel's moment is a constant). A *fused*
    cache (:func:`fuse`) keeps no stencils: it points at the reference
    positions and the layout, and the transfers locate each stencil again
    (the Eulerian scheme updates every step: writing the stencils and
    reading them back costs more memory traffic than computing them)."""
    Wm = weight_matrix_type(t, kernel)
    Gv = wp.types.vector(kernel.n_grids, t.scalar)

    @wp.struct
    class StencilCache:
        # the first stencil node's flat index within its box (the box's offset is added where it is
        # read: a refit of another body moves the boxes' offsets, not this box)
        base: wp.array(dtype=wp.int32)
        fx: wp.array(dtype=t.vec)  # X / dx - o_g - base
        W: wp.array(dtype=Wm)  # per-axis kernel weights
        dW: wp.array(dtype=Wm)  # and their derivatives (gradient-based transfers)
        K: wp.array(dtype=t.mat)  # K_p [1/m^2]
        # fused: where the stencils are located from
        X: wp.array(dtype=t.vec)  # reference positions [m]
        lo: wp.array(dtype=t.ivec)  # layout: first node of box b * G + g
        offset: wp.array(dtype=wp.int32)  # layout: per box, its offset in the flat grid arrays
        grid_offsets: Gv  # the kernel grids' offsets [cells]
        inv_dx: t.scalar  # [1/m]

    return StencilCache


def stencil_cache(t: Types, kernel: Kernel, n: int):
    """A zeroed stencil cache for ``n`` particles on the current device."""
    G, Wm = kernel.n_grids, weight_matrix_type(t, kernel)
    cache = make_stencil_cache(t, kernel)()
    cache.base = wp.zeros(n * G, dtype=wp.int32)
    cache.fx = wp.zeros(n * G, dtype=t.vec)
    cache.W = wp.zeros(n * G, dtype=Wm)
    cache.dW = wp.zeros(n * G, dtype=Wm)
    cache.K = wp.zeros(n if kernel.moment is None else 1, dtype=t.mat)
    cache.X = wp.zeros(1, dtype=t.vec)
    cache.lo = wp.zeros(1, dtype=t.ivec)
    cache.offset = wp.zeros(1, dtype=wp.int32)
    return cache


def fuse(cache, t: Types, kernel: Kernel, X: wp.array, lo: wp.array, offset: wp.array, dx: float):
    """Make ``cache`` a fused one (see :func:`make_stencil_cache`): the
    per-grid stencil arrays are released, K_p stays cached."""
    cache.base = wp.zeros(1, dtype=wp.int32)
    cache.fx = wp.zeros(1, dtype=t.vec)
    cache.W = wp.zeros(1, dtype=weight_matrix_type(t, kernel))
    cache.dW = wp.zeros(1, dtype=weight_matrix_type(t, kernel))
    cache.X, cache.lo, cache.offset = X, lo, offset
    cache.grid_offsets = wp.types.vector(kernel.n_grids, t.scalar)(*kernel.grids)
    real = np.float32 if t.precision == "float32" else np.float64
    cache.inv_dx = t.scalar(real(1.0) / real(dx))  # 1/dx in the kernels' precision, as the update divides
    return cache


@functools.cache
def make_cached(t: Types, kernel: Kernel, with_gradients: bool, fused: bool = False):
    """``reference(p, cache) -> (u0, P)`` once per particle, then
    ``cached(p, g, body, shape, cache, u0, P) -> (strides, flat, fx, W, dW)``
    per kernel grid g: particle p's stencil as the last configuration update
    left it (dW zero unless ``with_gradients``); ``fused``: located again
    from the reference position (the same arithmetic as the update's; u0 and
    P are :func:`make_origin`'s, unused otherwise)."""
    G = kernel.n_grids
    strides = make_strides(t)
    Wm = weight_matrix_type(t, kernel)
    Pm = wp.types.matrix((t.dim, 3), t.scalar)
    Cache = make_stencil_cache(t, kernel)
    locate = make_locate(t, kernel, with_gradients)
    origin = make_origin(t, kernel, with_gradients)

    @wp.func
    def reference(p: int, cache: Cache):
        if wp.static(fused):
            return origin(cache.X[p], cache.inv_dx, cache.grid_offsets)
        return t.vec(), Pm()

    @wp.func
    def cached(p: int, g: int, body: int, shape: wp.array(dtype=t.ivec), cache: Cache, u0: t.vec, P: Pm):
        box = body * G + g
        if wp.static(fused):
            flat, fx, W, dW = locate(u0, P, cache.grid_offsets[g] - cache.grid_offsets[0], g, cache.lo[box],
                                     shape[box], cache.offset[box])
            return strides(shape[box]), flat, fx, W, dW
        k = p * G + g
        dW = Wm()
        if wp.static(with_gradients):
            dW = cache.dW[k]
        return strides(shape[box]), cache.offset[box] + cache.base[k], cache.fx[k], cache.W[k], dW

    return reference, cached


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


@functools.cache
def make_walk(t: Types, kernel: Kernel, with_gradients: bool, visit, Args):
    """``walk(p, b, shape, cache, dx, acc, args) -> acc``: particle p's
    stencils on the G grids (:func:`make_cached`, not fused), node by node
    in the nested order (a, b, c, c fastest): ``acc = visit(acc, a, b, c, w,
    r, i, W, dW, args)`` (``visit`` a Warp function, ``acc`` a matrix,
    ``args`` an ``Args`` struct: what the visit reads and writes)."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    node = make_node(t, kernel)
    Cache = make_stencil_cache(t, kernel)
    reference, cached = make_cached(t, kernel, with_gradients)

    @wp.func
    def walk(p: int, b: int, shape: wp.array(dtype=t.ivec), cache: Cache, dx: S, acc: t.mat, args: Args):
        out = acc
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            for a in range(Ks):
                for bb in range(Ks):
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        out = visit(out, a, bb, c, w, r, i, W, dW, args)
        return out

    return walk


@functools.cache
def make_node_gradient(t: Types, kernel: Kernel):
    """``node_gradient(a, b, c, W, dW, inv_dx) -> grad w_ip`` [1/m]: the
    gradient of the node's weight with respect to the particle's reference
    position X_p (the MPM force f_i = -sum_p V_p^0 P F^{0s,T} grad w_ip; MLS
    approximates it by K_p (X_i - X_p) w_ip)."""
    vec = t.vec
    Wm = weight_matrix_type(t, kernel)
    S = t.scalar

    @wp.func
    def node_gradient(a: int, b: int, c: int, W: Wm, dW: Wm, inv_dx: S):
        # t = X_p / dx - base: d t / d X_p = 1 / dx
        if wp.static(t.dim == 2):
            return inv_dx * vec(dW[0, a] * W[1, b], W[0, a] * dW[1, b])
        else:
            return inv_dx * vec(dW[0, a] * W[1, b] * W[2, c], W[0, a] * dW[1, b] * W[2, c],
                                W[0, a] * W[1, b] * dW[2, c])

    return node_gradient


@functools.cache
def make_node_box(t: Types):
    """``node_box(i, offset, n_boxes) -> box``: the box holding flat grid node
    i, the last whose first node ``offset[box]`` is at most i (the boxes lie
    one after another; in a shared layout the bodies' boxes coincide)."""

    @wp.func
    def node_box(i: int, offset: wp.array(dtype=wp.int32), n_boxes: int):
        box = int(0)
        for k in range(n_boxes):
            if i >= offset[k]:
                box = k
        return box

    return node_box


@functools.cache
def make_node_position(t: Types, n_grids: int):
    """``node_position(i, lo, shape, offset, n_boxes, grid_offsets, dx) -> x_i``
    [m]: where the layout puts flat grid node i, (first node of its box + its
    index in the box + o_g) dx: an Eulerian grid's nodes sit on the lattice."""
    S = t.scalar
    Gv = wp.types.vector(n_grids, S)
    strides = make_strides(t)
    node_box = make_node_box(t)

    @wp.func
    def node_position(i: int, lo: wp.array(dtype=t.ivec), shape: wp.array(dtype=t.ivec),
                      offset: wp.array(dtype=wp.int32), n_boxes: int, grid_offsets: Gv, dx: S):
        box = node_box(i, offset, n_boxes)
        local = i - offset[box]
        st = strides(shape[box])
        corner = lo[box]
        x = t.vec()
        for d in range(wp.static(t.dim)):
            k = local / st[d]
            local = local - k * st[d]
            x[d] = (S(corner[d] + k) + grid_offsets[box % wp.static(n_grids)]) * dx
        return x

    return node_position
