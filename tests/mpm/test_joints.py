"""Joints through Newton (mpm.joints): pendulums against the closed-form
period, a hinged body striking an elastic block without gaining energy, a
double pendulum, batched steps, and the one-line refusals."""

import numpy as np
import pytest

import mpm
from mpm.colliders import Collider
from mpm.materials import FixedCorotated
from mpm.model import SceneError

pytest.importorskip("newton")

G = 9.81


def elliptic_k(k: float) -> float:
    """K(k) = int_0^{pi/2} dphi / sqrt(1 - k^2 sin^2 phi), by the arithmetic-geometric mean:
    K = pi / (2 AGM(1, sqrt(1 - k^2)))."""
    a, b = 1.0, np.sqrt(1.0 - k * k)
    for _ in range(40):
        a, b = 0.5 * (a + b), np.sqrt(a * b)
    return np.pi / (2.0 * a)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` turned by the unit quaternion q = (x, y, z, w)."""
    u, w = q[:3], q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def quat_conj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def half_periods(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """The times between the angle's successive zero crossings (linear interpolation)."""
    i = np.flatnonzero(angle[:-1] * angle[1:] < 0.0)
    crossings = t[i] - angle[i] * (t[i + 1] - t[i]) / (angle[i + 1] - angle[i])
    return np.diff(crossings)


def _block(dim: int, centre) -> mpm.Body:
    return mpm.Body(mpm.Box(centre, (0.04,) * dim), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))


@pytest.mark.parametrize("dim, kind", [(2, "revolute"), (3, "revolute"), (3, "ball")])
def test_pendulum_swings_with_the_period_of_a_physical_pendulum(dim, kind):
    """A rigid bob (2D: a box 0.08 x 0.04 m turned by theta0; 3D: a
    ball r = 0.04 m) hinged l = 0.25 m from its centre, released from rest
    at theta0 = 1 rad, no material near: the exact large-amplitude period of
    a physical pendulum, T = 4 sqrt(I_p / (m g l)) K(sin(theta0 / 2)),
    I_p = I_cm + m l^2 (the small-amplitude 2 pi sqrt(I_p / (m g l)) is 6.6 %
    shorter), every half period within 1e-4 (measured 2e-6 at dt = 1 ms:
    semi-implicit Euler's phase error is O(dt^2)); the pivot (the anchor
    carried by the body) stays within 1e-6 m of where it was (float32 state,
    measured 1e-7). 3D: the revolute axis (1, 0, 1) is horizontal; the ball
    joint swings in the same plane. 2D: a free body beside it (a planar joint
    to the world in Newton) flies as v = v0 + g t."""
    theta0, length, dt = 1.0, 0.25, 1.0e-3
    anchor = np.array([0.5, 0.8] + [0.5] * (dim - 2))
    if dim == 2:
        axis, down, across = np.array([0.0, 0.0, 1.0]), np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    else:
        axis = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
        down, across = np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, -1.0]) / np.sqrt(2.0)
    # the bob displaced by theta0 about the axis: r = l (cos down + sin across)
    a3 = np.pad(anchor, (0, 3 - dim))
    centre = a3 + length * (np.cos(theta0) * down + np.sin(theta0) * across)
    if dim == 2:
        shape, orientation = Collider.box(tuple(centre[:2]), (0.04, 0.02)), theta0
    else:
        shape, orientation = Collider.sphere(tuple(centre), 0.04), None
    bob = mpm.RigidBody(shape, density=1000.0, orientation=orientation, name="bob")
    bodies = [bob]
    if dim == 2:
        bodies.append(mpm.RigidBody(Collider.sphere((0.8, 0.8), 0.03), density=500.0, velocity=(0.1, 8.0)))
    joint = mpm.Joint("bob", tuple(anchor), type=kind, axis=tuple(axis) if (dim == 3 and kind == "revolute") else None)
    scene = mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=16 if dim == 2 else 12, gravity=(0.0, -G, 0.0)[:dim],
                      bodies=[_block(dim, (0.3,) * dim)], walls=("slip",) * 2 * dim, rigid_bodies=bodies,
                      joints=[joint])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float32")
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    coupler = solver.conditions.rigid
    p = coupler.poses()
    m = float(p["mass"][0])
    inertia = coupler.newton.body_inertia.numpy()[0].astype(np.float64)
    I_p = float(axis @ inertia @ axis) + m * length**2
    exact = 4.0 * np.sqrt(I_p / (m * G * length)) * elliptic_k(np.sin(theta0 / 2.0))
    q0 = p["quaternion"][0]
    pivot = quat_rotate(quat_conj(q0), a3 - p["position"][0])  # the anchor in the bob's frame
    steps = int(1.6 * exact / dt)
    angles, drift = np.empty(steps), 0.0
    for i in range(steps):
        solver.advance(state, dt)
        p = coupler.poses()
        r = p["position"][0] - a3
        angles[i] = np.arctan2(np.cross(down, r) @ axis, down @ r)
        drift = max(drift, float(np.linalg.norm(p["position"][0] + quat_rotate(p["quaternion"][0], pivot) - a3)))
    halves = half_periods(dt * np.arange(1, steps + 1), angles)
    assert len(halves) >= 2 and angles.max() > 0.99 * theta0
    assert np.abs(2.0 * halves / exact - 1.0).max() < 1e-4, (2.0 * halves, exact)
    assert drift < 1e-6, drift
    if dim == 2:
        # v = v0 + g t, to float32's rounding of each step's sum (2^-24 of |v| a step)
        v = 8.0 - G * steps * dt
        np.testing.assert_allclose(p["velocity"][1], [0.1, v, 0.0], atol=steps * 2.0**-24 * 2 * abs(v))
        assert p["angular_velocity"][1][2] == 0.0


def _strike(gravity: bool, res: int = 48):
    """A disc (r = 0.05 m, density 2000) hinged 0.3 m above its centre
    strikes an elastic block (E = 2e5 Pa) in float64: with gravity, released
    from rest at 1.2 rad onto a block on the floor; without, turning at
    6 rad/s from 0.6 rad into a floating block."""
    anchor, length, r = np.array([0.5, 0.45 if gravity else 0.75]), 0.3, 0.05
    theta0, w0 = (1.2, 0.0) if gravity else (0.6, 6.0)
    centre = anchor + length * np.array([-np.sin(theta0), -np.cos(theta0)])
    bob = mpm.RigidBody(Collider.sphere(tuple(centre), r, boundary="separate"), density=2000.0, angular_velocity=w0,
                        name="bob")
    x_block = 0.5 + r + 0.065
    block = mpm.Body(mpm.Box((x_block, 3.0 / res + 0.06 if gravity else 0.45), (0.06, 0.06)),
                     FixedCorotated(E=2e5, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[block], gravity=(0.0, -G if gravity else 0.0),
                      rigid_bodies=[bob], joints=[mpm.Joint("bob", tuple(anchor))])
    return scene, anchor, centre, w0


@pytest.mark.parametrize("gravity", [False, True])
def test_pendulum_striking_a_jelly_block_never_gains_energy(gravity):
    """The hinged disc of :func:`_strike` strikes the block (float64, EMPM,
    quadratic kernel, adaptive step): the energy of the two, the disc's
    kinetic energy 1/2 m v^2 + 1/2 I omega^2 and potential -m g . x, and the
    material's kinetic, potential and elastic, never rises above its start
    by more than the float32 body state's rounding (1e-6 of it: measured
    4e-7 without gravity) plus, with gravity, one step's work of gravity on
    the disc, dt max |m g . v| (semi-implicit Euler's energy error is first
    order in dt; measured: no rise at all). Momentum is not kept (the hinge
    takes some), so it is not checked; the hinge holds (anchor drift below
    1e-6 m, measured 9e-8), the disc starts at v = omega x (x - anchor), and
    the strike happened (the block took momentum, the disc slowed)."""
    scene, anchor, centre, w0 = _strike(gravity)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    coupler = solver.conditions.rigid
    m = model.mass.numpy()
    g = np.array(scene.gravity)
    inertia = float(coupler.newton.body_inertia.numpy()[0][2, 2])
    p = coupler.poses()
    mb = float(p["mass"][0])
    r0 = centre - anchor
    np.testing.assert_allclose(p["velocity"][0][:2], w0 * np.array([-r0[1], r0[0]]), atol=1e-6)
    pivot = -r0  # the anchor from the centre at rest (the disc starts unturned)

    def body():
        p = coupler.poses()
        v, w, x = p["velocity"][0][:2], p["angular_velocity"][0][2], p["position"][0][:2]
        th = 2.0 * np.arctan2(p["quaternion"][0][2], p["quaternion"][0][3])
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        return 0.5 * mb * v @ v + 0.5 * inertia * w * w - mb * g @ x, abs(mb * g @ v), x + R @ pivot

    E0, rise, power, dt_max, drift, report = None, -np.inf, 0.0, 0.0, 0.0, None
    duration = 0.42 if gravity else 0.28  # the block has not reached a wall
    while report is None or solver.time < duration:
        v, x = state.v.numpy(), state.x.numpy()
        material = 0.5 * np.sum(m * np.sum(v * v, axis=1)) - np.sum(m * (x @ g))
        e_body, p_gravity, _ = body()
        report = solver.advance(state, solver.timestep.stable_dt(0.4, report))
        E = material + e_body + solver.step_energy()  # (the state the step started from)
        E0 = E if E0 is None else E0
        rise, power, dt_max = max(rise, E - E0), max(power, p_gravity), max(dt_max, report.dt)
        drift = max(drift, float(np.linalg.norm(body()[2] - anchor)))
    assert E0 is not None
    assert rise <= 1e-6 * abs(E0) + dt_max * power, (rise, E0, dt_max * power)
    assert drift < 1e-6, drift
    P_block = m @ state.v.numpy()
    assert P_block[0] > 0.05 * mb * 1.0, P_block  # the block was pushed along +x
    w = coupler.poses()["angular_velocity"][0][2]
    assert abs(w) < 0.8 * (abs(w0) if w0 else np.sqrt(2 * mb * G * 0.3 * (1 - np.cos(1.2)) / (inertia + mb * 0.09)))


def test_double_pendulum_holds_both_hinges():
    """A rod-like box (turned 0.5 rad) hinged to the world at its top, a
    disc hinged to its bottom end (a body-to-body joint), released under
    gravity, no material near, dt = 1 ms for 1 s: both anchors, carried by
    the bodies, stay within 1e-6 m of each other (float32 state); the
    energy 1/2 m v^2 + 1/2 I omega^2 - m g . x of the two stays within 2 %
    of the largest kinetic energy reached (semi-implicit Euler's error is
    first order in dt; measured 0.4 % at 1 ms, 0.2 % at 0.5 ms)."""
    top = np.array([0.5, 0.8])
    tilt, half = 0.5, 0.1
    u = np.array([np.sin(tilt), -np.cos(tilt)])  # along the rod, downward
    rod_c, elbow = top + half * u, top + 2 * half * u
    disc_c = elbow + np.array([0.12, 0.0])
    rod = mpm.RigidBody(Collider.box(tuple(rod_c), (0.01, half)), density=1000.0, orientation=tilt, name="rod")
    disc = mpm.RigidBody(Collider.sphere(tuple(disc_c), 0.03), density=1000.0, name="disc")
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(0.0, -G), bodies=[_block(2, (0.25, 0.25))],
                      rigid_bodies=[rod, disc],
                      joints=[mpm.Joint("disc", tuple(elbow), parent="rod"), mpm.Joint("rod", tuple(top))])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float32")
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    coupler = solver.conditions.rigid
    masses = coupler.newton.body_mass.numpy().astype(np.float64)
    inertias = coupler.newton.body_inertia.numpy()[:, 2, 2].astype(np.float64)
    g = np.array([0.0, -G, 0.0])
    p = coupler.poses()
    anchors = [(0, -1, top), (1, 0, elbow)]  # (child, parent, point)
    local = {(b, k): quat_rotate(quat_conj(p["quaternion"][b]), np.pad(a, (0, 1)) - p["position"][b])
             for k, (c, par, a) in enumerate(anchors) for b in (c, par) if b >= 0}

    def energy(p):
        v, w, x = p["velocity"], p["angular_velocity"][:, 2], p["position"]
        return float(np.sum(0.5 * masses * np.sum(v * v, axis=1) + 0.5 * inertias * w * w - masses * (x @ g)))

    E0, worst, kinetic, drift = energy(p), 0.0, 0.0, 0.0
    for _ in range(1000):
        solver.advance(state, 1.0e-3)
        p = coupler.poses()
        E = energy(p)
        worst = max(worst, abs(E - E0))
        kinetic = max(kinetic, E - float(np.sum(-masses * (p["position"] @ g))))
        for k, (c, par, a) in enumerate(anchors):
            at_child = p["position"][c] + quat_rotate(p["quaternion"][c], local[(c, k)])
            at_parent = (np.pad(a, (0, 1)) if par < 0
                         else p["position"][par] + quat_rotate(p["quaternion"][par], local[(par, k)]))
            drift = max(drift, float(np.linalg.norm(at_child - at_parent)))
    assert kinetic > 0.1  # it swung
    assert drift < 1e-6, drift
    assert worst < 0.02 * kinetic, worst / kinetic


def test_batched_steps_with_joints_move_the_bodies_as_single_steps_do():
    """A scene with joints reads each step back for Newton (one read per
    step, ``Coupler.reads``) and steps nothing where the driver skips: a
    hinged disc striking a ball, run by batches of 4 and of 7 steps (the
    last batch cut short), ends bit for bit where single steps end."""
    def run(batched, k):
        ball = mpm.Body(mpm.Sphere((0.5, 0.35), 0.1), mpm.NeoHookean(E=1e5, nu=0.3), velocity=(0.5, 0.0))
        disc = mpm.RigidBody(Collider.sphere((0.5, 0.52), 0.05), density=800.0, angular_velocity=-8.0, name="disc")
        scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(0.0, -G), bodies=[ball],
                          rigid_bodies=[disc], joints=[mpm.Joint("disc", (0.3, 0.52))])
        model, state = mpm.build(scene, mpm.QUADRATIC, "float32", "cpu")
        solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(batched=batched))
        driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=40), sync_every=k)
        assert driver.run().status == "completed" and driver.step == 40
        coupler = solver.conditions.rigid
        assert coupler.reads >= 40
        return state.x.numpy(), coupler.body_q.numpy(), coupler.body_qd.numpy(), coupler.joint_qd.numpy()

    single = run(False, 1)
    assert abs(single[3][0] + 8.0) > 0.1  # the ball slowed the disc
    for k in (4, 7):
        for a, b in zip(single, run(True, k)):
            assert np.array_equal(a, b), k


def _hinged(dim=2, **change):
    body = mpm.RigidBody(Collider.box((0.5, 0.5, 0.5)[:dim], (0.05,) * dim), density=500.0, name="box")
    keys = dict(child="box", anchor=(0.5, 0.6, 0.5)[:dim]) | change
    return mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=16, bodies=[_block(dim, (0.3,) * dim)],
                     gravity=(0.0, -G, 0.0)[:dim], walls=("slip",) * 2 * dim, rigid_bodies=[body],
                     joints=[mpm.Joint(**keys)])


@pytest.mark.parametrize("dim, change, key", [
    (2, dict(child="lid"), "joints[0].child: 'lid' is no rigid body; accepted: a rigid body's index (0 to 0) or "
                           "name (box)"),
    (2, dict(child=3), "joints[0].child: 3 is no rigid body; accepted: a rigid body's index"),
    (2, dict(parent="box"), "joints[0].parent: 'box' is the child itself; accepted: null (the world)"),
    (2, dict(parent="door"), "joints[0].parent: 'door' is no rigid body; accepted: null (the world) or"),
    (2, dict(type="hinge"), "joints[0].type: 'hinge'; accepted: revolute (in 2D; ball in 3D)"),
    (2, dict(type="ball"), "joints[0].type: 'ball'; accepted: revolute (in 2D; ball in 3D)"),
    (3, dict(type="prismatic", axis=(1.0, 0.0, 0.0)), "joints[0].type: 'prismatic'; accepted: revolute, ball"),
    (2, dict(anchor=(0.5, 1.5)), "joints[0].anchor: [0.5, 1.5] lies outside the domain; accepted: a point in"),
    (2, dict(anchor=(0.5,)), "joints[0].anchor: (0.5,); accepted: 2 finite numbers [m]"),
    (2, dict(axis=(0.0, 0.0, 1.0)), "joints[0].axis: (0.0, 0.0, 1.0); accepted: null (about z in 2D)"),
    (3, dict(), "joints[0].axis: None; accepted: 3 finite numbers, not all 0"),
    (3, dict(axis=(0.0, 0.0, 0.0)), "joints[0].axis: (0.0, 0.0, 0.0); accepted: 3 finite numbers, not all 0"),
    (3, dict(type="ball", axis=(0.0, 0.0, 1.0)), "joints[0].axis: (0.0, 0.0, 1.0); accepted: null (a ball)"),
])
def test_bad_joints_are_refused_in_one_line(dim, change, key):
    with pytest.raises(SceneError) as err:
        mpm.build(_hinged(dim, **change), mpm.KERNELS["quadratic"])
    assert str(err.value).startswith(key) and "\n" not in str(err.value), str(err.value)


def test_joints_that_break_the_tree_or_the_motion_are_refused():
    """Two joints on one child, a loop of parents, a child given a velocity,
    a 3D revolute child turning off its axis: one line each, before compiling."""
    a = mpm.RigidBody(Collider.box((0.5, 0.5), (0.05, 0.05)), density=500.0, name="a")
    b = mpm.RigidBody(Collider.box((0.5, 0.7), (0.05, 0.05)), density=500.0, name="b")
    base = dict(dim=2, domain=(1.0, 1.0), resolution=16, bodies=[_block(2, (0.3, 0.3))])
    cases = [
        (dict(rigid_bodies=[a, b], joints=[mpm.Joint("a", (0.5, 0.6)), mpm.Joint("a", (0.5, 0.4))]),
         "joints[1].child: 'a' is already the child of joints[0]; accepted: each rigid body the child of one joint"),
        (dict(rigid_bodies=[a, b], joints=[mpm.Joint("a", (0.5, 0.6), parent="b"), mpm.Joint("b", (0.5, 0.6),
                                                                                                 parent="a")]),
         "joints[0].parent: closes a loop of joints; accepted: joints that form trees"),
        (dict(rigid_bodies=[mpm.RigidBody(a.shape, density=500.0, velocity=(1.0, 0.0), name="a")],
              joints=[mpm.Joint("a", (0.5, 0.6))]),
         "rigid_bodies[0].velocity: (1.0, 0.0) on the child of joints[0]; accepted: null"),
        (dict(rigid_bodies=[], joints=[mpm.Joint(0, (0.5, 0.6))]),
         "joints[0].child: 0 is no rigid body; accepted: a rigid body, but the scene has none"),
    ]
    for change, key in cases:
        with pytest.raises(SceneError) as err:
            mpm.build(mpm.Scene(**(base | change)), mpm.KERNELS["quadratic"])
        assert str(err.value).startswith(key) and "\n" not in str(err.value), str(err.value)
    spun = mpm.RigidBody(Collider.box((0.5, 0.5, 0.5), (0.05,) * 3), density=500.0, angular_velocity=(1.0, 0.0, 0.0))
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=16, bodies=[_block(3, (0.3,) * 3)], rigid_bodies=[spun],
                      gravity=(0.0, -G, 0.0), walls=("slip",) * 6,
                      joints=[mpm.Joint(0, (0.5, 0.6, 0.5), axis=(0.0, 0.0, 1.0))])
    with pytest.raises(SceneError, match=r"^rigid_bodies\[0\].angular_velocity: \(1.0, 0.0, 0.0\) is not along "
                                         r"joints\[0\].axis; accepted: a multiple of the axis"):
        mpm.build(scene, mpm.KERNELS["quadratic"])
