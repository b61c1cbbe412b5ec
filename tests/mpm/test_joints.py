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


def pendulum(dim: int, kind: str, dt: float = 1.0e-3, theta0: float = 1.0) -> dict:
    """A rigid bob (2D: a box 0.08 x 0.04 m turned by theta0; 3D: a ball
    r = 0.04 m, density 1000) hinged l = 0.25 m from its centre (3D: about
    the horizontal axis (1, 0, 1), or by a ball joint), released from rest
    at ``theta0`` [rad] and run 1.6 periods at the fixed step ``dt`` [s],
    float32, no material near (2D: a free body beside it); returns
    ``periods`` (each half period doubled, over the exact one),
    ``exact`` [s] and ``small`` [s] (the small-amplitude period), ``drift``
    (the largest distance of the anchor carried by the bob from the
    anchor [m]), ``amplitude`` [rad], ``placed`` (the largest difference
    of Newton's initial pose, centre and quaternion, from the scene's), ``free`` (the free body's final
    velocity and the closed form v0 + g t, and the step count)."""
    length = 0.25
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
    turn = np.array([0.0, 0.0, np.sin(theta0 / 2), np.cos(theta0 / 2)]) if dim == 2 else np.array([0, 0, 0, 1.0])
    placed = max(np.abs(p["position"][0] - centre).max(), np.abs(q0 - turn).max())  # Newton's start: the scene's
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
    out = dict(periods=2.0 * halves / exact, exact=exact, small=2.0 * np.pi * np.sqrt(I_p / (m * G * length)),
               drift=drift, amplitude=float(angles.max()), placed=placed)
    if dim == 2:
        out["free"] = (p["velocity"][1], np.array([0.1, 8.0 - G * steps * dt, 0.0]), steps)
    return out


@pytest.mark.parametrize("dim, kind", [(2, "revolute"), (3, "revolute"), (3, "ball")])
def test_pendulum_swings_with_the_period_of_a_physical_pendulum(dim, kind):
    """:func:`pendulum` at theta0 = 1 rad, dt = 1 ms: the exact large-amplitude
    period of a physical pendulum, T = 4 sqrt(I_p / (m g l)) K(sin(theta0 / 2)),
    I_p = I_cm + m l^2 (the small-amplitude 2 pi sqrt(I_p / (m g l)) is 6.2 %
    shorter), every half period within 1e-4 (measured 2.7e-7 to 1.0e-6 at
    1 ms and at 0.5 ms alike: float32's rounding, the step's O(dt^2) phase
    error being below it); the pivot (the anchor carried by the body) stays
    within 1e-6 m of where it was (float32 state, measured 1.0-1.5e-7). 2D:
    a free body beside it (a planar joint to the world in Newton) flies as
    v = v0 + g t, to float32's rounding of each step's
    sum (2^-24 of |v| a step)."""
    r = pendulum(dim, kind)
    assert r["placed"] < 1e-6, r["placed"]  # (float32)
    assert len(r["periods"]) >= 2 and r["amplitude"] > 0.99
    assert np.abs(r["periods"] - 1.0).max() < 1e-4, r["periods"]
    assert abs(r["small"] / r["exact"] - 1.0) > 0.05  # (the test tells the two apart)
    assert r["drift"] < 1e-6, r["drift"]
    if dim == 2:
        v, exact, steps = r["free"]
        np.testing.assert_allclose(v, exact, atol=steps * 2.0**-24 * 2 * abs(exact[1]))
        assert v[2] == 0.0


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


def strike(gravity: bool, res: int = 48) -> dict:
    """The hinged disc of :func:`_strike` striking the block (float64, EMPM,
    quadratic kernel, the adaptive step at CFL 0.4) until just before the
    block could reach a wall; returns ``rise`` [J] (the most the energy rose
    above its start: the disc's 1/2 m v^2 + 1/2 I omega^2 - m g . x, the
    material's kinetic, potential and elastic), ``E0`` [J], ``bound`` [J]
    (dt max |m g . v|: one step's work of gravity on the disc), ``lost``
    (the energy lost by the end, over E0), ``drift`` [m] (the anchor
    carried by the disc from the anchor, largest), ``v0`` and ``v0_exact``
    (the disc's initial velocity and omega x (x - anchor)), ``P_block``
    [N s/m] (the block's momentum at the end), ``omega`` and ``omega_in``
    [rad/s] (the disc's at the end, and before the strike: its initial one,
    or with gravity the one it reaches at the bottom), ``steps``."""
    scene, anchor, centre, w0 = _strike(gravity, res)
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
    v0, v0_exact = p["velocity"][0][:2], w0 * np.array([-r0[1], r0[0]])
    pivot = -r0  # the anchor from the centre at rest (the disc starts unturned)

    def body():
        p = coupler.poses()
        v, w, x = p["velocity"][0][:2], p["angular_velocity"][0][2], p["position"][0][:2]
        th = 2.0 * np.arctan2(p["quaternion"][0][2], p["quaternion"][0][3])
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        return 0.5 * mb * v @ v + 0.5 * inertia * w * w - mb * g @ x, abs(mb * g @ v), x + R @ pivot

    E0, E, rise, power, dt_max, drift, report, steps = None, 0.0, -np.inf, 0.0, 0.0, 0.0, None, 0
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
        steps += 1
    assert E0 is not None
    # the disc's rate at the bottom, from energy: 1/2 I_p w^2 = m g l (1 - cos theta0)
    w_in = abs(w0) if w0 else np.sqrt(2 * mb * G * 0.3 * (1 - np.cos(1.2)) / (inertia + mb * 0.09))
    return dict(rise=rise, E0=E0, bound=dt_max * power, lost=(E0 - E) / E0, drift=drift, v0=v0, v0_exact=v0_exact,
                P_block=m @ state.v.numpy(), omega=float(coupler.poses()["angular_velocity"][0][2]), omega_in=w_in,
                mass=mb, steps=steps)


@pytest.mark.parametrize("gravity", [False, True])
def test_pendulum_striking_a_jelly_block_never_gains_energy(gravity):
    """:func:`strike`: the energy of the disc and the material never rises
    above its start by more than the float32 body state's rounding (1e-6 of
    it; measured 4.3e-7 without gravity) plus, with gravity, one step's work
    of gravity on the disc, dt max |m g . v| (semi-implicit Euler's energy
    error is first order in dt; measured: no rise at all). Momentum is not
    kept (the hinge takes some), so it is not checked. The hinge holds
    (anchor drift below 1e-6 m; measured 8.0e-8, 9.1e-8), the disc starts at
    v = omega x (x - anchor), and the strike happened (the block took
    momentum along +x, the disc kept less than 80 % of its rate)."""
    r = strike(gravity)
    assert r["rise"] <= 1e-6 * abs(r["E0"]) + (r["bound"] if gravity else 0.0), (r["rise"], r["E0"], r["bound"])
    assert r["drift"] < 1e-6, r["drift"]
    np.testing.assert_allclose(r["v0"], r["v0_exact"], atol=1e-6)
    assert r["P_block"][0] > 0.05 * r["mass"], r["P_block"]
    assert abs(r["omega"]) < 0.8 * r["omega_in"], (r["omega"], r["omega_in"])


@pytest.mark.parametrize("kind", ["revolute", "ball"])
def test_3d_hinged_ball_striking_a_block_never_gains_energy(kind):
    """3D, float64, no gravity: a ball (r = 0.05 m, density 2000, mu = 0.3)
    hinged 0.25 m from its centre (revolute about z, or a ball joint),
    turning at 6 rad/s, strikes an elastic block off its centre line and is
    set spinning: the energy (the ball's 1/2 m v^2 + 1/2 omega . I omega, the
    material's kinetic and elastic) never rises above its start by more
    than the float32 body state's rounding (3e-6 of it; measured 6.4e-7
    revolute, 1.1e-6 ball, over 300 steps); the anchor stays within 1e-6 m
    (measured 0.8e-7, 1.4e-7); the block took momentum along +x."""
    anchor, length, th0 = np.array([0.5, 0.75, 0.5]), 0.25, 0.6
    centre = anchor + length * np.array([-np.sin(th0), -np.cos(th0), 0.0])
    bob = mpm.RigidBody(Collider.sphere(tuple(centre), 0.05, boundary="separate", friction=0.3), density=2000.0,
                        angular_velocity=(0.0, 0.0, 6.0), name="bob")
    block = mpm.Body(mpm.Box((0.61, 0.5, 0.53), (0.05, 0.05, 0.05)), FixedCorotated(E=2e5, nu=0.3, rho=1000.0))
    joint = mpm.Joint("bob", tuple(anchor), type=kind, axis=(0.0, 0.0, 1.0) if kind == "revolute" else None)
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=24, bodies=[block], gravity=(0.0, 0.0, 0.0),
                      walls=("slip",) * 6, rigid_bodies=[bob], joints=[joint], ppc=8)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    coupler = solver.conditions.rigid
    m = model.mass.numpy()
    inertia = coupler.newton.body_inertia.numpy()[0].astype(np.float64)  # (a ball: the same in any frame)
    pivot = anchor - centre

    def body_energy():
        p = coupler.poses()
        v, w = p["velocity"][0], p["angular_velocity"][0]
        return 0.5 * p["mass"][0] * v @ v + 0.5 * w @ inertia @ w

    E0, rise, drift, report = None, -np.inf, 0.0, None
    for _ in range(300):
        v = state.v.numpy()
        kinetic, e_body = 0.5 * np.sum(m * np.sum(v * v, axis=1)), body_energy()
        report = solver.advance(state, solver.timestep.stable_dt(0.4, report))
        E = kinetic + e_body + solver.step_energy()
        E0 = E if E0 is None else E0
        rise = max(rise, E - E0)
        p = coupler.poses()
        drift = max(drift, float(np.linalg.norm(p["position"][0] + quat_rotate(p["quaternion"][0], pivot) - anchor)))
    assert E0 is not None
    assert rise <= 3e-6 * E0, rise / E0
    assert drift < 1e-6, drift
    assert (m @ state.v.numpy())[0] > 0.5, m @ state.v.numpy()


def double_pendulum(dt: float = 1.0e-3, duration: float = 1.0) -> dict:
    """A rod-like box (0.02 x 0.2 m, turned 0.5 rad) hinged to the world at
    its top, a disc (r = 0.03 m) hinged to its bottom end (a body-to-body
    joint), density 1000, released under gravity, no material near, float32,
    fixed step ``dt`` [s]; returns ``drift`` [m] (the largest distance
    between a joint's anchor as carried by its child and by its parent),
    ``error`` (the largest |E - E0| of 1/2 m v^2 + 1/2 I omega^2 - m g . x,
    over the largest kinetic energy reached) and ``kinetic`` [J]."""
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
    for _ in range(int(round(duration / dt))):
        solver.advance(state, dt)
        p = coupler.poses()
        E = energy(p)
        worst = max(worst, abs(E - E0))
        kinetic = max(kinetic, E - float(np.sum(-masses * (p["position"] @ g))))
        for k, (c, par, a) in enumerate(anchors):
            at_child = p["position"][c] + quat_rotate(p["quaternion"][c], local[(c, k)])
            at_parent = (np.pad(a, (0, 1)) if par < 0
                         else p["position"][par] + quat_rotate(p["quaternion"][par], local[(par, k)]))
            drift = max(drift, float(np.linalg.norm(at_child - at_parent)))
    return dict(drift=drift, error=worst / kinetic, kinetic=kinetic)


def test_double_pendulum_holds_both_hinges():
    """:func:`double_pendulum` at dt = 1 ms for 1 s: both anchors stay
    within 1e-6 m of each other (float32 state; measured 1.8e-7); the energy
    stays within 1.5 % of the largest kinetic energy reached (semi-implicit
    Euler's energy error is first order in dt: measured 1.5 % at 2 ms,
    0.69 % at 1 ms, 0.33 % at 0.5 ms)."""
    r = double_pendulum()
    assert r["kinetic"] > 0.1  # it swung
    assert r["drift"] < 1e-6, r["drift"]
    assert r["error"] < 0.015, r["error"]


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


def test_a_cuda_graph_is_refused_with_joints():
    """The step read back for Newton cannot sit in a CUDA graph: the Driver
    refuses graph=True for a scene with joints, in one line, before the
    device (so on the CPU too)."""
    disc = mpm.RigidBody(Collider.sphere((0.5, 0.52), 0.05), density=800.0, name="disc")
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(0.0, -G), bodies=[_block(2, (0.3, 0.3))],
                      rigid_bodies=[disc], joints=[mpm.Joint("disc", (0.3, 0.52))])
    model, state = mpm.build(scene, mpm.QUADRATIC, "float32", "cpu")
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(batched=True))
    with pytest.raises(ValueError, match=r"^graph: a scene with joints or rigid contact reads each step back .*; "
                                         r"accepted: false or null$"):
        mpm.Driver(solver, state, mpm.StepPolicy(steps=4), sync_every=2, graph=True)


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
    (2, dict(type="hinge"), "joints[0].type: 'hinge'; accepted: revolute, prismatic, fixed (in 2D; ball in 3D)"),
    (2, dict(type="ball"), "joints[0].type: 'ball'; accepted: revolute, prismatic, fixed (in 2D; ball in 3D)"),
    (3, dict(type="slider", axis=(1.0, 0.0, 0.0)), "joints[0].type: 'slider'; accepted: revolute, ball, prismatic, "
                                                   "fixed"),
    (2, dict(type="prismatic"), "joints[0].axis: None; accepted: 2 finite numbers, not all 0 (the slide's"),
    (2, dict(type="prismatic", axis=(1.0, 0.0, 0.0)), "joints[0].axis: (1.0, 0.0, 0.0); accepted: 2 finite numbers"),
    (3, dict(type="fixed", axis=(1.0, 0.0, 0.0)), "joints[0].axis: (1.0, 0.0, 0.0); accepted: null (a fixed joint)"),
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


def _slider_and_weld(dim: int, v0: float = 0.2):
    """A box (density 500) on a prismatic joint to the world along (1, -1[, 0.5]), started at v0 [m/s]
    along it, and a ball welded to the world by a fixed joint; a block of material far from both."""
    axis = np.array([1.0, -1.0, 0.5][:dim])
    a = axis / np.linalg.norm(axis)
    slider = mpm.RigidBody(Collider.box((0.5, 0.7, 0.5)[:dim], (0.03,) * dim), density=500.0, name="slider",
                           velocity=tuple(v0 * a))
    weld = mpm.RigidBody(Collider.sphere((0.3, 0.7, 0.5)[:dim], 0.03), density=500.0, name="weld")
    scene = mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=16, gravity=(0.0, -G, 0.0)[:dim],
                      walls=("slip",) * 2 * dim, bodies=[_block(dim, (0.7,) + (0.3,) * (dim - 1))],
                      rigid_bodies=[slider, weld],
                      joints=[mpm.Joint("slider", (0.5, 0.7, 0.5)[:dim], type="prismatic", axis=tuple(axis)),
                              mpm.Joint("weld", (0.3, 0.7, 0.5)[:dim], type="fixed")])
    return scene, a


@pytest.mark.parametrize("dim", [2, 3])
def test_a_prismatic_joint_slides_along_its_axis_and_a_fixed_one_holds(dim):
    """A box on a prismatic joint along a, started at v0 = 0.2 m/s along it,
    gravity g: it moves along a only, by the semi-implicit Euler steps' exact
    sum s_n = v0 t + (1/2) (g . a) t (t + dt) at t = n dt (the closed form
    (1/2) (g . a) t^2 plus the scheme's first-order (1/2) (g . a) t dt),
    to the float32 state's rounding (1e-5 m over 0.2 m), without turning;
    a ball fixed to the world does not move."""
    scene, a = _slider_and_weld(dim)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"])
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    coupler = solver.conditions.rigid
    p0 = coupler.poses()
    dt, n = 1.0e-3, 200
    for _ in range(n):
        solver.advance(state, dt)
    p = coupler.poses()
    t, ga = n * dt, float(np.array([0.0, -G, 0.0][:dim]) @ a)
    moved = p["position"][0][:dim] - p0["position"][0][:dim]
    along = float(moved @ a)
    assert abs(along - (0.2 * t + 0.5 * ga * t * (t + dt))) < 1e-5, (along, 0.2 * t + 0.5 * ga * t * (t + dt))
    assert np.linalg.norm(moved - along * a) < 1e-6
    assert np.abs(p["quaternion"][0] - p0["quaternion"][0]).max() < 1e-6
    assert np.abs(p["position"][1] - p0["position"][1]).max() < 1e-7
    assert np.abs(p["velocity"][1]).max() < 1e-6


def test_a_fixed_joint_welds_a_body_to_its_parent():
    """A ball welded by a fixed joint to a box hinged to the world, released
    from 1 rad, 2D, 0.3 s at 1 ms: the ball keeps its place and orientation in
    the box's frame (float32 state: within 1e-5 m and 1e-5) while the pair
    swings through a large angle."""
    box = mpm.RigidBody(Collider.box((0.5, 0.5), (0.05, 0.02)), density=500.0, name="box")
    ball = mpm.RigidBody(Collider.sphere((0.58, 0.5), 0.02), density=500.0, name="ball")
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, gravity=(G * np.sin(1.0), -G * np.cos(1.0)),
                      walls=("slip",) * 4, bodies=[_block(2, (0.3, 0.3))], rigid_bodies=[box, ball],
                      joints=[mpm.Joint("box", (0.5, 0.7)), mpm.Joint("ball", (0.58, 0.5), type="fixed",
                                                                        parent="box")])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"])
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    coupler = solver.conditions.rigid

    def relative(p):
        """The ball's centre in the box's frame, and the two quaternions' difference."""
        return quat_rotate(quat_conj(p["quaternion"][0]), p["position"][1] - p["position"][0]), \
            np.abs(p["quaternion"][1] - p["quaternion"][0]).max()

    r0, _ = relative(coupler.poses())
    turned = 0.0
    for _ in range(300):
        solver.advance(state, 1.0e-3)
        p = coupler.poses()
        r, dq = relative(p)
        assert np.abs(r - r0).max() < 1e-5 and dq < 1e-5, (r - r0, dq)
        turned = max(turned, abs(2.0 * np.arcsin(p["quaternion"][0][2])))
    assert turned > 0.5  # it swung


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
    slid = [(mpm.RigidBody(a.shape, density=500.0, velocity=(1.0, 0.0), name="a"), "prismatic", (0.0, 1.0),
             "rigid_bodies[0].velocity: (1.0, 0.0) is not along joints[0].axis; accepted: a multiple of the axis"),
            (mpm.RigidBody(a.shape, density=500.0, angular_velocity=1.0, name="a"), "prismatic", (0.0, 1.0),
             "rigid_bodies[0].angular_velocity: 1.0 on the child of a prismatic joints[0]; accepted: null"),
            (mpm.RigidBody(a.shape, density=500.0, angular_velocity=1.0, name="a"), "fixed", None,
             "rigid_bodies[0].angular_velocity: 1.0 on the child of a fixed joints[0]; accepted: null")]
    for body, kind, axis, key in slid:
        scene = mpm.Scene(**(base | dict(rigid_bodies=[body], joints=[mpm.Joint("a", (0.5, 0.6), type=kind,
                                                                                axis=axis)])))
        with pytest.raises(SceneError) as err:
            mpm.build(scene, mpm.KERNELS["quadratic"])
        assert str(err.value).startswith(key) and "\n" not in str(err.value), str(err.value)
    spun = mpm.RigidBody(Collider.box((0.5, 0.5, 0.5), (0.05,) * 3), density=500.0, angular_velocity=(1.0, 0.0, 0.0))
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=16, bodies=[_block(3, (0.3,) * 3)], rigid_bodies=[spun],
                      gravity=(0.0, -G, 0.0), walls=("slip",) * 6,
                      joints=[mpm.Joint(0, (0.5, 0.6, 0.5), axis=(0.0, 0.0, 1.0))])
    with pytest.raises(SceneError, match=r"^rigid_bodies\[0\].angular_velocity: \(1.0, 0.0, 0.0\) is not along "
                                         r"joints\[0\].axis; accepted: a multiple of the axis"):
        mpm.build(scene, mpm.KERNELS["quadratic"])


def _dropped(mode: str, dim: int = 2):
    """Rigid bodies over the floor (walls' faces at 3 cells, 0.1875 m at 16 cells), a small block of
    material in a far corner: 2D a disc (r = 0.05, density 2000) 0.11 m above the floor, a box
    0.10 x 0.06 turned by 0.2 rad, a disc thrown at the left wall (-1.5 m/s); 3D a ball."""
    if dim == 2:
        bodies = [mpm.RigidBody(Collider.sphere((0.5, 0.3475), 0.05), density=2000.0, name="disc"),
                  mpm.RigidBody(Collider.box((0.7, 0.35), (0.05, 0.03)), density=2000.0, orientation=0.2, name="box"),
                  mpm.RigidBody(Collider.sphere((0.3, 0.3), 0.05), density=1000.0, velocity=(-1.5, 0.0),
                                name="thrown")]
    else:
        bodies = [mpm.RigidBody(Collider.sphere((0.5, 0.36, 0.5), 0.05), density=2000.0, name="ball")]
    return mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=16, bodies=[_block(dim, (0.75,) * dim)],
                     gravity=(0.0, -G, 0.0)[:dim], walls=("slip",) * 2 * dim, rigid_bodies=bodies,
                     rigid_contact=mode)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_body_dropped_on_the_floor_rests_on_it(dim):
    """rigid_contact = walls: bodies dropped onto the floor (the closed
    wall's face, 3 cells in: 0.1875 m) come to rest on it after 1 s at
    dt = 0.5 ms, float32: each one's lowest point between the face and
    m g / ke below it (the penalty's sag with one contact point holding it
    all; measured: a disc 0.8 mm, of 1.5 mm allowed; a box, landing on a
    corner, lies flat, 0.3 mm), its vertical speed below 1 mm/s and its
    rate below 0.01 rad/s (the floor is frictionless, as the walls are: the
    box, turned by its landing, slides on); the disc thrown at the left
    wall at 1.5 m/s bounced off its face (it never went past it by more
    than an undamped penalty spring would let it, v sqrt(m / ke): 13 mm;
    measured 3.9 mm; and moved right after). Without contact (none, the default)
    the same bodies fall through the floor."""
    floor = 3.0 / 16.0
    for mode in ("walls", "none"):
        scene = _dropped(mode, dim)
        model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float32")
        solver = mpm.Solver(model, mpm.EMPM())
        solver.prepare(state)
        coupler = solver.conditions.rigid
        xs = []
        for _ in range(2000):
            solver.advance(state, 5.0e-4)
            xs.append(coupler.poses()["position"][:, 0])
        p = coupler.poses()
        sag = p["mass"] * G / scene.rigid_contact_stiffness
        lowest = []
        for i, b in enumerate(scene.rigid_bodies):
            if b.shape.type == "box":  # its corners' lowest y
                th = 2.0 * np.arctan2(p["quaternion"][i][2], p["quaternion"][i][3])
                hx, hy = b.shape.half_size
                lowest.append(p["position"][i][1] - abs(hx * np.sin(th)) - abs(hy * np.cos(th)))
            else:
                lowest.append(p["position"][i][1] - b.shape.radius)
        lowest = np.array(lowest)
        if mode == "none":
            assert np.all(lowest < floor - 0.5), lowest
            continue
        assert np.all(lowest[:2] <= floor) and np.all(lowest >= floor - sag), (lowest - floor, sag)
        # at rest on it: no vertical motion, no turning (the floor is frictionless: a body may slide along it)
        assert np.abs(p["velocity"][:2, 1]).max() < 1e-3, p["velocity"]  # (the thrown one aside)
        assert np.abs(p["angular_velocity"][:2]).max() < 1e-2, p["angular_velocity"]
        if dim == 2:
            x = np.array(xs)[:, 2]
            # the left wall's face is at the floor's distance; an impact at v sinks at most v sqrt(m / ke) (one point)
            assert x.min() >= floor + 0.05 - 1.5 * np.sqrt(p["mass"][2] / scene.rigid_contact_stiffness), x.min()
            assert x[-1] > x.min() + 0.05  # it came back
            assert abs(np.sin(2.0 * np.arctan2(p["quaternion"][1][2], p["quaternion"][1][3]))) < 1e-3  # lies flat


def test_rigid_bodies_meet_one_another_with_contact_all():
    """rigid_contact = all: a disc (r = 0.05) dropped onto another resting
    on the floor, exactly above it, rests on it (centres 2 r apart, less
    the penalty's sag m g / ke at most); with walls only it falls through
    it onto the floor."""
    floor = 3.0 / 16.0
    for mode in ("all", "walls"):
        low = mpm.RigidBody(Collider.sphere((0.5, floor + 0.05), 0.05), density=2000.0, name="low")
        high = mpm.RigidBody(Collider.sphere((0.5, floor + 0.2), 0.05), density=1000.0, name="high")
        scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, bodies=[_block(2, (0.75, 0.75))],
                          gravity=(0.0, -G), rigid_bodies=[low, high], rigid_contact=mode)
        model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float32")
        solver = mpm.Solver(model, mpm.EMPM())
        solver.prepare(state)
        for _ in range(1200):
            solver.advance(state, 5.0e-4)
        p = solver.conditions.rigid.poses()
        gap = p["position"][1][1] - p["position"][0][1]
        sag = (p["mass"][0] + p["mass"][1]) * G / scene.rigid_contact_stiffness
        if mode == "all":
            assert 0.1 - sag <= gap <= 0.1, (gap, sag)
            assert np.abs(p["velocity"][:, :2]).max() < 1e-3
        else:
            assert abs(gap) < 0.01, gap  # both on the floor, one through the other


def test_bad_rigid_contact_is_refused_in_one_line():
    finite = "accepted: a finite number"
    for change, key in ((dict(rigid_contact="floor"), "rigid_contact: 'floor'; accepted: none, walls, all"),
                        (dict(rigid_contact_stiffness=0.0), f"rigid_contact_stiffness: 0.0; {finite} > 0"),
                        (dict(rigid_contact_damping=-1.0), f"rigid_contact_damping: -1.0; {finite} >= 0")):
        scene = mpm.Scene(**(vars(_dropped("walls")) | change))
        with pytest.raises(SceneError) as err:
            mpm.build(scene, mpm.KERNELS["quadratic"])
        assert str(err.value).startswith(key) and "\n" not in str(err.value), str(err.value)


def test_joints_and_rigid_contact_are_refused_under_the_implicit_integrator():
    """The implicit integrator couples free bodies only (staggered): a scene
    with joints, or with rigid contact, is refused in one line before it compiles."""
    model, _ = mpm.build(_hinged(), mpm.KERNELS["quadratic"])
    with pytest.raises(ValueError, match=r"^options.integrator: joints and rigid contact .* explicit integrator "
                                         r"only; accepted: mpm.Explicit\(\)"):
        mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=mpm.Implicit()))
    model, _ = mpm.build(_dropped("walls"), mpm.KERNELS["quadratic"])
    with pytest.raises(ValueError, match=r"^options.integrator: joints and rigid contact"):
        mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=mpm.Implicit()))
