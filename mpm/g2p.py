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
"""

import functools

import warp as wp

from .reference_update import make_committed, make_moment_at
from .kernels import Kernel
from .launch import warp_kernel
from .stepping.status import StepControl, StepStatus
from .stencil import make_cached, make_node, make_node_gradient, make_stencil_cache
from .types import Types


@functools.cache
def make_min_stretch2(t: Types):
    """``min_stretch2(F)``: the square of the smallest singular value of F,
    exact in 2D (the stable root 2 det^2 / (|F|^2 + sqrt(|F|^4 - 4 det^2)));
    in 3D the lower bound 3 det^2 / |cof F|^2, equal to 1 at F = I and never
    below a third of the true value."""
    S = t.scalar

    @wp.func
    def min_stretch2(F: t.mat):
        d = wp.determinant(F)
        if wp.static(t.dim == 2):
            f2 = wp.ddot(F, F)
            return S(2.0) * d * d / wp.max(f2 + wp.sqrt(wp.max(f2 * f2 - S(4.0) * d * d, S(0.0))),
                                           S(1.0e-30))
        else:
            G = wp.transpose(wp.inverse(F)) * d  # cofactor matrix
            return wp.min(S(3.0) * d * d / wp.max(wp.ddot(G, G), S(1.0e-30)), S(1.0))

    return min_stretch2


@functools.cache
def make_g2p(t: Types, kernel: Kernel, transfer: str, record_dJ: bool, count_marked: bool,
             lagrangian: bool, track_compression: bool, track_energy: bool = False,
             track_inversion: bool = False, removal: bool = False, fused: bool = False,
             bound_reach: bool = False, commit: bool = False, project=None, batched: bool = False,
             loads: bool = False, compensate: bool = False):
    """G2P for all particles, for the step ``control.dt`` (``batched``: nothing
    in a step the driver skips, mpm.stepping.driver).

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
    :func:`make_min_stretch2`) per body (mpm.stepping.detection);
    ``compensate``: x and F^sn as compensated sums with their running errors
    ``xc`` [m] and ``Fc`` (module docstring; with ``commit``, F^0s's unless
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
    S = t.scalar
    f64 = wp.float64
    vec, mat = t.vec, t.mat
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    comp_F0 = compensate and commit and project is None  # F^0s's sum (EMPM's commit)
    comp_Fsn = compensate and not commit  # F^sn's sum
    node = make_node(t, kernel)
    node_gradient = make_node_gradient(t, kernel)
    Cache = make_stencil_cache(t, kernel)
    min_stretch2 = make_min_stretch2(t)
    per_particle_K = kernel.moment is None
    mls = transfer == "mls" and not kernel.gradient_affine
    affine = transfer not in ("pic", "flip")
    flip = transfer == "flip"
    affine_from_gradient = affine and kernel.gradient_affine
    with_B = affine and not affine_from_gradient  # B = sum w v r^T for C
    reference, cached = make_cached(t, kernel, not mls, fused)
    inv_G = 1.0 / G
    committed = make_committed(t, project)
    moment_at = make_moment_at(t, kernel, not mls)
    commit_K = commit and per_particle_K and affine  # the update's K_p (the affine transfers read it)

    @wp.func
    def commit_reference(p: int, Xp: vec, Fs: mat, F0: mat, params: t.params, F0s: wp.array(dtype=mat),
                         Fsn: wp.array(dtype=mat), cache: Cache, dx: S):
        """The reference configuration moves to Xp (``commit``)."""
        cache.X[p] = Xp
        F0s[p] = committed(Fs, F0, params)
        Fsn[p] = wp.identity(n=dim, dtype=S)
        if wp.static(commit_K):
            cache.K[p] = moment_at(Xp, S(1.0) / dx, cache.grid_offsets, dx)

    @wp.func
    def commit_compensated(p: int, Xp: vec, D: mat, F0: mat, F0s: wp.array(dtype=mat),
                           Fsn: wp.array(dtype=mat), Fc: wp.array(dtype=mat), cache: Cache, dx: S):
        """``commit_reference`` with F^0s <- F^0s + D F^0s, D = dt grad v, a
        compensated sum whose running error is Fc (``comp_F0``)."""
        cache.X[p] = Xp
        y = D * F0 - Fc[p]
        F0n = F0 + y
        Fc[p] = (F0n - F0) - y
        F0s[p] = F0n
        Fsn[p] = wp.identity(n=dim, dtype=S)
        if wp.static(commit_K):
            cache.K[p] = moment_at(Xp, S(1.0) / dx, cache.grid_offsets, dx)

    @wp.func
    def slab(col: vec, r: S, v: vec):
        """A column of B / dx takes in a slab's weighted velocity v at offset
        r = index - fx; the next slab's offset."""
        col_next = col
        if wp.static(with_B):
            col_next = col + r * v
        return col_next, r + S(1.0)

    @wp.func
    def row_sum_norm(F: mat):
        """|F|_inf = max_d sum_k |F_dk|: |(F r)_d| <= |F|_inf max_k |r_k|."""
        n = S(0.0)
        for d in range(wp.static(dim)):
            row = S(0.0)
            for k in range(wp.static(dim)):
                row += wp.abs(F[d, k])
            n = wp.max(n, row)
        return n

    @wp.func
    def grow_box(status: StepStatus, b: int, xp: t.vec):
        """Body b's bounding box of the new positions (the next reference grids) takes in xp."""
        for d in range(wp.static(dim)):
            wp.atomic_min(status.box_lo, b * dim + d, f64(xp[d]))
            wp.atomic_max(status.box_hi, b * dim + d, f64(xp[d]))

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
    ):
        if wp.static(batched):
            if control.skip[0] != f64(0.0):
                return
        dt = S(control.dt[0])
        p = wp.tid()
        b = body[p]
        if wp.static(removal):
            if mass[p] == S(0.0):  # removed: parked inside, still in its body's reference box
                grow_box(status, b, x[p])
                if wp.static(commit):
                    commit_reference(p, x[p], Fsn[p], F0s[p], body_params[b], F0s, Fsn, cache, dx)
                return
        vp = vec()
        v_transferred = vec()  # FLIP: sum w p0_i / m_i
        B = mat()
        grad_v = mat()
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            # B = sum w v_i r^T with r = (index - fx) dx: per axis, the weighted velocities summed over
            # the stencil's slabs, times the slab's offset index - fx (no outer product per node)
            col0 = vec()
            col1 = vec()
            col2 = vec()
            ra = -fx[0]  # the slabs' offsets r / dx
            for a in range(Ks):
                va = vec()
                rb = -fx[1]
                for bb in range(Ks):
                    vb = vec()
                    rc = -fx[dim - 1]
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        vi = grid_v[i]
                        wv = w * vi
                        if wp.static(flip):
                            if w > S(0.0):
                                v_transferred += (w / grid_m[i]) * grid_p0[i]
                        vb += wv
                        if wp.static(dim == 3):
                            col2, rc = slab(col2, rc, wv)
                        if wp.static(not mls):
                            grad_v += wp.outer(vi, node_gradient(a, bb, c, W, dW, S(1.0) / dx))
                    va += vb
                    col1, rb = slab(col1, rb, vb)
                vp += va
                col0, ra = slab(col0, ra, va)
            if wp.static(with_B):
                if wp.static(dim == 3):
                    B += dx * wp.matrix_from_cols(col0, col1, col2)
                else:
                    B += dx * wp.matrix_from_cols(col0, col1)
        vp = S(inv_G) * vp
        v_new = vp  # the particle's new velocity (the positions move with PIC's, vp)
        if wp.static(flip):
            v_new = vp + flip_share * (v[p] - S(inv_G) * v_transferred)
        Cp = mat()
        if wp.static(mls):
            if wp.static(per_particle_K):
                Cp = S(inv_G) * B * cache.K[p]
            else:
                Cp = (S(inv_G) * K) * B
            grad_v = Cp
        else:
            grad_v = S(inv_G) * grad_v
            if wp.static(affine_from_gradient):
                Cp = grad_v
            elif wp.static(affine):
                if wp.static(per_particle_K):
                    Cp = S(inv_G) * B * cache.K[p]
                else:
                    Cp = (S(inv_G) * K) * B
        xp = x[p] + dt * vp
        if wp.static(compensate):
            x_old = x[p]
            yx = dt * vp - xc[p]
            xp = x_old + yx
            xc_new = (xp - x_old) - yx
        Fsn_old = Fsn[p]
        Fs = Fsn_old + dt * grad_v
        if wp.static(comp_Fsn):
            yF = dt * grad_v - Fc[p]
            Fs = Fsn_old + yF
            Fc_new = (Fs - Fsn_old) - yF
        if wp.static(removal):
            gone = False
            for d in range(wp.static(dim)):
                if (xp[d] < inside_lo[d] and open_lo[d] > S(0.0)) or (xp[d] > inside_hi[d] and open_hi[d] > S(0.0)):
                    gone = True
            if gone and wp.isfinite(xp):
                for d in range(wp.static(dim)):
                    xp[d] = wp.clamp(xp[d], inside_lo[d], inside_hi[d])
                x[p] = xp
                v[p] = vec()
                C[p] = mat()
                mass[p] = S(0.0)
                volume[p] = S(0.0)
                wp.atomic_add(status.removed, b, f64(1.0))
                grow_box(status, b, xp)
                if wp.static(commit):  # F^sn was not advanced for a removed particle
                    commit_reference(p, xp, Fsn_old, F0s[p], body_params[b], F0s, Fsn, cache, dx)
                return
        if wp.static(loads):
            work = S(0.5) * dt * mass[p] * wp.dot(body_force[p], v[p] + v_new)
            wp.atomic_add(status.load_work, 0, f64(work))
        x[p] = xp
        if wp.static(compensate):
            xc[p] = xc_new
        v[p] = v_new
        C[p] = Cp
        if wp.static(not commit):
            Fsn[p] = Fs
            if wp.static(comp_Fsn):
                Fc[p] = Fc_new
        dj = wp.abs(wp.determinant(Fs) - S(1.0))
        if wp.static(record_dJ):
            dJ[p] = dj
        if wp.static(count_marked):
            if dj >= epsilon:
                wp.atomic_add(status.marked, b, f64(1.0))
            wp.atomic_max(status.max_dJ, b, f64(dj))
        if wp.static(track_compression or track_inversion):
            wp.atomic_min(status.min_J, b, f64(wp.determinant(Fs) * wp.determinant(F0s[p])))
        if wp.static(track_inversion):
            wp.atomic_min(status.min_F_stretch2, b, f64(min_stretch2(Fs * F0s[p])))
        # |L|^2 of the velocity gradient in current coordinates, L = grad_v (F^sn)^-1
        # (for EMPM F^sn was I: L = grad_v); a singular F^sn makes it non-finite
        rate2 = wp.ddot(grad_v, grad_v)
        if wp.static(lagrangian):
            s2 = min_stretch2(Fs)
            wp.atomic_min(status.min_stretch2, b, f64(s2))
            if wp.static(bound_reach):
                wp.atomic_max(status.max_F_norm, b, f64(row_sum_norm(Fs)))
            L = grad_v * wp.inverse(Fsn_old)
            rate2 = wp.ddot(L, L)
        wp.atomic_max(status.max_rate2, b, f64(rate2))

        # stability monitor and bounding box of the new positions
        v2 = f64(wp.dot(v_new, v_new))
        wp.atomic_max(status.max_v2, 0, v2)
        if wp.static(track_energy):
            wp.atomic_add(status.kinetic, 0, f64(0.5) * f64(mass[p]) * v2)
            wp.atomic_add(status.potential, 0, -f64(mass[p]) * f64(wp.dot(gravity, xp)))
            wp.atomic_max(status.max_speed2, b, v2)
        if not (wp.isfinite(xp) and wp.isfinite(v_new) and wp.isfinite(Fs)):
            wp.atomic_add(status.nonfinite, 0, f64(1.0))
        else:
            outside = False
            for d in range(wp.static(dim)):
                if xp[d] < inside_lo[d] or xp[d] > inside_hi[d]:
                    outside = True
            grow_box(status, b, xp)
            if outside:
                wp.atomic_add(status.outside, 0, f64(1.0))
        if wp.static(commit):
            if wp.static(comp_F0):
                commit_compensated(p, xp, dt * grad_v, F0s[p], F0s, Fsn, Fc, cache, dx)
            else:
                commit_reference(p, xp, Fs, F0s[p], body_params[b], F0s, Fsn, cache, dx)

    return g2p
