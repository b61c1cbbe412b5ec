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
from mpm.materials import FixedCorotated
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


def test_only_turning_scenes_compile_the_rotation():
    still = [Collider.sphere((0.5, 0.5), 0.45, inside=True, velocity=(0.1, 0.0))]
    assert kinds_of(still) == ("sphere",)
    assert kinds_of(still + [Collider.box((0.5, 0.2), (0.1, 0.1), angular_velocity=0.0)]) == ("box", "sphere", TURNING)


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
