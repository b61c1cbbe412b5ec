"""Particle to grid (P2G), in each body's reference configuration, on every
grid of the kernel (A-ULMPM paper, eq. 10-12, 20, 23; notation: mpm.transfer).

Every grid g of the kernel receives the particle's full mass (for plastic
models after the return mapping, with F_E = F^sn F^0s in place of F^{0n}:
mpm.materials.plastic):
    m_i      = sum_p W_ip m_p
    m_i v_i  = sum_p W_ip [m_p v_p + m_p C_p r] - dt V_p^0 P(F^{0n}) F^{0s,T} grad_ip
    m_i q_i  = sum_p W_ip m_p (x_p + F^{sn}_p r)     (current node positions)
    p0_i     = sum_p W_ip m_p v_p                    (FLIP: the momentum transferred alone)
with grad_ip = K_p r W_ip for the MLS transfer (force and momentum fused as in
MLS-MPM) and the kernel's own weight gradient for APIC and PIC (no affine
term for PIC). After division by m_i the nodal velocity holds the internal-
force impulse. The stored energy sum_p V_p^0 psi(F^{0n}_p) of the state the
step starts from is accumulated on the way (one decomposition of F for
stress and energy).
"""

import functools

import warp as wp

from .kernels import Kernel
from .launch import warp_kernel
from .materials.plastic import make_plastic_update
from .stepping.status import StepControl, StepStatus
from .stencil import make_cached, make_node, make_node_gradient, make_stencil_cache
from .types import Types, make_types


def make_p2g(t: Types, kernel: Kernel, transfer: str, material, with_regions: bool,
             with_body_force: bool = False, lagrangian: bool = True, with_stress: bool = True,
             fused: bool = False, batched: bool = False, gradients: bool = False, compensated: str = ""):
    """P2G for the particles of one material model: see :func:`_make_p2g`
    (``lagrangian`` False, the Eulerian scheme: no node positions, which sit
    on the lattice, and F^sn = I in the return mapping; ``fused``: stencils
    located from the reference positions, mpm.stencil.fuse; ``compensated``:
    which factor of F G2P keeps as a compensated sum, "sn" or "0s", or ""
    (none): with it the stored energy of an elastic model is evaluated in
    float64 (:func:`make_exact_energy`))."""
    return _make_p2g(t, kernel, transfer, material, with_regions, with_body_force,
                     lagrangian or not material.plastic, with_stress, fused, positions=lagrangian,
                     batched=batched, gradients=gradients,
                     compensated=compensated if not material.plastic else "")


@functools.cache
def _make_p2g(t: Types, kernel: Kernel, transfer: str, material, with_regions: bool,
              with_body_force: bool, lagrangian: bool, with_stress: bool = True, fused: bool = False,
              positions: bool = True, batched: bool = False, gradients: bool = False, compensated: str = ""):
    """P2G for the particles of one material model (``material`` is its class);
    ``with_regions``: also the mass each node draws from kinematic regions;
    ``with_body_force``: add the impulse m_p b_p dt of a per-particle body
    force b [m/s^2] (a manufactured solution's) to the node momenta.

    A plastic model's return mapping runs first (mpm.materials.plastic): the
    trial F_E = F^sn F^0s is returned, the stress is that of the returned F_E,
    and, when ``write`` is set (a step, not a stress evaluation between
    steps), F^0s <- (F^sn)^-1 F_E and the history variables are stored;
    ``lagrangian`` False (EMPM) knows F^sn = I here and stores F_E as it is.
    A model that hardens records its largest stiffening factor per body in
    ``status`` (for the time step). ``with_stress`` False leaves the stress
    impulse out (the implicit integrator adds the stress of the step's end,
    mpm.implicit); the return mapping and the energy stay.

    The step is ``control.dt`` (0 when not ``write``: the stored energy of a
    state between steps); ``control.positions`` 0 leaves the node positions
    out in a step where no boundary condition can reach the body
    (mpm.stepping.criterion); ``batched``: nothing happens in a step the driver
    skips (``control.skip``, mpm.stepping.driver)."""
    f64 = wp.float64
    S = t.scalar
    Cache = make_stencil_cache(t, kernel)
    stress_of = make_stress(t, material, lagrangian)
    exact_energy = make_exact_energy(t, material, compensated) if compensated else None
    momentum = make_momentum(t, kernel, transfer, with_body_force, positions)
    scatter = make_scatter(t, kernel, transfer, with_regions, positions, fused, gradients)

    @warp_kernel
    def p2g(
        # Model:
        mass: wp.array(dtype=S),
        volume: wp.array(dtype=S),
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        shape: wp.array(dtype=t.ivec),
        # State in:
        x: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        body_force: wp.array(dtype=t.vec),
        history: wp.array(dtype=t.history),  # plastic models: in/out, with F0s (``write``)
        Fc: wp.array(dtype=t.mat),  # compensated: the running error of F^sn's (or F^0s's) sum (mpm.g2p)
        # Stencil cache:
        cache: Cache,
        # Step:
        dx: S,
        K: S,
        start: int,
        write: int,  # 0: the stored energy of a state between steps (no step, nothing stored)
        # Grid out:
        grid_m: wp.array(dtype=S),
        grid_mv: wp.array(dtype=t.vec),
        grid_mq: wp.array(dtype=t.vec),
        grid_p0: wp.array(dtype=t.vec),  # FLIP: the transferred momentum alone, sum w m v
        grid_G: wp.array(dtype=t.mat),  # gradients: sum w m grad v (current coordinates)
        region: wp.array(dtype=wp.int32),
        grid_kin: wp.array(dtype=S),
        grid_kin_id: wp.array(dtype=wp.int32),
        # Step figures out (elastic energy, stiffening), clock in:
        status: StepStatus,
        control: StepControl,
    ):
        if wp.static(batched):
            if control.skip[0] != f64(0.0):
                return
        dt = S(0.0)
        if write != 0:
            dt = S(control.dt[0])
        sum_positions = int(control.positions[0])
        p = wp.tid() + start  # pyright: ignore[reportOperatorIssue]
        b = body[p]
        m = mass[p]
        xp = x[p]
        Cp = C[p]
        Fs = Fsn[p]
        P, psi, F0 = stress_of(p, b, dt, write, Fs, F0s[p], Cp, body_params, history, F0s, status)
        if wp.static(exact_energy is not None):
            wp.atomic_add(status.elastic, 0, f64(volume[p]) * exact_energy(Fs, F0s[p], Fc[p], Cp, body_params[b]))  # pyright: ignore[reportOptionalCall]
        else:
            wp.atomic_add(status.elastic, 0, f64(volume[p] * psi))
        stress = (dt * volume[p]) * P * wp.transpose(F0)  # dt V^0 P F^{0s,T}
        if wp.static(not with_stress):
            stress = t.mat()
        mv, mv0, mCdx, mFdx = momentum(p, m, v[p], Cp, Fs, stress, dt, body_force, cache, K, dx)
        rid = int(0)
        if wp.static(with_regions):
            rid = region[p]
        mG = t.mat()
        if wp.static(gradients):
            if wp.static(positions):
                mG = m * (Cp * wp.inverse(Fs))
            else:
                mG = m * Cp
        scatter(p, b, shape, cache, dx, m, xp, mv, mv0, mCdx, mFdx, stress, sum_positions, rid, grid_m, grid_mv,
                grid_mq, grid_p0, grid_kin, grid_kin_id, mG, grid_G)

    return p2g


@functools.cache
def make_stress(t: Types, material, lagrangian: bool):
    """``stress(p, b, dt, write, F^sn, F^0s, C, params, history, F0s, status)
    -> (P, psi, F^0s)``: a plastic model's return mapping (storing F^0s and
    the history when ``write`` is set, the stiffening in ``status``) or an
    elastic model's stress; the first Piola-Kirchhoff stress P of F^{0n} =
    F^sn F^0s, the energy density psi and the F^0s to take P's transpose by."""
    f64 = wp.float64
    needs_L = material.needs_velocity_gradient
    plastic = material.plastic
    plastic_update = stiffening = stress_energy = None
    if plastic:
        plastic_update = make_plastic_update(t, material)
        stiffening = material.stiffening(t) if material.stiffening is not None else None
    else:
        stress_energy = material.stress_energy(t)

    @wp.func
    def stress(p: int, b: int, dt: t.scalar, write: int, Fs: t.mat, F0_in: t.mat, Cp: t.mat,
               body_params: wp.array(dtype=t.params), history: wp.array(dtype=t.history),
               F0s: wp.array(dtype=t.mat), status: StepStatus):
        F0 = F0_in
        P = t.mat()
        psi = t.scalar(0.0)
        if wp.static(plastic):
            FE, P, psi, h = plastic_update(Fs * F0, body_params[b], history[p], dt)  # pyright: ignore[reportOptionalCall]
            if wp.static(lagrangian):
                F0 = wp.inverse(Fs) * FE
            else:
                F0 = FE
            if write != 0:
                F0s[p] = F0
                history[p] = h
            if wp.static(stiffening is not None):
                wp.atomic_max(status.stiffening, b, f64(stiffening(body_params[b], h)))  # pyright: ignore[reportOptionalCall]
        else:
            L = Cp  # velocity gradient in current coordinates: C (F^sn)^-1
            if wp.static(needs_L):
                L = Cp * wp.inverse(Fs)
            P, psi = stress_energy(Fs * F0, L, body_params[b])  # pyright: ignore[reportOptionalCall]
        return P, psi, F0

    return stress


@functools.cache
def make_exact_energy(t: Types, material, compensated: str):
    """``energy(F^sn, F^0s, Fc, C, params) -> psi`` [J/m^3], float64: an
    elastic model's energy density evaluated in float64 from the float32
    state, with the running error ``Fc`` of the compensated factor
    (``compensated``: "sn" or "0s"; the true sum is the stored one minus
    its error, mpm.g2p). A model's energy in float32 carries the rounding of
    its terms of order 1 (a neo-Hookean's tr(F^T F) and ln J cancel to
    first order): about 6e-8 mu per particle, which over a beam strained
    by 1e-3 summed to 2.4 times its energy; the stress is linear in that
    rounding and averages it out (the same beam deflects as in float64)."""
    t64 = make_types(t.dim, "float64")
    stress_energy = material.stress_energy(t64)
    needs_L = material.needs_velocity_gradient

    @wp.func
    def energy(Fs: t.mat, F0: t.mat, Fc: t.mat, Cp: t.mat, params: t.params):
        Fsn = t64.mat(Fs)
        F0s = t64.mat(F0)
        if wp.static(compensated == "sn"):
            Fsn = Fsn - t64.mat(Fc)
        else:
            F0s = F0s - t64.mat(Fc)
        L = t64.mat(Cp)
        if wp.static(needs_L):
            L = L * wp.inverse(Fsn)
        _P, psi = stress_energy(Fsn * F0s, L, t64.params(params))
        return psi

    return energy


@functools.cache
def make_momentum(t: Types, kernel: Kernel, transfer: str, with_body_force: bool, positions: bool):
    """``momentum(p, m, v, C, F^sn, stress, dt, body_force, cache, K, dx) ->
    (m v', m v, dx mC, m dx F^sn)``: the particle's momentum (with a body
    force's impulse), and the steps of the affine momentum and of the node
    position term per stencil index (MLS: mC with the stress fused in)."""
    S = t.scalar
    mls = transfer == "mls" and not kernel.gradient_affine
    affine = transfer not in ("pic", "flip")
    per_particle_K = kernel.moment is None
    Cache = make_stencil_cache(t, kernel)

    @wp.func
    def momentum(p: int, m: S, vp: t.vec, Cp: t.mat, Fs: t.mat, stress: t.mat, dt: S,
                 body_force: wp.array(dtype=t.vec), cache: Cache, K: S, dx: S):
        mv = m * vp
        mv0 = mv
        if wp.static(with_body_force):
            mv = mv + (m * dt) * body_force[p]
        mC = m * Cp
        if wp.static(mls):
            if wp.static(per_particle_K):
                mC = mC - stress * cache.K[p]
            else:
                mC = mC - K * stress
        mCdx = t.mat()
        if wp.static(affine):
            mCdx = dx * mC
        mFdx = t.mat()
        if wp.static(positions):
            mFdx = (m * dx) * Fs
        return mv, mv0, mCdx, mFdx

    return momentum


@functools.cache
def make_scatter(t: Types, kernel: Kernel, transfer: str, with_regions: bool, positions: bool, fused: bool,
                 gradients: bool = False):
    """``scatter(p, b, shape, cache, dx, m, x, mv, mv0, dx mC, m dx F^sn,
    stress, sum_positions, region, grid arrays...)``: the particle's share
    of every node of its stencils on the G grids (module docstring)."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    node = make_node(t, kernel)
    node_gradient = make_node_gradient(t, kernel)
    Cache = make_stencil_cache(t, kernel)
    mls = transfer == "mls" and not kernel.gradient_affine
    affine = transfer not in ("pic", "flip")
    flip = transfer == "flip"
    reference, cached = make_cached(t, kernel, not mls, fused)

    @wp.func
    def next_index(p: t.vec, q: t.vec, dCT: t.mat, dFT: t.mat, k: int):
        """The affine momentum p and the position term q one stencil index
        further along axis k (dCT, dFT: the transposed steps)."""
        p_next = p
        q_next = q
        if wp.static(affine):
            p_next = p + dCT[k]
        if wp.static(positions):
            q_next = q + dFT[k]
        return p_next, q_next

    @wp.func
    def scatter(p: int, b: int, shape: wp.array(dtype=t.ivec), cache: Cache, dx: S, m: S, xp: t.vec,
                mv: t.vec, mv0: t.vec, mCdx: t.mat, mFdx: t.mat, stress: t.mat, sum_positions: int, rid: int,
                grid_m: wp.array(dtype=S), grid_mv: wp.array(dtype=t.vec), grid_mq: wp.array(dtype=t.vec),
                grid_p0: wp.array(dtype=t.vec), grid_kin: wp.array(dtype=S), grid_kin_id: wp.array(dtype=wp.int32),
                mG: t.mat, grid_G: wp.array(dtype=t.mat)):
        # the affine momentum mv + mC r and the mass-weighted node position m (x_p + F^sn r) are
        # linear in the offset r = (index - fx) dx: evaluated at the stencil's first node, then
        # stepped by a column of dx mC (or m dx F^sn) per index step (no matrix product per node)
        dCT = wp.transpose(mCdx)
        dFT = wp.transpose(mFdx)
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            pa = mv
            if wp.static(affine):
                pa = mv - mCdx * fx
            qa = t.vec()
            if wp.static(positions):
                qa = m * xp - mFdx * fx
            for a in range(Ks):
                pb = pa
                qb = qa
                for bb in range(Ks):
                    pc = pb
                    qc = qb
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        wp.atomic_add(grid_m, i, w * m)
                        if wp.static(mls):
                            wp.atomic_add(grid_mv, i, w * pc)
                        else:
                            wp.atomic_add(grid_mv, i, w * pc - stress * node_gradient(a, bb, c, W, dW, S(1.0) / dx))
                        if wp.static(positions):
                            if sum_positions != 0:
                                wp.atomic_add(grid_mq, i, w * qc)
                        if wp.static(flip):
                            wp.atomic_add(grid_p0, i, w * mv0)
                        if wp.static(gradients):
                            wp.atomic_add(grid_G, i, w * mG)
                        if wp.static(with_regions):
                            if rid > 0:
                                wp.atomic_add(grid_kin, i, w * m)
                                wp.atomic_max(grid_kin_id, i, rid)
                        if wp.static(dim == 3):
                            pc, qc = next_index(pc, qc, dCT, dFT, 2)
                    pb, qb = next_index(pb, qb, dCT, dFT, 1)
                pa, qa = next_index(pa, qa, dCT, dFT, 0)

    return scatter
