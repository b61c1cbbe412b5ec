"""The configuration update (A-ULMPM paper, section 5.7).

For the particles of the bodies being updated:
    X <- x,  F^0s <- project(F^sn F^0s),  F^sn <- I,
    C <- C (F^sn)^-1 when the scheme re-expresses the affine matrix,
and the stencil cache (first node, local coordinate, weights) is recomputed
in the body's new reference grid. For the quadratic B-spline the MLS moment
inverse K_p = 4/dx^2 I is the same for every particle and is not cached.
"""

import functools

import warp as wp

from .kernels import Kernel
from .stencil import make_locate, weight_matrix_type
from .types import Types


@functools.cache
def make_update(t: Types, kernel: Kernel, project, transform_affine: bool):
    """``project``: the material's projection factory or None."""
    S = t.scalar
    dim = t.dim
    locate = make_locate(t, kernel)
    proj = project(t) if project is not None else None
    Wm = weight_matrix_type(t, kernel)

    @wp.kernel(module="unique")
    def update(
        # Model:
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        # Layout of the new reference grids:
        lo: wp.array(dtype=t.ivec),
        shape: wp.array(dtype=t.ivec),
        offset: wp.array(dtype=wp.int32),
        inv_dx: S,
        start: int,
        # State in/out:
        x: wp.array(dtype=t.vec),
        X: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        # Stencil cache out:
        cache_base: wp.array(dtype=wp.int32),
        cache_fx: wp.array(dtype=t.vec),
        cache_W: wp.array(dtype=Wm),
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
        flat, fx, W = locate(Xp, inv_dx, lo[b], shape[b], offset[b])
        cache_base[p] = flat
        cache_fx[p] = fx
        cache_W[p] = W

    return update
