"""The boundary conditions' impulse (``StepReport.boundary_impulse``,
mpm.grid ``make_work``): with gravity's M g dt it is the whole change of the
bodies' momentum in a step, to round-off, whether walls, a collider, a
kinematic region or the implicit integrator's constraints give it."""

import numpy as np
import pytest

import mpm
from mpm.integrators import Implicit

EPS = np.finfo(np.float64).eps
G = -9.81


def ball(**scene):
    """A 2D elastic ball falling fast onto the floor (it bounces within the steps run)."""
    body = mpm.Body(mpm.Sphere((0.5, 0.3), 0.1), mpm.NeoHookean(E=2e4, nu=0.3), velocity=(0.4, -2.0))
    return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, bodies=[body], gravity=(0.0, G),
                     **{"walls": ("slip",) * 4, **scene})


CASES = {
    "slip walls": (lambda: ball(), {}),
    "sticky walls": (lambda: ball(walls=("sticky",) * 4), {}),
    # the floor a collider above the wall band (the walls open: only the collider acts)
    "collider": (lambda: ball(walls=("slip", "slip", "open", "slip"), colliders=[
        mpm.Collider("half_space", boundary="sticky", point=(0.5, 0.15), normal=(0.0, 1.0))]), {}),
    # the ball's top held by a kinematic region moving up: it pulls against gravity and the floor
    "region": (lambda: ball(regions=[mpm.KinematicRegion(body=0, select=mpm.Box((0.5, 0.38), (0.04, 0.03)),
                                                         velocity=(0.0, 0.5))]), {}),
    # the solve's residual is momentum the balance misses: solved to round-off here (measured: the
    # default newton_tol 1e-4 leaves 2e-4 kg m/s over the bounce, 1e-8 leaves 1.5e-8)
    "implicit": (lambda: ball(), {"integrator": Implicit(newton_tol=1e-12, cg_tol=1e-14, newton_max=50,
                                                         cg_max=5000)}),
    # Coulomb friction on the solved velocities (a rough floor collider): its tangential impulse too
    "implicit friction": (lambda: ball(walls=("slip", "slip", "open", "slip"), colliders=[
        mpm.Collider("half_space", boundary="slip", friction=0.5, point=(0.5, 0.15), normal=(0.0, 1.0))]),
        {"integrator": Implicit(newton_tol=1e-12, cg_tol=1e-14, newton_max=50, cg_max=5000)}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_momentum_change_is_gravity_plus_boundary_impulse(case, device):
    """A ball bouncing on the floor under gravity, float64: after every step,
    P(t) - P(0) = sum M g dt + sum J to round-off (J: the step's boundary
    impulse, summed over the kernel's grids, each carrying the full mass),
    while J itself is of the order of the ball's momentum (the bounce)."""
    make, options = CASES[case]
    model, state = mpm.build(make(), mpm.KERNELS["quadratic"], "float64", device)
    solver = mpm.Solver(model, options=mpm.SolverOptions(**options))
    solver.prepare(state)
    names = solver.diagnostics.names
    p_idx = [names.index("momentum_x"), names.index("momentum_y")]

    def momentum():
        return solver.measure(state, elastic=False)[p_idx]

    mass = float(model.mass.numpy().astype(np.float64).sum())
    p0 = momentum()
    scale = mass * 2.5  # sum m |v| at most: the ball's speed stays below 2.5 m/s
    dt = mpm.cfl_dt(model.dx, model.wave_speed(), 2.5, 0.4)
    steps = int(np.ceil(0.08 / dt))  # the ball reaches the floor after about 0.05 s
    gravity = np.zeros(2)
    impulse = np.zeros(2)
    worst = 0.0
    for _ in range(steps):
        report = solver.advance(state, dt)
        assert report.reason is None, report.reason
        assert report.boundary_impulse.shape == (2,)
        gravity += mass * np.array([0.0, G]) * report.dt
        impulse += report.boundary_impulse / model.kernel.n_grids
        worst = max(worst, float(np.abs(momentum() - p0 - gravity - impulse).max()))
    # round-off: the transfers' sums, a few eps of the momentum scale per step
    assert worst <= 4 * EPS * scale * steps, (worst, EPS * scale * steps)
    # not trivially true: the boundary gave an impulse of the order of the ball's momentum
    assert impulse[1] > 0.3 * mass * 2.0, impulse
    assert np.abs(momentum() - p0 - gravity).max() > 1e6 * worst
    if "friction" in case:  # the rough floor slowed the ball's sliding (0.4 m/s): an x impulse
        assert impulse[0] < -0.05 * mass * 0.4, impulse
