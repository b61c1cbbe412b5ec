"""Colliders that turn (mpm.colliders, mpm.collider_motion): the signed
distance, normal and surface velocity of a turned shape against numpy,
every shape's surface carried along by its rigid motion, a sticky drum
that hands its wall speed to the sand on it, a body stuck to a turning box
turning with it, and the refusals of a badly sized or non-finite motion."""

import numpy as np
import pytest

import mpm
from collider_sdf import evaluate, evaluate_at
from mpm.collider_device import kinds_of
from mpm.colliders import TURNING, Collider, rotation_of
from mpm.materials import FixedCorotated, Sand
from mpm.meshes import MeshShape

EPS12 = 8 * np.finfo(np.float64).eps  # coordinates <= 1 m, a rotation of a few ulps more
RNG = np.random.default_rng(5)
Q2 = RNG.uniform(0.0, 1.0, (3000, 2))
Q3 = RNG.uniform(0.0, 1.0, (3000, 3))


def _box_sdf(q, c, h):
    d = np.abs(q - c) - h
    return np.linalg.norm(np.maximum(d, 0), axis=1) + np.minimum(d.max(axis=1), 0)


def _box_normal(q, c, h):
    """The box's outward normal, grad phi: outside, the direction from the
    nearest point of the box; inside, the nearest face's normal."""
    d = q - c
    e = np.abs(d) - h
    out = np.sign(d) * np.maximum(e, 0)
    inner = np.eye(q.shape[1])[e.argmax(axis=1)] * np.sign(d)
    L = np.linalg.norm(out, axis=1)
    return np.where((L > 0)[:, None], out / np.where(L > 0, L, 1)[:, None], inner)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_turned_box_against_numpy(dim):
    """A box turning at omega about an off-centre pivot while it translates
    at u, seen at t inside and after its window: phi(q) is the rest box's at
    R(-theta)(q - p - s) + p, n its normal turned by R(theta), the surface
    velocity u + omega x (q - phi n - p - s) (zero outside the window)."""
    q = Q2 if dim == 2 else Q3
    c, h = np.full(dim, 0.5), np.linspace(0.12, 0.2, dim)
    pivot = c + np.linspace(0.05, -0.03, dim)
    w = 1.3 if dim == 2 else (0.4, -0.9, 0.7)
    u = np.linspace(0.1, -0.05, dim)
    box = Collider.box(tuple(c), tuple(h), velocity=tuple(u), angular_velocity=w, pivot=tuple(pivot),
                       start=0.1, end=0.6)
    w3 = box.omega(dim)
    for time, moving in ((0.5, True), (0.8, False)):
        elapsed = min(time, 0.6) - 0.1
        R = rotation_of(w3 * elapsed, dim)
        s = u * elapsed
        rest = (q - pivot - s) @ R + pivot  # R^T (q - p - s) + p, row by row
        phi, n, v = evaluate_at(box, q, time)
        np.testing.assert_allclose(phi, _box_sdf(rest, c, h), rtol=0, atol=EPS12)
        # near a corner out / |out| magnifies the rounding of the mapped point by 1 / |out| (measured 3e-15)
        np.testing.assert_allclose(n, _box_normal(rest, c, h) @ R.T, rtol=0, atol=1e-12)
        r = q - phi[:, None] * n - pivot - s
        spin = np.cross(w3, r)[:, :dim] if dim == 3 else w3[2] * np.stack([-r[:, 1], r[:, 0]], axis=1)
        np.testing.assert_allclose(v, u + spin if moving else np.zeros_like(v), rtol=0, atol=EPS12)
    # Collider.place (the recording's pose) agrees: a rest corner lands on the turned surface
    corner = (c + h)[None, :]
    phi, _, _ = evaluate_at(box, box.place(corner, 0.5), 0.5)
    assert abs(phi[0]) < EPS12


THREE_D = [
    Collider.half_space((0.5, 0.4, 0.5), (0.3, 1.0, -0.2)),
    Collider.wedge((0.5, 0.5, 0.5), ((-1.0, 1.0, 0.2), (1.0, 1.0, 0.0))),
    Collider.box((0.5, 0.5, 0.5), (0.2, 0.1, 0.15)),
    Collider.sphere((0.5, 0.5, 0.5), 0.3, inside=True),
    Collider("cylinder", center=(0.5, 0.5, 0.5), radius=0.15, half_height=0.2, axis=(1.0, 1.0, 0.0)),
    Collider.cup((0.5, 0.3, 0.5), 0.2, 0.3, 0.05),
    Collider.bowl((0.5, 0.6, 0.5), 0.3, 0.05, 0.1),
    Collider.from_mesh(MeshShape("warp:cube", (0.5, 0.5, 0.5), 0.4)),
]


@pytest.mark.parametrize("rest", THREE_D, ids=lambda c: c.type)
def test_every_shape_turns_with_its_surface(rest):
    """For each shape, the turned and translated field is the rest field
    carried by the rigid motion (Collider.place): at the point where q has
    gone, the signed distance is the rest one at q and the normal the rest
    normal turned; the solid's velocity there is the rate of the rigid
    motion of the surface point below q (a centred difference of place over
    +-1e-4 s)."""
    moving = Collider(**{**rest.__dict__, "velocity": (0.05, -0.1, 0.02), "angular_velocity": (0.5, 1.0, -0.8)})
    q = Q3[:400]
    phi0, n0 = evaluate(rest, q)
    t, dt = 0.7, 1e-4
    phi, n, u = evaluate_at(moving, moving.place(q, t), t)
    tol = 2e-6 if rest.type == "mesh" else 1e-12  # float32 mesh queries
    np.testing.assert_allclose(phi, phi0, atol=tol)
    # away from the medial surfaces, where rounding may pick either of two normals
    far = np.abs(np.einsum("ij,ij->i", n, n0 @ moving.rotation(t, 3).T) - 1) < 1e-6
    assert far.mean() > 0.95
    np.testing.assert_allclose(n[far], (n0 @ moving.rotation(t, 3).T)[far], atol=max(tol, 1e-12))
    surface = q - phi0[:, None] * n0
    rate = (moving.place(surface, t + dt) - moving.place(surface, t - dt)) / (2 * dt)
    np.testing.assert_allclose(u[far], rate[far], atol=1e-7 + tol)  # the difference's truncation ~ (omega dt)^2


# ------------------------------------------------------------------ dynamics
def _run(scene, scheme="empm", integrator="explicit", duration=0.2, cap=1e-3):
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.SCHEMES[scheme](), mpm.SolverOptions(integrator=mpm.INTEGRATORS[integrator]()))
    solver.prepare(state)
    x0 = state.x.numpy().copy()
    factor = 5.0 if integrator == "implicit" else 1.0
    t, report = 0.0, None
    while t < duration:
        dt = min(factor * solver.timestep.stable_dt(0.4, report), factor * cap)
        report = solver.advance(state, dt)
        assert report.reason is None, report.reason
        t += dt
    assert not solver.conditions.inside_colliders(state.x, solver.time).any()
    return x0, state.x.numpy(), state.v.numpy(), solver.time


@pytest.mark.parametrize("boundary, friction, integrator", [("sticky", 0.0, "explicit"),
                                                         ("separate", 1.0, "explicit"),
                                                         ("separate", 1.0, "implicit")])
def test_a_turning_drum_carries_the_sand_on_its_wall(boundary, friction, integrator):
    """Sand filling the lower half of a circular drum (R = 0.4 m, 32 cells
    across 1 m) that turns at omega = 2 rad/s, sticky or with mu = 1: after
    0.25 s (0.5 rad, short of the 35 deg the sand would slide at) the sand
    within a cell of the wall moves with the wall, at the tangential speed
    omega r. Measured: v_t / (omega r) 0.994 (sticky) and 0.990 (mu = 1)
    on average, each particle's v_t / (omega R) >= 0.88 and 0.85: the
    wall's nodes move at omega R, a particle a cell in at omega (R - dx) =
    0.92 omega R, less what the grid blends in from the sand further in.
    A wall at rest leaves it at about 0. The implicit integrator's friction,
    inside its solve (mpm.implicit.rough), holds the sand to the wall's
    turning surface the same way."""
    res, omega, R = 32, 2.0, 0.4
    c, dx = np.array([0.5, 0.5]), 1.0 / res
    sand = mpm.Body(mpm.scene.Bowl(tuple(c), 1e-3, R - 0.5 * dx, 0.0),  # the lower half disc
                    Sand(E=1e6, nu=0.3, rho=2200.0, friction_angle=35.0))
    drum = Collider.sphere(tuple(c), R, inside=True, boundary=boundary, friction=friction, angular_velocity=omega)
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[sand], gravity=(0.0, -9.81),
                      colliders=[drum])
    _, x, v, _ = _run(scene, integrator=integrator, duration=0.25)
    d = x - c
    r = np.linalg.norm(d, axis=1)
    vt = np.einsum("ij,ij->i", v, np.stack([-d[:, 1], d[:, 0]], axis=1) / r[:, None])  # counter-clockwise
    wall = r > R - dx
    assert wall.sum() > 100
    assert np.mean(vt[wall] / (omega * r[wall])) == pytest.approx(1.0, abs=0.02)
    assert vt[wall].min() > 0.8 * omega * R and vt[wall].max() < omega * R * (1 + 1e-9)


@pytest.mark.parametrize("scheme, integrator", [("empm", "explicit"), ("tlmpm", "explicit"), ("empm", "implicit")])
def test_a_body_stuck_to_a_turning_box_turns_with_it(scheme, integrator):
    """An elastic square frame around a sticky box collider (32 cells across
    1 m, no gravity) that turns at 1 rad/s about its centre: after 0.2 rad
    every particle is where the rotation carries it, R(theta)(x0 - c) + c,
    within 0.02 cells (measured 0.0016 explicit EMPM, 0.0007 TLMPM, 0.0065
    implicit) while the frame's corners have moved 1.2 cells: the wall
    hands the frame its rigid velocity omega x r and the frame is stiff
    (E = 1e6 Pa: its centripetal load omega^2 r rho strains it by 1e-7)."""
    res, omega, h, w = 32, 1.0, 0.08, 0.06
    c = np.array([0.5, 0.5])
    parts = (mpm.Box((0.5, 0.5 + h + w / 2), (h + w, w / 2)), mpm.Box((0.5, 0.5 - h - w / 2), (h + w, w / 2)),
             mpm.Box((0.5 + h + w / 2, 0.5), (w / 2, h)), mpm.Box((0.5 - h - w / 2, 0.5), (w / 2, h)))
    frame = mpm.Body(mpm.scene.Compound(parts), FixedCorotated(E=1e6, nu=0.3, rho=1000.0))
    box = Collider.box(tuple(c), (h, h), boundary="sticky", angular_velocity=omega)
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=res, bodies=[frame], gravity=(0.0, 0.0),
                      colliders=[box])
    x0, x, _, time = _run(scene, scheme, integrator, duration=0.2)
    turned = (x0 - c) @ rotation_of((0.0, 0.0, omega * time), 2).T + c
    assert np.linalg.norm(x - x0, axis=1).max() * res > 1.1
    assert np.linalg.norm(x - turned, axis=1).max() * res < 0.02


def test_a_shell_stuck_to_a_box_turning_about_a_tilted_axis_turns_with_it():
    """3D: an elastic shell of six slabs around a sticky box collider that
    turns at |omega| = 1.04 rad/s about the axis (0.3, 0.6, 0.8) (16 cells
    across 1 m, one particle per cell): after 0.2 s every particle is where
    the rigid motion carries it (Collider.place) within 0.1 cells (measured
    0.026) while the shell's corners have moved 1.24 cells."""
    res, h, w = 16, 0.125, 0.125
    c = np.full(3, 0.5)
    parts = []
    for k in range(3):
        for side in (-1, 1):
            centre, half = c.copy(), np.full(3, h + w)
            centre[k] += side * (h + w / 2)
            half[k] = w / 2
            parts.append(mpm.Box(tuple(centre), tuple(half)))
    shell = mpm.Body(mpm.scene.Compound(tuple(parts)), FixedCorotated(E=1e6, nu=0.3, rho=1000.0))
    box = Collider.box(tuple(c), (h,) * 3, boundary="sticky", angular_velocity=(0.3, 0.6, 0.8))
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=res, bodies=[shell], gravity=(0.0,) * 3, ppc=1,
                      walls=("slip",) * 6, colliders=[box])
    x0, x, _, time = _run(scene, duration=0.2)
    assert np.linalg.norm(x - x0, axis=1).max() * res > 1.1
    assert np.linalg.norm(x - box.place(x0, time), axis=1).max() * res < 0.1


def test_a_collider_turning_at_zero_moves_as_one_that_does_not_turn():
    """The rotation code with omega = 0 (compiled, turning by the identity)
    and the translation alone (the code of every scene without a turning
    collider) give the same run to round-off: a block dragged by a moving
    frictional floor and pushed by a moving sticky box."""
    runs = []
    for spin in (None, 0.0):
        body = mpm.Body(mpm.Box((0.4, 0.33), (0.08, 0.03)), FixedCorotated(E=1e5, nu=0.3, rho=1000.0))
        cols = [Collider.half_space((0.5, 0.3), (0.0, 1.0), boundary="separate", friction=0.4, velocity=(0.5, 0.0),
                                    angular_velocity=spin),
                Collider.box((0.2, 0.35), (0.05, 0.05), boundary="sticky", velocity=(0.3, 0.0), start=0.05)]
        scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, bodies=[body], gravity=(0.0, -9.81),
                          colliders=cols)
        runs.append(_run(scene, duration=0.15)[1])
    np.testing.assert_allclose(runs[1], runs[0], rtol=0, atol=1e-12)


def test_only_turning_scenes_compile_the_rotation():
    still = [Collider.sphere((0.5, 0.5), 0.45, inside=True, velocity=(0.1, 0.0))]
    assert kinds_of(still) == ("sphere",)
    assert kinds_of(still + [Collider.box((0.5, 0.2), (0.1, 0.1), angular_velocity=0.0)]) == ("box", "sphere", TURNING)


def test_a_turning_collider_s_speed_enters_the_time_step():
    """|u| + |omega| times the farthest corner of the domain from the pivot:
    a drum turning at 2 rad/s about the middle of a 1 m square, moving at
    0.1 m/s, bounds its surface's speed by 0.1 + 2 sqrt(0.5) m/s."""
    drum = Collider.sphere((0.5, 0.5), 0.4, inside=True, angular_velocity=-2.0, velocity=(0.0, 0.1))
    assert drum.speed((1.0, 1.0)) == pytest.approx(0.1 + 2.0 * np.sqrt(0.5), rel=1e-12)
    assert drum.speed() == pytest.approx(0.1)  # no domain: the translation alone, as before
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=8, colliders=[drum],
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.5), 0.1), FixedCorotated())])
    model, _ = mpm.build(scene, mpm.QUADRATIC)
    assert mpm.Solver(model).conditions.speed() == pytest.approx(0.1 + 2.0 * np.sqrt(0.5), rel=1e-12)


@pytest.mark.parametrize("dim, keys, key", [
    (2, dict(angular_velocity=(1.0, 2.0)), "colliders[0].angular_velocity"),
    (2, dict(angular_velocity=float("nan")), "colliders[0].angular_velocity"),
    (3, dict(angular_velocity=1.0), "colliders[0].angular_velocity"),
    (3, dict(angular_velocity=(1.0, float("inf"), 0.0)), "colliders[0].angular_velocity"),
    (2, dict(angular_velocity=1.0, pivot=(0.5, 0.5, 0.5)), "colliders[0].pivot"),
    (3, dict(angular_velocity=(0.0, 1.0, 0.0), pivot=(0.5, float("nan"), 0.5)), "colliders[0].pivot"),
    (2, dict(velocity=(1.0, 0.0, 0.0)), "colliders[0].velocity"),
])
def test_a_bad_turning_motion_is_refused_naming_its_key(dim, keys, key):
    collider = Collider.sphere((0.5,) * dim, 0.45, inside=True, **keys)
    scene = mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=8, colliders=[collider], gravity=(0.0,) * dim,
                      walls=("slip",) * 2 * dim,
                      bodies=[mpm.Body(mpm.Sphere((0.5,) * dim, 0.1), FixedCorotated())])
    with pytest.raises(mpm.SceneError) as e:
        mpm.build(scene, mpm.QUADRATIC)
    assert e.value.key == key, str(e.value)
    message = str(e.value)
    assert "\n" not in message and "accepted:" in message
