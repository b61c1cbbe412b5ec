"""Angular momentum of a freely spinning elastic block under the implicit
integrator (mpm.integrators.Implicit): backward Euler loses it at first
order in dt, by exactly the amount the analysis gives, while the explicit
integrator keeps it to round-off.

The analysis (APIC/MLS transfers, Jiang et al. 2015/2017): P2G puts the
particles' angular momentum on the grid, L = 1/G sum_i x_i x m_i v*_i (x_i
the nodes, G the kernel's grids), and G2P gives back 1/G sum_i x_i x m_i v~_i
(the particles move with v~, and x~_i x v~_i adds x_i x v~_i). The step
changes it by dt/G sum_i x_i x f_i. Forward Euler's force is that of the
nodes at x_i, hence torque-free about them: L is kept. Backward Euler's is
that of the moved nodes x^_i = x_i + dt v~_i: sum x^_i x f_i = 0, so with
m_i (v~_i - v*_i) = dt f_i (the solved residual R_i = 0),

    dL = -dt^2/G sum_i v~_i x f_i = dt/G sum_i m_i v~_i x v*_i,

and for a steady spin of rate w (v~ - v* = -w^2 r dt) dL = -(w dt)^2 L per
step: L decays at the rate w^2 dt, first order in dt. With a residual R_i
left by Newton's method the step's change differs from this by
1/G sum_i x^_i x R_i, at most |R| (sum_i |x^_i|^2)^1/2 / G (Cauchy-Schwarz).
"""

import numpy as np
import pytest

import mpm
from helpers import DEVICE
from mpm.integrators import Explicit, Implicit

OMEGA = 5.0  # the block's spin [rad/s]


def cross(a, b):
    """The z component of a x b, rows of 2D or 3D vectors."""
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def spinning_block(scheme, integrator, dim=2, transfer="mls", resolution=32, kernel="quadratic"):
    """A free elastic block (E = 2e5 Pa, nu = 0.3, rho = 1000, 0.24 m wide)
    spinning at OMEGA about z through its centre, v = w x (x - c) and
    C = its gradient, no gravity, no wall reached; float64. Returns the
    solver, the state and a function giving L_z about the origin (APIC's
    about the centre of mass plus c x P)."""
    c = (0.5,) * dim
    body = mpm.Body(mpm.Box(c, (0.12,) * dim), mpm.FixedCorotated(E=2e5, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=resolution, ppc=4 if dim == 2 else 8,
                      gravity=(0.0,) * dim, walls=("open",) * (2 * dim), bodies=[body])
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", DEVICE)
    solver = mpm.Solver(model, scheme, mpm.SolverOptions(transfer=transfer, integrator=integrator))
    solver.prepare(state)
    W = np.zeros((dim, dim))
    W[0, 1], W[1, 0] = -OMEGA, OMEGA
    state.v.assign((state.x.numpy() - np.asarray(c)) @ W.T)
    state.C.assign(np.broadcast_to(W, (model.n_particles, dim, dim)).copy())
    names = solver.diagnostics.names

    def angular_momentum():
        d = solver.measure(state, elastic=False)
        cm, P = (np.array([d[names.index(f"{k}_{a}")] for a in "xyz"[:dim]]) for k in ("center_of_mass", "momentum"))
        return d[names.index("angular_momentum" if dim == 2 else "angular_momentum_z")] + cm[0] * P[1] - cm[1] * P[0]

    return solver, state, angular_momentum


@pytest.mark.parametrize("scheme, transfer, dim", [
    (mpm.EMPM(), "mls", 2), (mpm.EMPM(), "apic", 2), (mpm.TLMPM(), "mls", 2), (mpm.AULMPM(), "mls", 2),
    (mpm.EMPM(), "mls", 3)], ids=lambda p: getattr(p, "name", str(p)))
def test_backward_euler_changes_angular_momentum_by_dt_sum_m_v_cross_v_star(scheme, transfer, dim):
    """Each implicit step changes the spinning block's angular momentum by
    dL = dt/G sum_i m_i v~_i x v*_i (module docstring; v* the nodes'
    velocities from P2G, v~ the solve's), to within the Newton residual's
    bound |R| (sum_i |x^_i|^2)^1/2 / G plus round-off: the transfers, the
    affine C, the position update and the stress keep angular momentum, and
    all of its loss is backward Euler's. Measured at newton_tol = 1e-4:
    0.04-0.07 of the bound for EMPM; under TLMPM (and A-ULMPM, which makes
    no reference update here) the nodes x_i are the reference lattice's and
    the lever is their image, which q_i (the mass-weighted node position)
    approximates: measured within 1e-5 of the step's dL, allowed 1e-4."""
    dt, steps = 2e-3, 20 if dim == 2 else 10
    solver, state, angular_momentum = spinning_block(scheme, Implicit(newton_tol=1e-4), dim, transfer,
                                                     32 if dim == 2 else 16)
    G = solver.model.kernel.n_grids
    solve, seen = solver.implicit.solve, {}

    def solve_and_record(st, dtS):
        rep = solve(st, dtS)
        n = solver.layout.n_nodes
        m, q = solver.grid.m.numpy()[:n], solver.grid.q.numpy()[:n]
        v_star, v = solver.implicit.v_star.numpy()[:n], solver.grid.v.numpy()[:n]
        on = m > 0
        residual = rep.residual * rep.residual0 if rep.newton > 0 else rep.residual0
        lever = np.sqrt(np.sum((q[on] + float(dtS) * v[on]) ** 2)) / G
        seen.update(dL=float(dtS) * np.sum(m * cross(v, v_star)) / G, bound=residual * lever,
                    roundoff=64 * np.finfo(np.float64).eps * np.sum(m * np.linalg.norm(q, axis=1)
                                                                     * np.linalg.norm(v, axis=1)) / G)
        return rep

    solver.implicit.solve = solve_and_record
    L0 = L = angular_momentum()
    lagrangian = scheme.name != "empm"
    for _ in range(steps):
        assert solver.advance(state, dt).reason is None
        L, before = angular_momentum(), L
        allowed = seen["bound"] + seen["roundoff"] + (1e-4 * abs(seen["dL"]) if lagrangian else 0.0)
        assert abs((L - before) - seen["dL"]) <= allowed, (L - before, seen)
    # the loss is backward Euler's (w dt)^2 a step, not round-off: 20 steps lose ~1e-3 of L
    assert L0 - L > 0.1 * steps * (OMEGA * dt) ** 2 * L0


def test_backward_euler_angular_momentum_decay_is_first_order_in_dt():
    """Over 0.15 s the spinning block (EMPM, MLS, 32 cells, w = 5 rad/s)
    loses the fraction ~ w^2 T dt of its angular momentum (module docstring;
    a steady spin's (w dt)^2 a step): halving dt halves the loss (ratio
    within 2 +- 0.1; measured 1.99, 1.98), the loss is 0.85-1.0 of
    w^2 T dt (measured 0.937 at 2 ms, 0.945 at 1 ms: the spin's stress,
    which supplies the centripetal acceleration, oscillates about it from
    zero at the start), and it is the integrator's, not the Newton
    solve's: newton_tol 1e-8 changes it by less than 1e-4 of itself. The
    explicit integrator at its stable step keeps L to 1e-12."""
    T = 0.15

    def loss(integrator, dt):
        solver, state, angular_momentum = spinning_block(mpm.EMPM(), integrator)
        L0 = angular_momentum()
        for _ in range(int(round(T / dt))):
            assert solver.advance(state, dt).reason is None
        return (L0 - angular_momentum()) / L0

    coarse, fine = loss(Implicit(newton_tol=1e-4), 2e-3), loss(Implicit(newton_tol=1e-4), 1e-3)
    assert 1.9 < coarse / fine < 2.1, (coarse, fine)
    for dt, got in ((2e-3, coarse), (1e-3, fine)):
        assert 0.85 < got / (OMEGA**2 * T * dt) < 1.0, (dt, got)
    assert abs(loss(Implicit(newton_tol=1e-8), 1e-3) - fine) < 1e-4 * fine
    assert abs(loss(Explicit(), 5e-4)) < 1e-12



@pytest.mark.parametrize("integrator", [Explicit(), Implicit(newton_tol=1e-6)], ids=lambda i: i.name)
def test_linear_kernel_under_empm_loses_the_moment_shift_of_the_kept_affine_velocity(integrator):
    """EMPM with the linear kernel loses angular momentum under either
    integrator: G2P's C_p (from the weights at x_p^n) carries m_p axial(C_p
    D_p(x^n)) (D_p = sum_i w_ip (x_i - x_p)(x_i - x_p)^T, the kernel's
    second moment, dx^2 diag(t (1 - t)) with t the position in its cell),
    and the next P2G spreads the same C_p from x_p^(n+1), where the moment
    differs:

        dL = sum_p m_p axial(C_p (D_p(x^(n+1)) - D_p(x^n))) + backward Euler's dt/G sum_i m_i v~_i x v*_i,

    axial(A) = A_10 - A_01, a step. (Jiang et al. keep B_p = C_p D_p and
    divide by the new moment; the quadratic and cubic kernels' moment is
    constant.) The loss equals the two sums to 1e-6 of itself (measured
    1.3e-7 explicit, 1.4e-7 implicit); the moment's sum is all of the
    explicit loss (3.9e-3 of L over 0.05 s) and 0.62 of the implicit one
    (6.2e-3 over 0.05 s; backward Euler's 0.38)."""
    implicit = integrator.name == "implicit"
    dt, steps = (2e-3, 25) if implicit else (2.5e-4, 200)
    solver, state, angular_momentum = spinning_block(mpm.EMPM(), integrator, kernel="linear")
    m, dx = solver.model.mass.numpy(), float(solver.model.dx)

    def moment(x):  # the diagonal of D_p / dx^2 per axis
        t = x / dx - np.floor(x / dx)
        return t * (1.0 - t)

    euler = {"dL": 0.0}
    if implicit:
        solve = solver.implicit.solve

        def solve_and_record(st, dtS):
            rep = solve(st, dtS)
            n = solver.layout.n_nodes
            v_star, v = solver.implicit.v_star.numpy()[:n], solver.grid.v.numpy()[:n]
            euler["dL"] += float(dtS) * np.sum(solver.grid.m.numpy()[:n] * cross(v, v_star))
            return rep

        solver.implicit.solve = solve_and_record
    L0, shift = angular_momentum(), 0.0
    for _ in range(steps):
        x = state.x.numpy().copy()  # (a view of the state on the CPU)
        assert solver.advance(state, dt).reason is None
        dD, C = dx**2 * (moment(state.x.numpy()) - moment(x)), state.C.numpy()
        shift += np.sum(m * (C[:, 1, 0] * dD[:, 0] - C[:, 0, 1] * dD[:, 1]))
    loss = angular_momentum() - L0
    assert abs(loss - (shift + euler["dL"])) <= 1e-6 * abs(loss), (loss, shift, euler["dL"])
    assert abs(shift) > 0.2 * abs(loss) and abs(loss) > 1e-4 * abs(L0)
