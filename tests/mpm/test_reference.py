"""The Eulerian step against the independent NumPy MLS-MPM of reference_mpm.py,
step by step, on tiny 2D and 3D problems with several bodies and materials."""

import numpy as np
import pytest

import mpm
from reference_mpm import step as reference_step


def tiny_scene(dim):
    """Bodies far enough apart that contact never acts (each body on a grid of
    its own, as in the reference); see assert_no_contact."""
    if dim == 2:
        bodies = [
            mpm.Body(mpm.Sphere((0.3, 0.35), 0.09), mpm.FixedCorotated(E=2e4, nu=0.3, rho=900),
                     velocity=(1.0, -0.5), angular_velocity=3.0),
            mpm.Body(mpm.Box((0.72, 0.3), (0.08, 0.1)), mpm.Fluid(K=1e4, gamma=7.0, viscosity=0.5),
                     velocity=(-1.0, 0.0)),
            mpm.Body(mpm.Box((0.5, 0.72), (0.12, 0.06)), mpm.NeoHookean(E=3e4, nu=0.4),
                     velocity=(0.0, -2.0)),
        ]
        return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, bodies=bodies,
                         gravity=(0.0, -9.81), walls=("slip", "sticky", "slip", "slip"), ppc=4)
    bodies = [
        mpm.Body(mpm.Sphere((0.3, 0.45, 0.5), 0.1), mpm.FixedCorotated(E=2e4, nu=0.3),
                 velocity=(1.0, -0.5, 0.2), angular_velocity=(1.0, 2.0, -1.0)),
        mpm.Body(mpm.Box((0.74, 0.4, 0.5), (0.06, 0.08, 0.08)), mpm.Fluid(K=1e4, viscosity=0.2),
                 velocity=(-1.0, 0.0, 0.0)),
    ]
    return mpm.Scene(dim=3, domain=(1.0, 1.0, 1.0), resolution=20, bodies=bodies,
                     gravity=(0.0, -9.81, 0.0), walls=("slip",) * 6, ppc=1)


def assert_state_matches(state, x, v, C, F, step, C_atol):
    """The solver's float64 state against a NumPy reference after ``step``:
    differences are summation-order round-off, amplified by the stress term
    dt V K |P| (|P| up to ~1e4 Pa in these scenes) in v and most in C."""
    got = state.numpy()
    np.testing.assert_allclose(got["x"], x, rtol=0, atol=1e-12, err_msg=f"x, step {step}")
    np.testing.assert_allclose(got["v"], v, rtol=0, atol=1e-9, err_msg=f"v, step {step}")
    np.testing.assert_allclose(got["C"], C, rtol=0, atol=C_atol, err_msg=f"C, step {step}")
    np.testing.assert_allclose(got["F0s"], F, rtol=0, atol=1e-11, err_msg=f"F, step {step}")


def particle_inputs(scene, model):
    """What the NumPy references take per particle: body index, material name,
    packed material parameters, mass [kg] and volume [m^dim]."""
    body = model.body.numpy()
    return (body, [scene.bodies[b].material.name for b in body],
            [scene.bodies[b].material.packed() for b in body], model.mass.numpy(), model.volume.numpy())


def assert_no_contact(solver):
    """The premise of the reference comparisons: no bin in contact in the
    last step (the status's count, mpm.contact), so no contact correction."""
    if solver.contact:
        assert solver.report().contact_nodes == 0, "bodies touched"


@pytest.mark.parametrize("dim", [2, 3])
def test_eulerian_step_matches_numpy_reference(dim, device):
    scene = tiny_scene(dim)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", device)
    solver = mpm.Solver(model)
    solver.prepare(state)
    body, models, prms, mass, vol = particle_inputs(scene, model)
    s = state.numpy()
    x, v, C, F = s["x"], s["v"], s["C"], s["F0s"]
    dt = 2e-4
    steps = 12 if dim == 2 else 4
    for k in range(steps):
        x, v, C, F = reference_step(x, v, C, F, mass, vol, models, prms, model.dx, model.cells,
                                    scene.gravity, scene.walls, dt, body=body)
        solver.advance(state, dt)
        assert_no_contact(solver)
        assert_state_matches(state, x, v, C, F, k, C_atol=1e-7)
    assert solver.report().reason is None
    # the bodies really deformed and moved: the comparison is not trivial
    assert np.abs(F - np.eye(dim)).max() > 1e-3


@pytest.mark.parametrize("dim", [2, 3])
def test_elastic_energy_bookkeeping(dim, device):
    """The elastic energy P2G accumulates during a step is that of the state
    the step starts from, equal to sum_p V_p psi(F_p) of the NumPy formulas."""
    from reference_mpm import energy

    scene = tiny_scene(dim)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", device)
    solver = mpm.Solver(model)
    solver.prepare(state)
    body, vol = model.body.numpy(), model.volume.numpy()
    i = solver.diagnostics.names.index("elastic_energy")
    for _ in range(3):
        F = state.F0s.numpy()
        expected = sum(vol[p] * energy(scene.bodies[b].material.name, F[p],
                                       scene.bodies[b].material.packed())
                       for p, b in enumerate(body))
        measured = solver.measure(state)[i]
        solver.advance(state, 2e-4)
        assert solver.step_energy() == measured
        assert measured == pytest.approx(expected, rel=1e-10, abs=1e-12)
    assert measured > 0
