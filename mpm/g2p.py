"""Grid to particle (G2P), averaged over the kernel's G grids (A-ULMPM paper,
eq. 28, 30, 31; notation: mpm.transfer):
    v_p = 1/G sum_g sum_i W_ip v_i,   C_p = 1/G sum_g sum_i W_ip v_i r^T K_p (MLS, APIC),
    FLIP: v_p <- v_p^PIC + beta (v_p^n - 1/G sum_g sum_i W_ip p0_i / m_i) (the blend beta),
    x_p += dt v_p,   F^{sn} += dt grad v,   dJ_p = |det F^{sn} - 1|,
grad v = C_p for MLS, 1/G sum v_i grad_ip^T for APIC and PIC. On the way,
the step's stability figures (mpm.stepping.status).

Compensated sums (``compensate``, mpm.SolverOptions.compensate): a step's
increments dt v and dt grad v can fall below float32's spacing of the sums
they are added to (mpm.precision), and rounded away every step the sums
drift. Kept as compensated (Kahan) sums, each with the running error of
its sum (State.xc, State.Fc),
    y = inc - c,   s' = s + y,   c' = (s' - s) - y,
they keep the increments' lost bits: x and F^sn (with EMPM's commit, F^0s,
updated as F^0s + (dt grad v) F^0s). The configuration update restarts
F^sn's (mpm.reference_update).

The flags of :func:`make_g2p` (``batched``: nothing in a step the driver
skips, mpm.stepping.driver); the stages are mpm.g2p_stages'.

``removal`` (a domain with open faces): a particle that crosses the
interior's bound on an open face (``open_lo``/``open_hi`` 1 per axis) is
removed: its mass and volume become 0 (so no transfer sees it again), it
stays where it crossed, clamped to the interior, at rest, and G2P skips
it from then on; ``status.removed`` counts the removals per body. A
particle crossing a closed face still counts as outside (unstable).
``fused``: stencils located from the reference positions (mpm.stencil.fuse);
``commit`` (with it: the Eulerian scheme, whose reference follows the
particles every step): G2P also does the configuration update
(mpm.reference_update) that would otherwise be a pass of its own: X <- x,
F^0s <- project(F^sn F^0s) (``project``: the bodies' common projection
factory, or None), F^sn <- I (the Eulerian scheme keeps C as it is), and
K_p at the new position where the kernel's moment varies: the same
arithmetic, so every step that completes ends as with the separate update,
bit for bit. (A failed step - non-finite, outside - has moved the
references too, where the separate update would not run; the run stops
there. The massless particles of a body whose particles were all removed
keep being committed in place.)

``lagrangian``: the reference may lag behind (not EMPM), so track the
narrowest current cell and take the velocity gradient as C (F^sn)^-1 (for
EMPM F^sn = I at the start of every step: it is C); ``bound_reach`` (with
it): the largest |F^sn|_inf, the largest absolute row sum, which bounds
how far a node sits from its particles (mpm.solver);
``track_compression``: a material stiffens under compression (a fluid);
``track_energy``: sum the new state's kinetic energy 1/2 m |v|^2 and
potential energy -m g . x [J], and each body's largest |v_p|^2
(mpm.stepping.detection; no extra pass);
``loads``: the external loads' work over the step (mpm.loads), the
trapezoidal dt m_p b_p . (v_p + v_p') / 2 with the step's body force b_p
and the particle's velocities before and after, into ``status.load_work``
(exact for a free particle, and no work under a load held still);
``track_inversion``: the smallest J and the smallest stretch of F (its
smallest singular value, squared; in 3D a lower bound, see
mpm.g2p_stages.make_min_stretch2) per body (mpm.stepping.detection);
``compensate``: x and F^sn as compensated sums with their running errors
``xc`` [m] and ``Fc`` (above; with ``commit``, F^0s's unless
``project`` is given: a projected F^0s is committed as before).

``status`` (mpm.stepping.status.StepStatus) accumulates the largest |v_p|^2, the
non-finite and outside counts, then per body the marked count
(``count_marked``: dJ_p >= epsilon), the largest dJ_p, the smallest J = det F^{0n} (for the time step of materials
that stiffen under compression), the smallest stretch of F^sn (a
reference cell of width dx is sigma_min(F^sn) dx wide now, and the time
step must shrink with it), the largest velocity gradient |L| (the strain
increment dt |L| of a step must stay small), the largest speed
(``track_energy``), the smallest stretch of F (``track_inversion``), the
largest |F^sn|_inf (``bound_reach``), and the bounding box of the new
positions (min per axis, then max per axis).
"""

import functools

import warp as wp

from .g2p_stages import (make_advance, make_affine, make_commit, make_figures, make_removal,
                         make_velocity_sums, transfer_flags)
from .grid import make_boundary_data
from .keep_out import make_keep_out
from .kernels import Kernel
from .launch import warp_kernel
from .stepping.status import StepControl, StepStatus
from .stencil import make_stencil_cache
from .types import Types


@functools.cache
def make_g2p(t: Types, kernel: Kernel, transfer: str, record_dJ: bool, count_marked: bool,
             lagrangian: bool, track_compression: bool, track_energy: bool = False,
             track_inversion: bool = False, removal: bool = False, fused: bool = False,
             bound_reach: bool = False, commit: bool = False, project=None, batched: bool = False,
             loads: bool = False, compensate: bool = False, keep_out: bool = False, colliders: tuple = ()):
    """G2P for all particles, for the step ``control.dt``; the flags are the
    module docstring's; ``keep_out``: put the particles back out of the
    closed walls and the colliders (the shapes ``colliders``), mpm.keep_out."""
    S = t.scalar
    f64 = wp.float64
    comp_F0 = compensate and commit and project is None  # F^0s's sum (EMPM's commit)
    Cache = make_stencil_cache(t, kernel)
    flip = transfer_flags(kernel, transfer)[2]
    inv_G = 1.0 / kernel.n_grids
    sums = make_velocity_sums(t, kernel, transfer, fused)
    affine_C = make_affine(t, kernel, transfer)
    advance, store = make_advance(t, compensate, commit)
    commit_reference, commit_compensated = make_commit(t, kernel, transfer, project)
    remove, parked = make_removal(t, kernel, transfer, project, commit)
    Boundary = make_boundary_data(t)
    put_out = make_keep_out(t, colliders, kernel.n_grids) if keep_out else None
    deformation, motion = make_figures(t, record_dJ, count_marked, lagrangian, track_compression, track_energy,
                                       track_inversion, bound_reach)

    @warp_kernel
    def g2p(
        # Model:
        body: wp.array(dtype=wp.int32),
        shape: wp.array(dtype=t.ivec),
        # Grid in:
        grid_v: wp.array(dtype=t.vec),
        grid_m: wp.array(dtype=S),  # (FLIP)
        grid_p0: wp.array(dtype=t.vec),  # FLIP: the momentum P2G transferred alone
        flip_share: S,  # FLIP: beta, the share of the particle's own velocity updated by the grid's change
        # Stencil cache:
        cache: Cache,
        # Step:
        dx: S,
        K: S,
        control: StepControl,
        epsilon: S,
        inside_lo: t.vec,
        inside_hi: t.vec,
        # State in/out:
        x: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        dJ: wp.array(dtype=S),
        status: StepStatus,
        # with track_energy or removal:
        mass: wp.array(dtype=S),
        gravity: t.vec,
        # with removal:
        volume: wp.array(dtype=S),
        open_lo: t.vec,
        open_hi: t.vec,
        # with commit:
        body_params: wp.array(dtype=t.params),
        # with loads: the step's body force [m/s^2]
        body_force: wp.array(dtype=t.vec),
        # with compensate: the running errors of the sums of x [m] and of F^sn (F^0s with commit)
        xc: wp.array(dtype=t.vec),
        Fc: wp.array(dtype=t.mat),
        # with keep_out: the walls and colliders (mpm.grid)
        boundary: Boundary,
    ):
        if wp.static(batched):
            if control.skip[0] != f64(0.0):
                return
        dt = S(control.dt[0])
        p = wp.tid()
        b = body[p]
        if wp.static(removal):
            if parked(p, b, x, mass, status, body_params, F0s, Fsn, cache, dx):  # pyright: ignore[reportArgumentType]
                return
        vp, v_transferred, B, grad_v = sums(p, b, shape, cache, grid_v, grid_m, grid_p0, dx)  # pyright: ignore[reportArgumentType]
        vp = S(inv_G) * vp
        v_new = vp  # the particle's new velocity (the positions move with PIC's, vp)
        if wp.static(flip):
            v_new = vp + flip_share * (v[p] - S(inv_G) * v_transferred)
        Cp, grad_v = affine_C(p, B, grad_v, K, cache)  # pyright: ignore[reportArgumentType]
        xp, xc_new, Fsn_old, Fs, Fc_new = advance(p, dt, vp, grad_v, x, xc, Fsn, Fc)  # pyright: ignore[reportArgumentType]
        if wp.static(put_out is not None):
            xp, v_new = put_out(xp, v_new, mass[p], S(control.t[0]) + dt, boundary, inside_lo, inside_hi, status)  # pyright: ignore[reportOptionalCall]
        if wp.static(removal):
            if remove(p, b, xp, Fsn_old, inside_lo, inside_hi, open_lo, open_hi, x, v, C, mass, volume,  # pyright: ignore[reportArgumentType]
                      status, body_params, F0s, Fsn, cache, dx):
                return
        if wp.static(loads):
            work = S(0.5) * dt * mass[p] * wp.dot(body_force[p], v[p] + v_new)
            wp.atomic_add(status.load_work, 0, f64(work))
        store(p, xp, xc_new, v_new, Cp, Fs, Fc_new, x, xc, v, C, Fsn, Fc)  # pyright: ignore[reportArgumentType]
        deformation(p, b, Fs, Fsn_old, grad_v, epsilon, F0s, dJ, status)  # pyright: ignore[reportArgumentType]
        motion(p, b, mass, xp, v_new, Fs, gravity, inside_lo, inside_hi, status)  # pyright: ignore[reportArgumentType]
        if wp.static(commit):
            if wp.static(comp_F0):
                commit_compensated(p, xp, dt * grad_v, F0s[p], F0s, Fsn, Fc, cache, dx)  # pyright: ignore[reportArgumentType]
            else:
                commit_reference(p, xp, Fs, F0s[p], body_params[b], F0s, Fsn, cache, dx)  # pyright: ignore[reportArgumentType]

    return g2p
