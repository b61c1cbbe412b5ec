"""The rigid bodies' energy (mpm.rigid_coupling.Coupler.energies) in the
energy balance: what the material loses to a body the body gains."""

import numpy as np
import pytest

import mpm
from mpm.colliders import Collider
from mpm.materials import FixedCorotated

pytest.importorskip("newton")

G = 9.81


def test_coupler_energies_of_a_turned_spinning_box():
    """A box (0.2 x 0.1 x 0.04 m, density 1000: m = 0.8 kg) turned a quarter
    turn about z, spinning at 1 rad/s about world x (its own -y axis), moving
    at (1, 2, 0) m/s with its centre at y = 0.6 m under g = 9.81 m/s^2 along
    -y: 1/2 m |v|^2 = 2 J, 1/2 I_yy w^2 with I_yy = m (0.2^2 + 0.04^2) / 12
    (the axis across its longest side: about x it would be 3.6 times less),
    -m g . x = m g 0.6 (zero at the origin, as the material's)."""
    body = mpm.RigidBody(Collider.box((0.5, 0.6, 0.5), (0.1, 0.05, 0.02)), density=1000.0,
                         velocity=(1.0, 2.0, 0.0), angular_velocity=(1.0, 0.0, 0.0), orientation=(0.0, 0.0, np.pi / 2))
    block = mpm.Body(mpm.Box((0.5, 0.3, 0.5), (0.05, 0.05, 0.05)), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=16, bodies=[block], gravity=(0.0, -G, 0.0),
                      walls=("slip",) * 6, rigid_bodies=[body])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.SCHEMES["empm"](), mpm.SolverOptions())
    solver.prepare(state)
    e = solver.conditions.rigid.energies()
    m = 1000.0 * 0.2 * 0.1 * 0.04
    # the body's state is float32 (Newton's): its figures to 1e-6
    np.testing.assert_allclose(e["kinetic"], [0.5 * m * 5.0], rtol=1e-6)
    np.testing.assert_allclose(e["rotational"], [0.5 * m * (0.2**2 + 0.04**2) / 12.0], rtol=1e-6)
    np.testing.assert_allclose(e["potential"], [m * G * 0.6], rtol=1e-6)


@pytest.mark.parametrize("kernel", ["quadratic", "compact"])
def test_total_energy_never_grows_when_a_ball_falls_onto_a_block(kernel):
    """A rigid disc (r = 0.06 m, density 2000, 2 m/s down) falls onto an
    elastic block (E = 2e5 Pa) resting on the floor, under gravity, in
    float64 at 48 cells, EMPM, 400 steps (the strike at 0.02 s, the disc
    thrown back). The walls are static: they do no work (mpm.grid
    ``make_work``), so the energy of the material (kinetic + elastic +
    potential, mpm.diagnostics) and the disc (translation, rotation and
    potential, Coupler.energies) together, at each step's start, may not
    exceed its first value, E(t) - E(0) <= 0, but for round-off: 1e-6 of
    the disc's kinetic energy K (its state is float32). Measured: at most
    -1.7e-5 K after the first step with either kernel (its semi-implicit
    Euler loses 1/2 m g^2 dt^2 a step in the fall; the material and the
    disc exchange energy at the strike, the total falls). The material
    alone gains what the disc loses, more than 0.1 K (measured 0.15 K with
    the quadratic kernel, 0.26 K with the compact one), so the total
    without the disc's energy would fail. (The boundaries' work the run
    counts, mpm.stepping.detection, is 2.4 K here: the positive part of the
    disc's pushes on the material, an upper bound that the balance with
    the disc's energy does not need.)"""
    ball = mpm.RigidBody(Collider.sphere((0.5, 0.42), 0.06), density=2000.0, velocity=(0.0, -2.0))
    block = mpm.Body(mpm.Box((0.5, 0.21), (0.12, 0.08)), FixedCorotated(E=2e5, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=48, bodies=[block], gravity=(0.0, -G),
                      walls=("sticky",) + ("slip",) * 3, rigid_bodies=[ball])
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64")
    solver = mpm.Solver(model, mpm.SCHEMES["empm"](), mpm.SolverOptions())
    solver.prepare(state)
    coupler = solver.conditions.rigid
    m, g = model.mass.numpy(), np.array(scene.gravity)

    def body():
        return float(sum(np.sum(v) for v in coupler.energies().values()))

    E_body, K = body(), float(coupler.energies()["kinetic"][0])
    energies, materials, report = [], [], None
    for _ in range(400):
        x, v = state.x.numpy(), state.v.numpy()
        kinetic_potential = 0.5 * np.sum(m * np.sum(v * v, axis=1)) - np.sum(m * (x @ g))
        report = solver.advance(state, solver.timestep.stable_dt(0.4, report))
        materials.append(kinetic_potential + solver.step_energy())  # (the state the step started from)
        energies.append(materials[-1] + E_body)
        E_body = body()
    growth = (max(energies[1:]) - energies[0]) / K
    assert growth < 1e-6, growth
    assert (materials[-1] - materials[0]) / K > 0.1, (materials[-1] - materials[0]) / K
