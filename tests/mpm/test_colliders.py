"""Rigid colliders (mpm.colliders): signed distances against closed forms,
Coulomb friction on an incline, a conveyor (a moving collider), a container
that holds its contents, and compiling only what a scene has."""

import numpy as np
import pytest

import mpm
from collider_sdf import evaluate
from mpm.collider_device import kinds_of
from mpm.colliders import Collider
from mpm.materials import FixedCorotated, Fluid
from mpm.meshes import MeshShape
from mpm.scene import Rotated, rotation_matrix

G = 9.81
EPS12 = 8 * np.finfo(np.float64).eps  # closed forms of coordinates <= 1 m: a few ulps (measured <= 1 ulp)


# ------------------------------------------------------------ signed distances
def _box_sdf(q, c, h):
    d = np.abs(q - c) - h
    return np.linalg.norm(np.maximum(d, 0), axis=1) + np.minimum(d.max(axis=1), 0)


RNG = np.random.default_rng(3)
Q3 = RNG.uniform(0.0, 1.0, (4000, 3))
Q2 = RNG.uniform(0.0, 1.0, (4000, 2))


def test_half_space_and_wedge_distances():
    # phi = (q - p) . n / |n|; a wedge is the larger of its two faces' distances
    n = np.array([1.0, 2.0, -0.5])
    phi, normal = evaluate(Collider("half_space", point=(0.5, 0.4, 0.5), normal=tuple(n)), Q3)
    u = n / np.linalg.norm(n)
    np.testing.assert_allclose(phi, (Q3 - [0.5, 0.4, 0.5]) @ u, rtol=0, atol=EPS12)
    np.testing.assert_allclose(normal, np.tile(u, (len(Q3), 1)), rtol=0, atol=EPS12)
    n1, n2 = np.array([-1.0, 1.0]) / np.sqrt(2), np.array([1.0, 1.0]) / np.sqrt(2)
    phi, normal = evaluate(Collider("wedge", point=(0.5, 0.4), normals=((-1.0, 1.0), (1.0, 1.0))), Q2)
    d = Q2 - [0.5, 0.4]
    np.testing.assert_allclose(phi, np.maximum(d @ n1, d @ n2), rtol=0, atol=EPS12)
    np.testing.assert_allclose(normal, np.where((d @ n1 > d @ n2)[:, None], n1, n2), rtol=0, atol=EPS12)


@pytest.mark.parametrize("dim", [2, 3])
def test_box_and_sphere_distances(dim):
    q = Q2 if dim == 2 else Q3
    c, h = np.full(dim, 0.5), np.linspace(0.1, 0.3, dim)
    phi, normal = evaluate(Collider("box", center=tuple(c), half_size=tuple(h)), q)
    np.testing.assert_allclose(phi, _box_sdf(q, c, h), rtol=0, atol=EPS12)
    # the normal is the gradient of phi (central differences away from edges and the medial axes)
    eps = 1e-6
    grad = np.stack([(_box_sdf(q + eps * e, c, h) - _box_sdf(q - eps * e, c, h)) / (2 * eps)
                     for e in np.eye(dim)], axis=1)
    smooth = np.linalg.norm(grad, axis=1) > 1 - 1e-6
    # the differences' round-off eps |phi| / eps_h (phi ~ 1; measured 32 eps / eps_h)
    np.testing.assert_allclose(normal[smooth], grad[smooth], rtol=0, atol=128 * np.finfo(float).eps / eps)
    phi, normal = evaluate(Collider("sphere", center=tuple(c), radius=0.3), q)
    r = np.linalg.norm(q - c, axis=1)
    np.testing.assert_allclose(phi, r - 0.3, rtol=0, atol=EPS12)
    np.testing.assert_allclose(normal, (q - c) / r[:, None], rtol=0, atol=EPS12)
    # a container is the same sphere seen from inside: phi and n change sign
    phi_in, normal_in = evaluate(Collider("sphere", center=tuple(c), radius=0.3, inside=True), q)
    np.testing.assert_allclose(phi_in, 0.3 - r, rtol=0, atol=EPS12)
    np.testing.assert_allclose(normal_in, -normal, rtol=0, atol=EPS12)


def test_cylinder_distance_along_any_axis():
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    c = np.array([0.5, 0.5, 0.5])
    phi, _ = evaluate(Collider("cylinder", center=tuple(c), radius=0.2, half_height=0.25,
                               axis=tuple(axis)), Q3)
    d = Q3 - c
    s = d @ axis
    rho = np.linalg.norm(d - s[:, None] * axis, axis=1)
    e = np.stack([rho - 0.2, np.abs(s) - 0.25], axis=1)  # a 2D box in (rho, s)
    ref = np.linalg.norm(np.maximum(e, 0), axis=1) + np.minimum(e.max(axis=1), 0)
    np.testing.assert_allclose(phi, ref, rtol=0, atol=EPS12)


def test_cup_and_bowl_membership():
    """Solid exactly where the closed-form description says (away from a
    thin band around the surface, where float rounding may decide)."""
    c = np.array([0.5, 0.2, 0.5])
    cup = Collider("cup", center=tuple(c), radius=0.2, depth=0.3, thickness=0.05, axis=1)
    phi, _ = evaluate(cup, Q3)
    d = Q3 - c
    rho = np.hypot(d[:, 0], d[:, 2])
    solid = (d[:, 1] >= -0.05) & (d[:, 1] <= 0.3) & (rho <= 0.25) & ~((d[:, 1] >= 0.0) & (rho < 0.2))
    clear = np.abs(phi) > 1e-9
    assert np.array_equal((phi < 0)[clear], solid[clear])
    # the distance is exact on the wall's inner face and the floor of the cup
    wall = np.array([[0.5 + 0.19, 0.35, 0.5], [0.5, 0.21, 0.5]])
    np.testing.assert_allclose(evaluate(cup, wall)[0], [0.01, 0.01], rtol=0, atol=EPS12)
    bowl = Collider("bowl", center=(0.5, 0.6, 0.5), radius=0.3, thickness=0.05, rim=0.1, axis=1)
    phi, _ = evaluate(bowl, Q3)
    d = Q3 - [0.5, 0.6, 0.5]
    r = np.linalg.norm(d, axis=1)
    solid = (r >= 0.3) & (r <= 0.35) & (d[:, 1] <= 0.1)
    clear = np.abs(phi) > 1e-9
    assert np.array_equal((phi < 0)[clear], solid[clear])
    # the solid bowl shape fills the same region
    shape = mpm.scene.Bowl((0.5, 0.6, 0.5), 0.3, 0.05, 0.1, 1)
    assert np.array_equal(shape.contains(Q3)[clear], solid[clear])


def test_mesh_distance_of_a_cube():
    # the shipped cube mesh scaled to side 0.4 about (0.5, 0.5, 0.5) against the box's exact distance
    cube = Collider("mesh", mesh=MeshShape("warp:cube", (0.5, 0.5, 0.5), 0.4))
    phi, normal = evaluate(cube, Q3)
    ref = _box_sdf(Q3, np.full(3, 0.5), np.full(3, 0.2))
    np.testing.assert_allclose(phi, ref, atol=1e-6)  # float32 mesh queries
    outside_face = np.array([[0.8, 0.5, 0.5], [0.5, 0.1, 0.5]])
    np.testing.assert_allclose(evaluate(cube, outside_face)[1], [[1, 0, 0], [0, -1, 0]], atol=1e-6)


# ------------------------------------------------------------------ dynamics
THETA = np.radians(30.0)


def _incline(mu: float, scheme: str = "empm", boundary: str = "separate", res: int = 64,
             duration: float = 0.3, integrator=None, dt_factor: float = 1.0):
    """A flat elastic block on the left face of a wedge inclined at 30 deg.
    Returns (t, velocity along the slope, displacement [m]) of its centre of mass."""
    n1 = np.array([-np.sin(THETA), np.cos(THETA)])
    down = np.array([-np.cos(THETA), -np.sin(THETA)])
    apex = np.array([0.8, 0.6])
    half = np.array([0.08, 0.03])  # wide and flat: well away from tipping (tan 30 deg < 0.08/0.03)
    c = apex + 0.16 * down + n1 * half[1]  # on the face: dropped onto it, an elastic block bounces
    body = mpm.Body(Rotated(mpm.Box(tuple(c), tuple(half)), rotation_matrix(np.degrees(THETA), 2)),
                    FixedCorotated(E=3e5, nu=0.3, rho=1000.0))
    wedge = Collider("wedge", boundary=boundary, friction=mu, point=tuple(apex),
                     normals=(tuple(n1), (np.sin(THETA), np.cos(THETA))))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[body], gravity=(0.0, -G),
                      ppc=4, colliders=[wedge])
    return _track(scene, scheme, duration, down, integrator, dt_factor)


def _track(scene, scheme, duration, direction, integrator=None, dt_factor=1.0):
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], precision="float64")
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](),
                        mpm.SolverOptions(integrator=integrator or mpm.integrators.Explicit()))
    solver.prepare(state)
    m = model.mass.numpy()
    x0 = m @ state.x.numpy() / m.sum()
    t, report, ts, vs = 0.0, None, [], []
    while t < duration:
        dt = min(dt_factor * solver.timestep.stable_dt(0.4, report), 1e-3 * dt_factor)
        report = solver.advance(state, dt)
        assert report.reason is None, report.reason
        t += dt
        ts.append(t)
        vs.append((m @ state.v.numpy() / m.sum()) @ direction)
    disp = (m @ state.x.numpy() / m.sum() - x0) @ direction  # along ``direction`` [m]
    return np.array(ts), np.array(vs), disp, solver, state


def _acceleration(ts, vs, after=0.05):
    sel = ts > after  # after the block has settled on the face
    return np.polyfit(ts[sel], vs[sel], 1)[0]


@pytest.mark.parametrize("scheme,mu", [("empm", 0.0), ("empm", 0.3), ("tlmpm", 0.3), ("aulmpm", 0.3)])
def test_block_slides_down_a_wedge_at_coulomb_acceleration(scheme, mu):
    # a = g (sin theta - mu cos theta) for a block sliding on a plane inclined at theta
    ts, vs, _, solver, state = _incline(mu, scheme)
    expected = G * (np.sin(THETA) - mu * np.cos(THETA))
    assert _acceleration(ts, vs) == pytest.approx(expected, rel=0.02)
    assert solver.conditions.inside_colliders(state.x, solver.time).tolist() == [0]


def test_block_stays_put_when_friction_exceeds_the_slope():
    # mu > tan theta: static friction holds the block. It starts on the face and moves a few
    # hundredths of a cell while its weight settles on it (measured 0.055), then stops (1e-4)
    ts, vs, disp, _, _ = _incline(0.7, duration=0.3)
    held = ts > 0.15
    creep = np.sum(vs[held][1:] * np.diff(ts[held]))  # [m] down the slope after the weight settled
    assert abs(creep) < 0.005 / 64 and abs(disp) < 0.1 / 64
    assert np.abs(vs[held]).max() < 0.02  # a sliding block would be at 0.6 m/s here


def test_moving_collider_drags_a_block_by_friction():
    """A floor moving sideways at u (a conveyor belt: the half-space slides
    along itself) accelerates a block at rest by friction at mu g until it
    moves with the belt: the collider hands it the momentum m u."""
    u, mu, res = 0.5, 0.4, 64
    body = mpm.Body(mpm.Box((0.3, 0.3 + 0.03), (0.08, 0.03)),  # resting on the belt
                    FixedCorotated(E=1e6, nu=0.3, rho=1000.0))
    belt = Collider("half_space", boundary="separate", friction=mu, point=(0.5, 0.3), normal=(0.0, 1.0),
                    velocity=(u, 0.0))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[body], gravity=(0.0, -G),
                      ppc=4, colliders=[belt])
    ts, vs, _, solver, _ = _track(scene, "empm", 0.25, np.array([1.0, 0.0]))
    slip_end = u / (mu * G)  # 0.127 s
    sliding = ts < 0.9 * slip_end  # the block's vibrations modulate the normal force: fit the whole phase
    assert np.polyfit(ts[sliding], vs[sliding], 1)[0] == pytest.approx(mu * G, rel=0.02)
    assert vs[ts > 1.5 * slip_end].mean() == pytest.approx(u, rel=0.01)
    # the collider's speed enters the time step's speed term
    assert solver.timestep.limits(0.4)[0].wave == pytest.approx(solver.timestep.limits(0.4, max_speed=u)[0].wave)


def test_sphere_container_holds_a_splashing_fluid():
    # a fluid ball thrown at 3 m/s inside a spherical container: no particle ever gets out
    c, R, res = np.array([0.5, 0.5]), 0.4, 48
    body = mpm.Body(mpm.Sphere((0.5, 0.45), 0.15), Fluid(K=1e5, rho=1000.0), velocity=(3.0, -1.0))
    container = Collider("sphere", boundary="separate", center=tuple(c), radius=R, inside=True)
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[body], gravity=(0.0, -G),
                      ppc=4, colliders=[container])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"])
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    t, report, worst = 0.0, None, 0.0
    while t < 0.5:
        dt = min(solver.timestep.stable_dt(0.4, report), 1e-3)
        report = solver.advance(state, dt)
        assert report.reason is None
        t += dt
        worst = max(worst, np.linalg.norm(state.x.numpy() - c, axis=1).max())
        assert solver.conditions.inside_colliders(state.x, solver.time)[0] == 0
    # particles stop within a cell of the wall (the nodes inside the solid hold them)
    assert worst < R + 1.0 / res


def test_only_the_scene_colliders_compile():
    body = mpm.Body(mpm.Sphere((0.5, 0.5), 0.1), FixedCorotated())
    plain = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, bodies=[body])
    model, _ = mpm.build(plain, mpm.KERNELS["quadratic"])
    solver = mpm.Solver(model)
    assert solver.conditions.collider_kinds == () and all(k.key.find("inside") < 0 for k in solver.kernels())
    cols = [Collider("sphere", center=(0.5, 0.5), radius=0.45, inside=True),
            Collider("half_space", point=(0.5, 0.2), normal=(0.0, 1.0))]
    assert kinds_of(cols) == ("half_space", "sphere")
    model, _ = mpm.build(mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, bodies=[body], colliders=cols),
                         mpm.KERNELS["quadratic"])
    assert mpm.Solver(model).conditions.collider_kinds == ("half_space", "sphere")


# ------------------------------------------------------------ the Python description
def test_each_types_constructor_is_the_keyword_record():
    """``Collider.<type>(...)`` builds the same collider as ``Collider(type, ...)``,
    with the keys every collider has passed through."""
    pairs = [
        (Collider.half_space((0.5, 0.3), (0.0, 1.0), friction=0.2), Collider("half_space", point=(0.5, 0.3),
                                                                             normal=(0.0, 1.0), friction=0.2)),
        (Collider.wedge((0.5, 0.3), ((-1.0, 1.0), (1.0, 1.0))), Collider("wedge", point=(0.5, 0.3),
                                                                        normals=((-1.0, 1.0), (1.0, 1.0)))),
        (Collider.box((0.5, 0.5), (0.1, 0.2), boundary="sticky"), Collider("box", center=(0.5, 0.5),
                                                                           half_size=(0.1, 0.2), boundary="sticky")),
        (Collider.sphere((0.5, 0.5), 0.3, inside=True), Collider("sphere", center=(0.5, 0.5), radius=0.3, inside=True)),
        (Collider.cylinder((0.5, 0.5, 0.5), 0.1, 0.2, axis=2), Collider("cylinder", center=(0.5, 0.5, 0.5), radius=0.1,
                                                                        half_height=0.2, axis=2)),
        (Collider.cup((0.5, 0.1), 0.2, 0.3, 0.05, velocity=(0.1, 0.0), end=1.0),
         Collider("cup", center=(0.5, 0.1), radius=0.2, depth=0.3, thickness=0.05, velocity=(0.1, 0.0), end=1.0)),
        (Collider.bowl((0.5, 0.5), 0.2, 0.05, 0.1), Collider("bowl", center=(0.5, 0.5), radius=0.2, thickness=0.05,
                                                             rim=0.1)),
    ]
    for built, keyed in pairs:
        assert built == keyed
        assert built.problems(len(built.center if built.center is not None else built.point)) == []
    assert {c.type for c, _ in pairs} | {"mesh"} == set(mpm.COLLIDER_KINDS)


@pytest.mark.parametrize("collider, key", [
    (Collider("cone", center=(0.5, 0.5)), "colliders[0].type"),
    (Collider("box", center=(0.5, 0.5)), "colliders[0].half_size"),
    (Collider("half_space", point=(0.5, 0.2)), "colliders[0].normal"),
    (Collider.half_space((0.5, 0.2), (0.0, 1.0), boundary="glue"), "colliders[0].boundary"),
    (Collider.half_space((0.5, 0.2), (0.0, 1.0), friction=-0.1), "colliders[0].friction"),
    (Collider("mesh"), "colliders[0].mesh"),
])
def test_a_bad_collider_is_refused_naming_its_field(collider, key):
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, colliders=[collider],
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.6), 0.1), FixedCorotated())])
    with pytest.raises(mpm.SceneError) as e:
        mpm.build(scene, mpm.QUADRATIC)
    assert e.value.key == key, str(e.value)


@pytest.mark.parametrize("integrator", ["explicit", "implicit"])
def test_each_collider_reports_its_force(integrator):
    """A block on a frictional floor collider, gravity tilted by the friction
    it needs to hold (g_x = 0.25 g < mu g): the floor's impulse over a span of
    steps is the block's change of momentum less gravity's impulse (to
    round-off), its time-mean the block's weight and the friction that
    holds it (within 5 %: the block still vibrates), and all of the
    boundaries' impulse (no wall is reached)."""
    res = 32
    body = mpm.Body(mpm.Box((0.5, 0.35), (0.1, 0.1)), FixedCorotated(E=1e5, nu=0.3, rho=1000.0))
    floor = Collider.half_space((0.5, 0.25), (0.0, 1.0), friction=0.5, boundary="separate", name="floor")
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[body], gravity=(0.25 * G, -G),
                      colliders=[floor])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=mpm.INTEGRATORS[integrator]()))
    solver.prepare(state)
    m = model.mass.numpy()
    t, report, J, J_all, span, P0 = 0.0, None, np.zeros(2), np.zeros(2), 0.0, None
    while t < 0.6:
        dt = solver.timestep.stable_dt(0.4, report) * (5.0 if integrator == "implicit" else 1.0)
        if t > 0.2 and P0 is None:
            P0 = m @ state.v.numpy()
        report = solver.advance(state, dt)
        t += dt
        if P0 is not None:
            J, J_all, span = J + report.collider_impulse[0], J_all + report.boundary_impulse, span + dt
    M = m.sum()
    gravity = M * np.array([0.25 * G, -G])
    # explicit: round-off; implicit: the reaction at the solution, converged to newton_tol = 1e-4 of the residual
    tol = 1e-9 if integrator == "explicit" else 1e-4
    np.testing.assert_allclose(J, m @ state.v.numpy() - P0 - gravity * span, atol=tol * M * G * span)
    np.testing.assert_allclose(J / span, -gravity, rtol=0.05)
    np.testing.assert_array_equal(J, J_all)
