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

import numpy as np
import warp as wp

from .kernels import Kernel
from .launch import warp_kernel
from .stepping.status import StepControl
from .stencil import make_locate, make_origin, make_stencil_cache, make_weigh, weight_matrix_type
from .materials.decompositions import make_rotation
from .types import Types

MOMENT_REGULARISATION = 1.0e-6


@functools.cache
def make_moment(t: Types, kernel: Kernel):
    """``add_moment(D, fx, W, dx) -> D``: D [m^2] takes in one grid's share
    of the second moment sum_i w r r^T, from the 1-D moments (module
    docstring); ``moment_inverse(D, dx) -> K_p`` [1/m^2] of the sum over the
    grids."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    Wm = weight_matrix_type(t, kernel)
    inv_G = 1.0 / G

    @wp.func
    def add_moment(D: t.mat, fx: t.vec, W: Wm, dx: S):
        m1 = t.vec()
        m2 = t.vec()
        for a in range(dim):
            for s in range(Ks):
                r = (S(s) - fx[a]) * dx
                m1[a] += W[a, s] * r
                m2[a] += W[a, s] * r * r
        D_new = D + wp.outer(m1, m1)
        for a in range(dim):
            D_new[a, a] += m2[a] - m1[a] * m1[a]
        return D_new

    @wp.func
    def moment_inverse(D: t.mat, dx: S):
        return wp.inverse(S(inv_G) * D + S(MOMENT_REGULARISATION) * dx * dx * wp.identity(n=dim, dtype=S))

    return add_moment, moment_inverse


@functools.cache
def make_moment_at(t: Types, kernel: Kernel, gradients: bool):
    """``moment_at(X, inv_dx, grid_offsets, dx) -> K_p`` [1/m^2] at a
    reference position X [m], its stencils unclamped: those of the layout's
    boxes, which hold every stencil of the positions they were fitted to
    (``gradients``: the origin as the transfers with slopes compute it, so
    that the weights are theirs bit for bit). Where the host's float64 fit
    lets a box clamp a float32 stencil at its edge (fx = 1 exactly), only a
    zero weight moves and K_p is the same."""
    S = t.scalar
    G = kernel.n_grids
    Gv = wp.types.vector(G, S)
    weigh = make_weigh(t, kernel, gradients, clamped=False)
    origin = make_origin(t, kernel, gradients)
    add_moment, moment_inverse = make_moment(t, kernel)

    @wp.func
    def moment_at(X: t.vec, inv_dx: S, grid_offsets: Gv, dx: S):
        u0, P = origin(X, inv_dx, grid_offsets)
        D = t.mat()
        for g in range(wp.static(G)):
            _first, fx, W, _dW = weigh(u0, P, grid_offsets[g] - grid_offsets[0], g, t.ivec(), t.ivec())
            D = add_moment(D, fx, W, dx)
        return moment_inverse(D, dx)

    return moment_at


@functools.cache
def make_committed(t: Types, project):
    """``committed(F_sn, F_0s, params) -> F^0s`` of the new reference:
    project(F^sn F^0s) with the material's projection (``project``: its
    factory, or None)."""
    proj = project(t) if project is not None else None

    @wp.func
    def committed(Fsn: t.mat, F0s: t.mat, params: t.params):
        F = Fsn * F0s
        if wp.static(proj is not None):
            F = proj(F, params)  # pyright: ignore[reportOptionalCall]
        return F

    return committed


@functools.cache
def make_update(t: Types, kernel: Kernel, project, affine: str, gradients: bool,
                fused: bool = False, moment: bool = True, gated: bool = False, compensate: bool = False):
    """``project``: the material's projection factory or None; ``affine``: C
    over the update (mpm.schemes.AFFINE: keep, transform C <- C (F^sn)^-1,
    rotate C <- C R^T with F^sn = R U); ``gradients``:
    cache the weight derivatives too (APIC and PIC transfers); ``fused``: the
    transfers locate the stencils themselves (mpm.stencil.fuse): only K_p is
    cached; ``moment``: the transfer uses K_p (not PIC), built when the
    kernel's moment varies per particle; ``gated``: only when the criterion
    asked for it (``control.update`` of the body, mpm.stepping.criterion), so that the
    driver can launch it every step without the host; ``compensate``: G2P keeps
    F^sn as a compensated sum (mpm.g2p), whose running error ``Fc`` restarts
    at zero with F^sn = I."""
    S = t.scalar
    dim, G = t.dim, kernel.n_grids
    locate = make_locate(t, kernel, gradients)
    origin = make_origin(t, kernel, gradients)
    committed = make_committed(t, project)
    rotation = make_rotation(t)
    add_moment, moment_inverse = make_moment(t, kernel)
    moment_at = make_moment_at(t, kernel, gradients)
    Cache = make_stencil_cache(t, kernel)
    Gv = wp.types.vector(G, S)
    per_particle_K = moment and kernel.moment is None
    located = not fused  # the cache holds the stencils (fused: the transfers locate them)

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
        control: StepControl,
        # with compensate: the running error of G2P's sum of F^sn (mpm.g2p)
        Fc: wp.array(dtype=t.mat),
    ):
        p = wp.tid() + start  # pyright: ignore[reportOperatorIssue]
        b = body[p]
        if wp.static(gated):  # (a body whose grid must be refitted first: the host moves it)
            if (control.update[b] == wp.float64(0.0) or control.regrid[b] != wp.float64(0.0)
                    or control.skip[0] != wp.float64(0.0)):
                return
        Xp = x[p]
        Fs = Fsn[p]
        if wp.static(affine == "transform"):
            C[p] = C[p] * wp.inverse(Fs)
        if wp.static(affine == "rotate"):  # |C R^T| = |C|: the spin carried over, never amplified
            # an inverted F^sn has no polar rotation (the closest one flips a direction, turning C by
            # an arbitrary angle: the linear-kernel soft ball gained energy until it blew up): C kept
            if wp.determinant(Fs) > S(0.0):
                C[p] = C[p] * wp.transpose(rotation(Fs))
        X[p] = Xp
        F0s[p] = committed(Fs, F0s[p], body_params[b])
        Fsn[p] = wp.identity(n=dim, dtype=S)
        if wp.static(compensate):
            Fc[p] = t.mat()
        if wp.static(located):
            D = t.mat()
            u0, P = origin(Xp, S(1.0) / dx, grid_offsets)
            for g in range(wp.static(G)):
                box = b * G + g
                flat, fx, W, dW = locate(u0, P, grid_offsets[g] - grid_offsets[0], g, lo[box], shape[box],
                                         offset[box])
                k = p * G + g
                cache.base[k] = flat - offset[box]
                cache.fx[k] = fx
                cache.W[k] = W
                if wp.static(gradients):
                    cache.dW[k] = dW
                if wp.static(per_particle_K):
                    D = add_moment(D, fx, W, dx)
            if wp.static(per_particle_K):
                cache.K[p] = moment_inverse(D, dx)
        elif wp.static(per_particle_K):  # as G2P's commit computes it (mpm.transfer)
            cache.K[p] = moment_at(Xp, S(1.0) / dx, grid_offsets, dx)

    return update


class References:
    """The bodies' reference configurations on the device: their grids (the
    boxes of ``layout``, whose nodal fields ``grid`` grows to fit) and the
    update of their particles (one kernel per body, for its material's
    projection; a gated twin for the driver, mpm.stepping.driver). ``affine``: C
    over an update (mpm.schemes.AFFINE); ``gradients``, ``fused``, ``moment``:
    what the stencil cache holds; ``compensate``: restart G2P's compensated sum
    of F^sn (:func:`make_update`)."""

    def __init__(self, model, launch, layout, grid, control, *, affine: str, gradients: bool, fused: bool,
                 moment: bool, compensate: bool = False):
        t, k = model.types, model.kernel
        self.model, self.launch, self.layout, self.grid, self.control = model, launch, layout, grid, control
        options = dict(gradients=gradients, fused=fused, moment=moment, compensate=compensate)
        self.update = [make_update(t, k, b.material.project, affine, **options) for b in model.scene.bodies]
        self.gated = [make_update(t, k, b.material.project, affine, gated=True, **options)
                      for b in model.scene.bodies]

    def kernels(self, gated: bool = False) -> list:
        return list(self.gated if gated else self.update)

    def fit(self, bodies, lo, hi, pad: float = 0.0) -> None:
        """Grids for ``bodies`` covering every stencil of positions within
        ``lo``/``hi`` [body, axis] [m], grown by ``pad`` [m] on every side; the
        nodal fields grow to fit."""
        for b in bodies:
            self.layout.fit(b, np.asarray(lo[b], float) - pad, np.asarray(hi[b], float) + pad)
        self.layout.commit()
        self.grid.reserve(self.layout.n_nodes)

    def move(self, state, bodies, const, gated: bool = False) -> None:
        """X <- x for the particles of ``bodies`` (module docstring), in their
        current grids; ``gated``: those whose criterion fired (``control.update``)."""
        m, lay = self.model, self.layout
        kernels = self.gated if gated else self.update
        for b in bodies:
            start, count = m.body_ranges[b]
            self.launch(kernels[b], count, [
                m.body, m.body_params, lay.lo_d, lay.shape_d, lay.offset_d, const.grid_offsets, const.dx,
                start, state.x, state.X, state.C, state.F0s, state.Fsn, state.stencils, self.control, state.Fc])
