"""The Eulerian step against the independent NumPy MLS-MPM of reference_mpm.py,
step by step, on tiny 2D and 3D problems with several bodies and materials."""

import numpy as np
import pytest

import mpm
from reference_mpm import step as reference_step


def tiny_scene(dim, rule="nodes"):
    """Bodies far enough apart that contact never acts (each body on a grid of
    its own, as in the reference; see assert_no_contact), two of them at a
    wall; ``rule`` the walls' (Scene.boundary_rule)."""
    if dim == 2:
        bodies = [
            mpm.Body(mpm.Sphere((0.3, 0.35), 0.09), mpm.FixedCorotated(E=2e4, nu=0.3, rho=900),
                     velocity=(1.0, -0.5), angular_velocity=3.0),
            # on the floor's and the sticky wall's faces (3 cells in), and pushed against the wall
            mpm.Body(mpm.Box((0.7325, 0.2875), (0.08, 0.1)), mpm.Fluid(K=1e4, gamma=7.0, viscosity=0.5),
                     velocity=(0.5, 0.0)),
            mpm.Body(mpm.Box((0.5, 0.72), (0.12, 0.06)), mpm.NeoHookean(E=3e4, nu=0.4),
                     velocity=(0.0, -2.0)),
        ]
        return mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, bodies=bodies, boundary_rule=rule,
                         gravity=(0.0, -9.81), walls=("slip", "sticky", "slip", "slip"), ppc=4)
    bodies = [
        mpm.Body(mpm.Sphere((0.3, 0.45, 0.5), 0.1), mpm.FixedCorotated(E=2e4, nu=0.3),
                 velocity=(1.0, -0.5, 0.2), angular_velocity=(1.0, 2.0, -1.0)),
        mpm.Body(mpm.Box((0.74, 0.4, 0.5), (0.06, 0.08, 0.08)), mpm.Fluid(K=1e4, viscosity=0.2),
                 velocity=(-1.0, 0.0, 0.0)),
    ]
    return mpm.Scene(dim=3, domain=(1.0, 1.0, 1.0), resolution=20, bodies=bodies, boundary_rule=rule,
                     gravity=(0.0, -9.81, 0.0), walls=("slip",) * 6, ppc=1)


EPS64 = np.finfo(np.float64).eps


def round_off(x, v, F, dx, C_factor=128):
    """Absolute tolerances for a float64 state against a NumPy reference that
    sums the same terms in other orders, by field (eps = float64's 2.2e-16):
        x, X: 4 eps max|x|   (x + dt v rounds alike; dt dv is far below an ulp)
        v: 64 eps max|v|     (the node sums of w (m v + affine + stress impulse) / m_i;
                              measured: up to 15 eps max|v|, 3D compact)
        C: C_factor eps max|v| / dx  (C = B K_p ~ sum w v_i r^T / dx^2: the
                              velocities' round-off over r / dx^2 ~ 1 / dx; measured:
                              up to 35 eps max|v| / dx for the B-splines, 110 for the
                              compact kernel, whose K_p is inverted per particle)
        F: 8 eps max|F|      ((I + dt C) F: dt dC is below an ulp of F ~ 1;
                              measured: up to 2 eps)"""
    vmax = np.abs(v).max()
    return {"x": 4 * EPS64 * np.abs(x).max(), "v": 64 * EPS64 * vmax, "C": C_factor * EPS64 * vmax / dx,
            "F": 8 * EPS64 * np.abs(F).max()}


def assert_state_matches(state, x, v, C, F, step, dx, C_factor=128):
    """The solver's float64 state against a NumPy reference after ``step``
    (tolerances: :func:`round_off`)."""
    got = state.numpy()
    tol = round_off(x, v, F, dx, C_factor)
    for key, ref, name in (("x", x, "x"), ("v", v, "v"), ("C", C, "C"), ("F0s", F, "F")):
        np.testing.assert_allclose(got[key], ref, rtol=0, atol=tol[name], err_msg=f"{key}, step {step}")


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


@pytest.mark.parametrize("dim,rule", [(2, "nodes"), (3, "nodes"), (2, "surface"), (3, "surface")])
def test_eulerian_step_matches_numpy_reference(dim, rule, device):
    """Both wall rules (Scene.boundary_rule): the node rule, and the surface
    rule of mpm.surface with the particles kept out of the walls, each
    written out in the reference (reference_mpm.wall_contacts, keep_out)."""
    scene = tiny_scene(dim, rule)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", device)
    solver = mpm.Solver(model)
    solver.prepare(state)
    body, models, prms, mass, vol = particle_inputs(scene, model)
    rho = np.array([scene.bodies[b].material.rho for b in body]) if rule == "surface" else None
    s = state.numpy()
    x, v, C, F = s["x"], s["v"], s["C"], s["F0s"]
    dt = 2e-4
    steps = 12 if dim == 2 else 4
    impulse = 0.0
    for k in range(steps):
        x, v, C, F = reference_step(x, v, C, F, mass, vol, models, prms, model.dx, model.cells,
                                    scene.gravity, scene.walls, dt, body=body, rho=rho)
        report = solver.advance(state, dt)
        impulse += np.abs(report.boundary_impulse).sum()
        assert_no_contact(solver)
        assert_state_matches(state, x, v, C, F, k, model.dx)
    assert solver.report().reason is None
    assert impulse > 0.0 or dim == 3  # the walls acted (in 2D: the fluid on the floor, at the sticky wall)
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
        # psi ~ |F - R|^2 and (J - 1)^2: the round-off eps of F - R and J - 1 against
        # the strain |sigma - 1| (sigma the singular values of F) makes psi's relative
        # round-off about 2 eps / strain; F = I at the start: psi = 0 exactly
        strain = np.abs(np.linalg.svd(F, compute_uv=False) - 1.0).max()
        assert measured == (pytest.approx(expected, rel=8 * EPS64 / strain, abs=0) if strain > 0 else 0.0)
    assert measured > 0


@pytest.mark.parametrize("transfer", ["mls", "apic"])
@pytest.mark.parametrize("kernel", ["linear", "cubic"])
@pytest.mark.parametrize("dim", [2, 3])
def test_bspline_eulerian_step_matches_numpy_reference(dim, kernel, transfer, device):
    """The linear and cubic B-splines through full steps (walls, gravity, a
    solid, a viscous fluid and in 2D a neo-Hookean solid) against the NumPy
    step of reference_mpm.bspline_step, which takes its weights from the
    textbook N(d) and inverts each particle's moment matrix D_p itself: for
    the linear kernel the solver's gradient-based affine matrix and force
    must equal B D_p^-1 and w D_p^-1 r (the APIC paper's multilinear
    identity), for the cubic one K_p = 3 / dx^2."""
    from reference_mpm import bspline_step

    scene = tiny_scene(dim)
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", device)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(transfer=transfer))
    solver.prepare(state)
    body, models, prms, mass, vol = particle_inputs(scene, model)
    s = state.numpy()
    x, v, C, F = s["x"], s["v"], s["C"], s["F0s"]
    dt = 2e-4
    for k in range(8 if dim == 2 else 3):
        x, v, C, F = bspline_step(x, v, C, F, mass, vol, models, prms, kernel, model.dx, model.domain,
                                  scene.gravity, scene.walls, dt, transfer, body=body)
        solver.advance(state, dt)
        assert_no_contact(solver)
        assert_state_matches(state, x, v, C, F, k, model.dx)
    assert solver.report().reason is None
    assert np.abs(F - np.eye(dim)).max() > 1e-4  # the bodies deformed: the comparison is not trivial


@pytest.mark.parametrize("kernel", ["linear", "quadratic"])
@pytest.mark.parametrize("dim", [2, 3])
def test_flip_step_matches_numpy_reference(dim, kernel, device):
    """The PIC/FLIP blend (transfer flip, blend 0.9) against the NumPy step:
    v_p <- v_pic + 0.9 (v_p - sum w p0_i / m_i), p0_i the momentum the step
    transferred before any force, positions moved with v_pic; C stays 0.
    Over steps whose grid changes the velocities (gravity, stress, walls),
    FLIP's velocities differ from PIC's (checked), so the blend is tested."""
    from reference_mpm import bspline_step

    scene = tiny_scene(dim)
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", device)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(transfer="flip", flip=0.9))
    solver.prepare(state)
    body, models, prms, mass, vol = particle_inputs(scene, model)
    s = state.numpy()
    x, v, C, F = s["x"], s["v"], s["C"], s["F0s"]
    v_pic = v.copy()
    dt = 2e-4
    for k in range(6 if dim == 2 else 3):
        _, v_pic, _, _ = bspline_step(x, v, C, F, mass, vol, models, prms, kernel, model.dx, model.domain,
                                      scene.gravity, scene.walls, dt, "pic", body=body)
        x, v, C, F = bspline_step(x, v, C, F, mass, vol, models, prms, kernel, model.dx, model.domain,
                                  scene.gravity, scene.walls, dt, "flip", body=body, flip=0.9)
        solver.advance(state, dt)
        assert_no_contact(solver)
        assert_state_matches(state, x, v, C, F, k, model.dx)
    assert np.abs(v - v_pic).max() > 1e3 * np.abs(v).max() * np.finfo(float).eps
