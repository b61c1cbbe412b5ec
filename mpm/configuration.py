"""The configuration update (A-ULMPM paper, section 5.7).

For the particles of the bodies being updated:
    X <- x,  F^0s <- project(F^sn F^0s),  F^sn <- I,
    C <- C (F^sn)^-1 when the scheme re-expresses the affine matrix,
and the stencil cache is recomputed in the body's new reference grids: per
grid the first node, the local coordinate, the weights (and their
derivatives for gradient-based transfers), and, when the kernel's second
moment varies with the particle (linear, compact), the MLS/APIC moment inverse
    K_p = (1/G sum_g sum_i w_ip r r^T + delta dx^2 I)^-1,   r = X_i - X_p,
with delta = 1e-6 keeping it finite where the linear kernel's moment vanishes
(a particle on a node). For B-splines with a full stencil K_p = I/(moment dx^2)
is a constant of the solver and not cached.
"""

import functools

import warp as wp

from .kernels import Kernel
from .stencil import make_locate, make_node, make_strides, weight_matrix_type
from .types import Types

MOMENT_REGULARISATION = 1.0e-6


@functools.cache
def make_update(t: Types, kernel: Kernel, project, transform_affine: bool, gradients: bool):
    """``project``: the material's projection factory or None; ``gradients``:
    cache the weight derivatives too (APIC and PIC transfers)."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    locate = make_locate(t, kernel)
    node = make_node(t, kernel)
    strides = make_strides(t)
    proj = project(t) if project is not None else None
    Wm = weight_matrix_type(t, kernel)
    Gv = wp.types.vector(G, S)
    per_particle_K = kernel.moment is None
    inv_G = 1.0 / G

    @wp.kernel(module="unique")
    def update(
        # Model:
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        # Layout of the new reference grids (box b * G + g):
        lo: wp.array(dtype=t.ivec),
        shape: wp.array(dtype=t.ivec),
        offset: wp.array(dtype=wp.int32),
        grid_offsets: Gv,
        dx: S,
        start: int,
        # State in/out:
        x: wp.array(dtype=t.vec),
        X: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        # Stencil cache out (entry p * G + g; K_p per particle):
        cache_base: wp.array(dtype=wp.int32),
        cache_fx: wp.array(dtype=t.vec),
        cache_W: wp.array(dtype=Wm),
        cache_dW: wp.array(dtype=Wm),
        cache_K: wp.array(dtype=t.mat),
    ):
        p = wp.tid() + start
        b = body[p]
        Xp = x[p]
        Fs = Fsn[p]
        F = Fs * F0s[p]
        if wp.static(proj is not None):
            F = proj(F, body_params[b])
        if wp.static(transform_affine):
            C[p] = C[p] * wp.inverse(Fs)
        X[p] = Xp
        F0s[p] = F
        Fsn[p] = wp.identity(n=dim, dtype=S)
        D = t.mat()
        for g in range(G):
            box = b * G + g
            flat, fx, W, dW = locate(Xp, S(1.0) / dx, grid_offsets[g], lo[box], shape[box], offset[box])
            k = p * G + g
            cache_base[k] = flat
            cache_fx[k] = fx
            cache_W[k] = W
            if wp.static(gradients):
                cache_dW[k] = dW
            if wp.static(per_particle_K):
                st = strides(shape[box])
                for a in range(Ks):
                    for bb in range(Ks):
                        for c in range(wp.static(Ks if dim == 3 else 1)):
                            w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                            D += w * wp.outer(r, r)
        if wp.static(per_particle_K):
            cache_K[p] = wp.inverse(S(inv_G) * D + S(MOMENT_REGULARISATION) * dx * dx
                                    * wp.identity(n=dim, dtype=S))

    return update
