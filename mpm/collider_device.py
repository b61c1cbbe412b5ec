"""Rigid colliders on the device (their description and rules:
mpm.colliders): the packed per-collider records, the signed distances of the
shapes a scene has, the grid rule, the implicit solve's constraints and the
count of particles gone through a collider. The kernels compile only the
shapes present (:func:`kinds_of`)."""

import functools

import numpy as np
import warp as wp

from .colliders import BOUNDARIES, KINDS, Collider
from .launch import warp_kernel
from .types import Types

STICKY, SLIP, SEPARATE = range(len(BOUNDARIES))


@functools.cache
def make_collider_data(t: Types):
    """The per-collider record the boundary kernels read."""

    @wp.struct
    class ColliderData:
        kind: int  # KINDS
        boundary: int  # BOUNDARIES
        friction: t.scalar
        invert: int  # 1: a container (the solid is outside the shape)
        p: t.vec  # point, centre
        n0: t.vec  # normal or axis (unit)
        n1: t.vec  # the wedge's second normal
        h: t.vec  # box half sizes
        r: t.scalar  # radius
        a: t.scalar  # cylinder half height, cup depth, bowl rim height
        w: t.scalar  # wall thickness
        u: t.vec  # velocity while moving [m/s]
        window: wp.types.vector(2, t.scalar)  # (start, end) of the motion [s]
        mesh: wp.uint64  # wp.Mesh id (mesh colliders)

    return ColliderData


def pack(colliders: list[Collider], t: Types, meshes: dict, device) -> wp.array:
    """Device array of :func:`make_collider_data` records (one placeholder
    record when there is no collider; the kernels then compile them out).
    ``meshes`` maps a collider index to its wp.Mesh (kept alive by the caller)."""
    Data = make_collider_data(t)
    out = []
    for i, c in enumerate(colliders or [Collider("half_space", point=(0.0,) * t.dim,
                                                 normal=(1.0,) + (0.0,) * (t.dim - 1))]):
        rec = c.record(t.dim)
        d = Data()
        d.kind, d.boundary, d.invert = rec["kind"], rec["boundary"], rec["invert"]
        d.friction, d.r, d.a, d.w = (t.scalar(float(rec[k])) for k in ("friction", "r", "a", "w"))
        for k in ("p", "n0", "n1", "h", "u"):
            setattr(d, k, t.vec(*rec[k]))
        d.window = wp.types.vector(2, t.scalar)(*rec["window"])
        d.mesh = wp.uint64(meshes[i].id if i in meshes else 0)
        out.append(d)
    return wp.array(out, dtype=Data, device=device)


@functools.cache
def make_axial(t: Types):
    """``unit(v, fallback)``: v / |v| (``fallback`` for a null v);
    ``along_radial(d, axis) -> (s, radial)``; ``capped(s, rho, er, axis,
    half, radius) -> (phi, n)``: the signed distance and normal of a capped
    cylinder in (rho, s) space."""
    S, vec = t.scalar, t.vec
    tiny = S(1.0e-12)

    @wp.func
    def unit(v: vec, fallback: vec):
        n = wp.length(v)
        if n > tiny:
            return v / n
        return fallback

    @wp.func
    def along_radial(d: vec, axis: vec):
        """(coordinate along the axis, radial vector)."""
        s = wp.dot(d, axis)
        return s, d - s * axis

    @wp.func
    def capped(s: S, rho: S, er: vec, axis: vec, half: S, radius: S):
        """Signed distance and normal of a capped cylinder in (rho, s) space."""
        dr = rho - radius
        ds = wp.abs(s) - half
        sign_s = S(1.0)
        if s < S(0.0):
            sign_s = S(-1.0)
        if dr > S(0.0) and ds > S(0.0):
            L = wp.sqrt(dr * dr + ds * ds)
            return L, (dr * er + ds * sign_s * axis) / L
        if dr > ds:
            return dr, er
        return ds, sign_s * axis

    return unit, along_radial, capped


@functools.cache
def make_solids(t: Types):
    """The half space, the wedge, the box, the sphere and the cylinder as
    ``shape(c, d, q) -> (phi, n)``: the signed distance [m] and the outward
    normal of collider ``c`` at ``q``, ``d = q - c.p``, before any inversion."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    unit, along_radial, capped = make_axial(t)

    @wp.func
    def half_space(c: Data, d: vec, q: vec):
        return wp.dot(d, c.n0), c.n0

    @wp.func
    def wedge(c: Data, d: vec, q: vec):
        p0 = wp.dot(d, c.n0)
        p1 = wp.dot(d, c.n1)
        phi = p0
        n = c.n0
        if p1 > p0:
            phi = p1
            n = c.n1
        return phi, n

    @wp.func
    def box(c: Data, d: vec, q: vec):
        e = vec()
        out = vec()
        big = S(-1.0e30)
        k_max = int(0)
        for k in range(wp.static(t.dim)):
            e[k] = wp.abs(d[k]) - c.h[k]
            sg = S(1.0)
            if d[k] < S(0.0):
                sg = S(-1.0)
            if e[k] > S(0.0):
                out[k] = sg * e[k]
            if e[k] > big:
                big = e[k]
                k_max = k
        phi = big
        n = vec()
        if big > S(0.0):
            phi = wp.length(out)
            n = out / phi
        else:
            n[k_max] = S(1.0)
            if d[k_max] < S(0.0):
                n[k_max] = S(-1.0)
        return phi, n

    @wp.func
    def sphere(c: Data, d: vec, q: vec):
        rho = wp.length(d)
        return rho - c.r, unit(d, c.n0)

    @wp.func
    def cylinder(c: Data, d: vec, q: vec):
        s, rad = along_radial(d, c.n0)
        phi, n = capped(s, wp.length(rad), unit(rad, c.n1), c.n0, c.a, c.r)
        return phi, n

    return {"half_space": half_space, "wedge": wedge, "box": box, "sphere": sphere, "cylinder": cylinder}


@functools.cache
def make_vessels(t: Types):
    """The cup, the bowl and (3D) the mesh as ``shape(c, d, q) -> (phi, n)``
    (:func:`make_solids`)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    unit, along_radial, capped = make_axial(t)

    @wp.func
    def cup(c: Data, d: vec, q: vec):
        """The outer capped cylinder from s = -w to s = depth, minus the cavity s >= 0, rho < r."""
        s, rad = along_radial(d, c.n0)
        rho = wp.length(rad)
        er = unit(rad, c.n1)
        half = S(0.5) * (c.a + c.w)
        phi, n = capped(s - (half - c.w), rho, er, c.n0, half, c.r + c.w)
        cav = rho - c.r  # cavity's distance (open upwards)
        ncav = er
        if -s > cav:
            cav = -s
            ncav = -c.n0
        if -cav > phi:
            phi = -cav
            n = -ncav
        return phi, n

    @wp.func
    def bowl(c: Data, d: vec, q: vec):
        rho = wp.length(d)
        er = unit(d, -c.n0)
        phi = rho - (c.r + c.w)
        n = er
        if c.r - rho > phi:
            phi = c.r - rho
            n = -er
        s = wp.dot(d, c.n0) - c.a
        if s > phi:
            phi = s
            n = c.n0
        return phi, n

    if t.dim != 3:
        return {"cup": cup, "bowl": bowl}

    @wp.func
    def mesh(c: Data, d: vec, q: vec):
        qf = wp.vec3(wp.float32(q[0]), wp.float32(q[1]), wp.float32(q[2]))
        hit = wp.mesh_query_point_sign_winding_number(c.mesh, qf, wp.float32(1.0e6))
        phi = S(1.0e30)
        n = c.n0
        if hit.result:
            cp = wp.mesh_eval_position(c.mesh, hit.face, hit.u, hit.v)
            dv = vec(S(qf[0] - cp[0]), S(qf[1] - cp[1]), S(qf[2] - cp[2]))
            L = wp.length(dv)
            phi = S(hit.sign) * L
            nf = wp.mesh_eval_face_normal(c.mesh, hit.face)
            n = unit(S(hit.sign) * dv, vec(S(nf[0]), S(nf[1]), S(nf[2])))
        return phi, n

    return {"cup": cup, "bowl": bowl, "mesh": mesh}


@functools.cache
def make_shape(t: Types, kinds: tuple[str, ...]):
    """``shape(c, d, q) -> (phi, n)`` of collider ``c`` whatever its kind
    among ``kinds`` (:func:`make_solids`); another kind (a mesh in 2D): 0
    and ``c.n0``. One function per kind, each testing its own and passing
    the others on, so that only the kinds given are compiled."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    shapes = make_solids(t) | make_vessels(t)
    kinds = tuple(k for k in kinds if k in shapes)
    if not kinds:
        @wp.func
        def shape(c: Data, d: vec, q: vec):
            return S(0.0), c.n0

        return shape
    kind, own, others = KINDS.index(kinds[0]), shapes[kinds[0]], make_shape(t, kinds[1:])

    @wp.func
    def shape(c: Data, d: vec, q: vec):
        if c.kind == kind:
            phi, n = own(c, d, q)
            return phi, n
        phi, n = others(c, d, q)
        return phi, n

    return shape


@functools.cache
def make_sdf(t: Types, kinds: tuple[str, ...]):
    """``sdf(c, q) -> (phi, n)``: signed distance [m] of the point ``q`` (in
    the collider's own frame, i.e. already moved back by its displacement)
    and the outward normal; only the shapes in ``kinds`` are compiled."""
    vec, Data = t.vec, make_collider_data(t)
    shape = make_shape(t, kinds)

    @wp.func
    def sdf(c: Data, q: vec):
        phi, n = shape(c, q - c.p, q)
        if c.invert != 0:
            return -phi, -n
        return phi, n

    return sdf


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
def make_collide(t: Types, kinds: tuple[str, ...]):
    """``collide(v, q, time, colliders) -> v``: every collider's boundary
    condition on a node at ``q`` with velocity ``v`` (see the module docstring)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    sdf = make_sdf(t, kinds)
    motion = make_motion(t)

    @wp.func
    def collide(v: vec, q: vec, time: S, colliders: wp.array(dtype=Data)):
        for k in range(colliders.shape[0]):
            c = colliders[k]
            shift, u = motion(c, time)
            phi, n = sdf(c, q - shift)
            if phi < S(0.0):
                vr = v - u
                vn = wp.dot(vr, n)
                if c.boundary == STICKY:
                    v = u
                elif c.boundary == SLIP or vn < S(0.0):
                    vt = vr - vn * n
                    lt = wp.length(vt)
                    if c.friction > S(0.0) and lt > S(0.0):
                        vt = vt * wp.max(S(0.0), S(1.0) - c.friction * wp.abs(vn) / lt)
                    v = u + vt
        return v

    return collide


@functools.cache
def make_remove_direction(t: Types):
    """``remove_direction(Pi, n) -> Pi``: the orthogonal projector ``Pi``
    onto a subspace, with the direction ``n`` taken out of that subspace."""
    S = t.scalar

    @wp.func
    def remove_direction(Pi: t.mat, n: t.vec):
        w = Pi * n
        ww = wp.dot(w, w)
        if ww > S(1.0e-12) * wp.dot(n, n):
            return Pi - wp.outer(w, w) / ww
        return Pi

    return remove_direction


@functools.cache
def make_constrain(t: Types, kinds: tuple[str, ...]):
    """``constrain(v, Pi, q, time, colliders) -> (v, Pi, mu, u, n)``: the
    colliders as constraints of an implicit solve, at the predicted velocity
    ``v``: a node inside a sticky collider is fixed (v = u, Pi = 0); inside a
    slip collider, or a separating one it approaches, its normal velocity is
    fixed (v_n = u_n, n removed from the free subspace ``Pi``). Friction is
    not a constraint: the last frictional contact's coefficient ``mu``,
    velocity ``u`` and normal ``n`` are returned for the friction applied
    after the solve with the solve's normal reaction (mpm.implicit)."""
    S, vec, mat, Data = t.scalar, t.vec, t.mat, make_collider_data(t)
    sdf = make_sdf(t, kinds)
    motion = make_motion(t)
    remove_direction = make_remove_direction(t)

    @wp.func
    def constrain(v: t.vec, Pi: t.mat, q: t.vec, time: S, colliders: wp.array(dtype=Data)):
        mu = S(0.0)
        uf = vec()
        nf = vec()
        for k in range(colliders.shape[0]):
            c = colliders[k]
            shift, u = motion(c, time)
            phi, n = sdf(c, q - shift)
            if phi < S(0.0):
                vn = wp.dot(v - u, n)
                if c.boundary == STICKY:
                    v = u
                    Pi = mat()
                elif c.boundary == SLIP or vn < S(0.0):
                    v = v - vn * n
                    Pi = remove_direction(Pi, n)
                    if c.friction > S(0.0):
                        mu = c.friction
                        uf = u
                        nf = n
        return v, Pi, mu, uf, nf

    return constrain


@functools.cache
def make_inside_count(t: Types, kinds: tuple[str, ...]):
    """Kernel: per collider, the particles deeper inside it than ``depth`` [m]."""
    S, Data = t.scalar, make_collider_data(t)
    sdf = make_sdf(t, kinds)

    @warp_kernel
    def inside_count(x: wp.array(dtype=t.vec), time: S, depth: S, colliders: wp.array(dtype=Data),
                     count: wp.array(dtype=wp.int32)):
        p = wp.tid()
        for k in range(colliders.shape[0]):
            c = colliders[k]
            tc = wp.min(wp.max(time, c.window[0]), c.window[1])
            phi, n = sdf(c, x[p] - (tc - c.window[0]) * c.u)
            if phi < -depth:
                wp.atomic_add(count, k, 1)

    return inside_count


def kinds_of(colliders: list[Collider]) -> tuple[str, ...]:
    """The shapes present, in KINDS order (the kernels' specialisation key)."""
    return tuple(k for k in KINDS if any(c.type == k for c in colliders))


def build_meshes(colliders: list[Collider], device) -> dict:
    """wp.Mesh (float32 points, with winding numbers) per mesh collider index."""
    out = {}
    for i, c in enumerate(colliders):
        if c.type == "mesh":
            pts, tris = c.mesh.geometry
            out[i] = wp.Mesh(points=wp.array(pts.astype(np.float32), dtype=wp.vec3, device=device),
                             indices=wp.array(tris.reshape(-1).astype(np.int32), dtype=wp.int32,
                                              device=device),
                             support_winding_number=True)
    return out
