"""Where a collider is at a time, on the device: its translation
(:func:`make_motion`) and, for a collider that turns, its rotation about the
moving pivot (:func:`make_place`; mpm.colliders describes both).

A turning collider's shape at time t is its rest shape turned by the
rotation vector theta = omega (clamp(t, start, end) - start) about the pivot
p, then displaced by s(t): a point q is in the shape where its rest shape
holds R(-theta) (q - p - s) + p, so the signed distance there is the rest
shape's, and the outward normal the rest normal turned by R(theta). The
velocity of the solid at the point q_s of its surface below q,
q_s = q - phi n, is the rigid motion's

    u(q_s) = u + omega x (q_s - p - s(t))

(2D: omega about z, omega x r = omega (-r_y, r_x)), zero rotation rate
outside the window like the translation. Only the shapes ``kinds`` that
name :data:`mpm.colliders.TURNING` compile the rotation; the others place a
collider by its translation alone, as before turning existed.

A rigid body (mpm.rigid, ``kinds`` naming :data:`mpm.colliders.RIGID`) is
a collider whose record mpm.rigid_coupling rewrites every step from the
body's pose: the window starts at the step's time, ``u`` and ``omega`` are
the body's velocities, and two more fields give the pose then, the pivot's
displacement ``origin`` and the rotation ``frame`` from rest, so that

    q_rest = R(-frame) R(-theta) (q - p - origin - s(t)) + p,

and the normal is the rest normal turned by R(theta) R(frame). A plain
collider in such a scene has both at zero, and is placed as above.
"""

import functools

import warp as wp

from .collider_shapes import make_collider_data, make_sdf
from .colliders import RIGID, TURNING
from .types import Types


@functools.cache
def make_motion(t: Types):
    """``motion(c, time) -> (displacement, velocity)`` of collider ``c``."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)

    @wp.func
    def motion(c: Data, time: S):
        tc = wp.min(wp.max(time, c.window[0]), c.window[1])
        u = vec()
        if time >= c.window[0] and time < c.window[1]:
            u = c.u
        return (tc - c.window[0]) * c.u, u

    return motion


@functools.cache
def make_turn(t: Types):
    """``turn(v, angle) -> R(angle) v``: ``v`` turned by the rotation vector
    ``angle`` [rad] (3 numbers; 2D: about z, its third); ``spin(w, r) -> w x r``
    (2D: w about z)."""
    S, vec = t.scalar, t.vec
    V3 = wp.types.vector(3, S)

    if t.dim == 2:
        @wp.func
        def turn(v: vec, angle: V3):  # pyright: ignore[reportRedeclaration]
            c = wp.cos(angle[2])
            s = wp.sin(angle[2])
            return vec(c * v[0] - s * v[1], s * v[0] + c * v[1])  # pyright: ignore[reportCallIssue]

        @wp.func
        def spin(w: V3, r: vec):  # pyright: ignore[reportRedeclaration]
            return vec(-w[2] * r[1], w[2] * r[0])  # pyright: ignore[reportCallIssue]

        return turn, spin

    @wp.func
    def turn(v: vec, angle: V3):
        theta = wp.length(angle)
        if theta == S(0.0):
            return v
        k = vec(angle[0], angle[1], angle[2]) / theta  # pyright: ignore[reportCallIssue]
        c = wp.cos(theta)
        # Rodrigues: v cos + (k x v) sin + k (k . v)(1 - cos)
        return v * c + wp.cross(k, v) * wp.sin(theta) + k * (wp.dot(k, v) * (S(1.0) - c))

    @wp.func
    def spin(w: V3, r: vec):
        return wp.cross(vec(w[0], w[1], w[2]), r)  # pyright: ignore[reportCallIssue]

    return turn, spin


@functools.cache
def make_place(t: Types, kinds: tuple[str, ...]):
    """``place(c, q, time) -> (phi, n, u)``: the signed distance [m] of the
    point ``q`` from collider ``c`` where it is at ``time`` [s], its outward
    normal there and the velocity [m/s] of the solid at the surface point
    q - phi n (module docstring). Only the shapes in ``kinds`` are compiled,
    the rotation only with :data:`mpm.colliders.TURNING` among them."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    V3 = wp.types.vector(3, S)
    sdf = make_sdf(t, kinds)
    motion = make_motion(t)

    if TURNING not in kinds:
        @wp.func
        def place(c: Data, q: vec, time: S):  # pyright: ignore[reportRedeclaration]
            shift, u = motion(c, time)
            phi, n = sdf(c, q - shift)
            return phi, n, u

        return place

    turn, spin = make_turn(t)
    rigid = RIGID in kinds  # a rigid body's pose (origin, frame) on top of the window's motion

    @wp.func
    def place(c: Data, q: vec, time: S):
        shift, u = motion(c, time)
        elapsed = wp.min(wp.max(time, c.window[0]), c.window[1]) - c.window[0]
        w = V3()
        if time >= c.window[0] and time < c.window[1]:
            w = c.omega
        angle = elapsed * c.omega
        pivot = c.pivot + shift
        if wp.static(rigid):
            pivot = c.pivot + c.origin + shift
        local = turn(q - pivot, -angle)
        if wp.static(rigid):
            local = turn(local, -c.frame)
        phi, n = sdf(c, c.pivot + local)
        if wp.static(rigid):
            n = turn(n, c.frame)
        n = turn(n, angle)
        return phi, n, u + spin(w, q - phi * n - pivot)

    return place


@functools.cache
def make_box_face(t: Types):
    """For a rigid body's box (a record of a scene with rigid bodies, whose
    kernels compile the rotation): ``rest(c, q, time) -> d``, where the point
    ``q`` lies in the box at rest at ``time``, from its centre [m] (module
    docstring: d = q_rest - c.p); ``face(c, q, time, d, j) -> (phi, n, u)``:
    the signed distance [m] of ``q`` from the plane of the box's face across
    axis ``j`` on d's side, that face's outward normal where the box is, and
    the velocity of the box at the point q - phi n of that plane."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    V3 = wp.types.vector(3, S)
    turn, spin = make_turn(t)
    motion = make_motion(t)

    @wp.func
    def rest(c: Data, q: vec, time: S):
        shift, u = motion(c, time)
        angle = (wp.min(wp.max(time, c.window[0]), c.window[1]) - c.window[0]) * c.omega
        return c.pivot + turn(turn(q - (c.pivot + c.origin + shift), -angle), -c.frame) - c.p

    @wp.func
    def face(c: Data, q: vec, time: S, d: vec, j: int):
        shift, u = motion(c, time)
        w = V3()
        if time >= c.window[0] and time < c.window[1]:
            w = c.omega
        angle = (wp.min(wp.max(time, c.window[0]), c.window[1]) - c.window[0]) * c.omega
        n_rest = vec()
        n_rest[j] = S(1.0)
        if d[j] < S(0.0):
            n_rest[j] = S(-1.0)
        phi = wp.abs(d[j]) - c.h[j]
        n = turn(turn(n_rest, c.frame), angle)
        return phi, n, u + spin(w, q - phi * n - (c.pivot + c.origin + shift))

    return rest, face


@functools.cache
def make_centre(t: Types):
    """``centre(c, time)``: where collider ``c``'s pivot is at ``time`` [m]
    (a rigid body's: its centre of mass)."""
    S, Data = t.scalar, make_collider_data(t)
    motion = make_motion(t)

    @wp.func
    def centre(c: Data, time: S):
        shift, u = motion(c, time)
        return c.pivot + c.origin + shift

    return centre


FAR = 1.01
"""a rigid body's bound, in its reach (mpm.rigid.RigidBody.reach), with a margin for rounding"""


@functools.cache
def make_beyond(t: Types):
    """``beyond(c, q, time, margin) -> bool``: whether the point ``q`` lies
    farther than :data:`FAR` times rigid body ``c``'s reach (``c.reach``,
    mpm.rigid_coupling) plus ``margin`` [m] from its centre of mass at
    ``time``: its signed distance from the body's closed surface, all
    within the reach of that centre, then exceeds ``margin``, and a kernel
    that acts only closer (the keep-out: phi < 0; the grid rule: phi below
    half a cell) need not place it (the four rotations of a turning body's
    :func:`make_place` skipped, no result changed)."""
    S, Data = t.scalar, make_collider_data(t)
    centre = make_centre(t)
    far = S(FAR)

    @wp.func
    def beyond(c: Data, q: t.vec, time: S, margin: S):
        r = q - centre(c, time)
        bound = far * c.reach + margin
        return wp.dot(r, r) > bound * bound

    return beyond
