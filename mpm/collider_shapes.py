"""The colliders on the device: the packed per-collider records
(:func:`pack`) and the signed distance and outward normal of each shape
(mpm.colliders lists them), compiled only for the shapes a scene has
(:func:`make_sdf`). The rules that act on the grid are mpm.collider_device's."""

import functools

import warp as wp

from .colliders import KINDS, Collider
from .types import Types


@functools.cache
def make_collider_data(t: Types):
    """The per-collider record the boundary kernels read."""

    @wp.struct
    class ColliderData:
        kind: int  # KINDS
        boundary: int  # BOUNDARIES
        friction: t.scalar
        stiffness: t.scalar  # an elastic collider's spring factor (mpm.elastic_contact)
        damping: t.scalar  # an elastic collider's dashpot, a fraction of the critical (mpm.elastic_contact)
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
        omega: wp.types.vector(3, t.scalar)  # angular velocity while moving [rad/s] (2D: about z)
        pivot: t.vec  # the point it turns about, at rest [m]
        mesh: wp.uint64  # wp.Mesh id (mesh colliders)
        origin: t.vec  # rigid bodies: the pivot's displacement from rest at the window's start [m] (else 0)
        frame: wp.types.vector(3, t.scalar)  # rigid bodies: the rotation vector from rest then [rad] (else 0)
        body: int  # 1: a rigid body's shape (mpm.rigid; a box's edges: mpm.collider_device.make_edge)
        reach: t.scalar  # rigid bodies: the surface's reach from the pivot [m] (collider_motion.make_beyond; else 0)

    return ColliderData


def pack(colliders: list[Collider], t: Types, meshes: dict, device, bodies: int = 0) -> wp.array:
    """Device array of :func:`make_collider_data` records (one placeholder
    record when there is no collider; the kernels then compile them out).
    ``meshes`` maps a collider index to its wp.Mesh (kept alive by the caller);
    the last ``bodies`` colliders are rigid bodies' shapes (mpm.rigid.solids)."""
    Data = make_collider_data(t)
    out = []
    for i, c in enumerate(colliders or [Collider("half_space", point=(0.0,) * t.dim,
                                                 normal=(1.0,) + (0.0,) * (t.dim - 1))]):
        rec = c.record(t.dim)
        d = Data()
        d.kind, d.boundary, d.invert = rec["kind"], rec["boundary"], rec["invert"]
        d.friction, d.r, d.a, d.w = (t.scalar(float(rec[k])) for k in ("friction", "r", "a", "w"))
        d.stiffness = t.scalar(float(rec["stiffness"]))
        d.damping = t.scalar(float(rec["damping"]))
        for k in ("p", "n0", "n1", "h", "u", "pivot"):
            setattr(d, k, t.vec(*rec[k]))
        d.window = wp.types.vector(2, t.scalar)(*rec["window"])
        d.omega = wp.types.vector(3, t.scalar)(*rec["omega"])
        d.mesh = wp.uint64(meshes[i].id if i in meshes else 0)
        d.body = int(bodies > 0 and i >= len(colliders) - bodies)
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
        hit = wp.mesh_query_point_sign_winding_number(c.mesh, qf, wp.float32(1.0e6))  # pyright: ignore[reportArgumentType]
        phi = S(1.0e30)
        n = c.n0
        if hit.result:  # pyright: ignore[reportAttributeAccessIssue]
            cp = wp.mesh_eval_position(c.mesh, hit.face, hit.u, hit.v)  # pyright: ignore[reportAttributeAccessIssue]
            dv = vec(S(qf[0] - cp[0]), S(qf[1] - cp[1]), S(qf[2] - cp[2]))  # pyright: ignore[reportIndexIssue]
            L = wp.length(dv)
            phi = S(hit.sign) * L  # pyright: ignore[reportAttributeAccessIssue]
            nf = wp.mesh_eval_face_normal(c.mesh, hit.face)  # pyright: ignore[reportAttributeAccessIssue]
            n = unit(S(hit.sign) * dv, vec(S(nf[0]), S(nf[1]), S(nf[2])))  # pyright: ignore[reportAttributeAccessIssue, reportIndexIssue]
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
        def shape(c: Data, d: vec, q: vec):  # pyright: ignore[reportRedeclaration]
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
