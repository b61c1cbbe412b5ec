"""The configuration update (A-ULMPM paper, section 5.7).

For the particles of the bodies being updated:
    X <- x,  F^0s <- project(F^sn F^0s),  F^sn <- I,
    C <- C (F^sn)^-1 when the scheme re-expresses the affine matrix,
and the stencil cache is recomputed in the body's new reference grids: per
grid the first node, the local coordinate, the weights (and their
derivatives for gradient-based transfers), and, when the kernel's second
moment varies with the particle (compact; linear too, unused there), the
MLS/APIC moment inverse
    K_p = (1/G sum_g sum_i w_ip r r^T + delta dx^2 I)^-1,   r = X_i - X_p,
with delta = 1e-6 keeping it finite where a moment vanishes. The weights are
tensor products whose 1-D factors sum to one, so per grid
    sum_i w r_a r_b = m2_a (a = b),  m1_a m1_b (a != b),
with the 1-D moments m1_a = sum_s w_as r_as, m2_a = sum_s w_as r_as^2: d
support terms instead of support^d. For B-splines with a full stencil
K_p = I/(moment dx^2) is a constant of the solver and not cached.
"""

import functools

import warp as wp

from .kernels import Kernel
from .launch import warp_kernel
from .stencil import make_locate, make_origin, make_stencil_cache
from .types import Types

MOMENT_REGULARISATION = 1.0e-6


@functools.cache
def make_update(t: Types, kernel: Kernel, project, transform_affine: bool, gradients: bool,
                fused: bool = False, moment: bool = True):
    """``project``: the material's projection factory or None; ``gradients``:
    cache the weight derivatives too (APIC and PIC transfers); ``fused``: the
    transfers locate the stencils themselves (mpm.stencil.fuse): only K_p is
    cached; ``moment``: the transfer uses K_p (not PIC), built when the
    kernel's moment varies per particle."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    locate = make_locate(t, kernel, gradients)
    origin = make_origin(t, kernel, gradients)
    proj = project(t) if project is not None else None
    Cache = make_stencil_cache(t, kernel)
    Gv = wp.types.vector(G, S)
    per_particle_K = moment and kernel.moment is None
    # grids whose stencils the update locates: none when the transfers locate them and K_p is not cached
    n_located = 0 if fused and not per_particle_K else G
    inv_G = 1.0 / G

    @warp_kernel
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
        cache: Cache,
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
        if wp.static(n_located > 0):  # the grids' shared sines only where a stencil is located
            u0, P = origin(Xp, S(1.0) / dx, grid_offsets)
        for g in range(wp.static(n_located)):
            box = b * G + g
            flat, fx, W, dW = locate(u0, P, grid_offsets[g] - grid_offsets[0], g, lo[box], shape[box], offset[box])
            if wp.static(not fused):
                k = p * G + g
                cache.base[k] = flat
                cache.fx[k] = fx
                cache.W[k] = W
                if wp.static(gradients):
                    cache.dW[k] = dW
            if wp.static(per_particle_K):
                m1 = t.vec()
                m2 = t.vec()
                for a in range(dim):
                    for s in range(Ks):
                        r = (S(s) - fx[a]) * dx
                        m1[a] += W[a, s] * r
                        m2[a] += W[a, s] * r * r
                D += wp.outer(m1, m1)
                for a in range(dim):
                    D[a, a] += m2[a] - m1[a] * m1[a]
        if wp.static(per_particle_K):
            cache.K[p] = wp.inverse(S(inv_G) * D + S(MOMENT_REGULARISATION) * dx * dx
                                    * wp.identity(n=dim, dtype=S))

    return update
