"""Rigid colliders: static or moving solids other than the domain's walls.

A collider is a solid described by a signed distance phi(q) (negative inside
the solid) and its outward normal n(q) = grad phi. It acts on the grid, on
every node whose current position q_i lies inside it (phi(q_i) < 0), after
the walls and before the kinematic regions (mpm.grid), so it works for every
scheme and kernel. With the collider's velocity u and the node's relative
velocity v_r = v_i - u, v_n = v_r . n:

* ``sticky``:   v_i = u;
* ``slip``:     the normal part of v_r is removed (no separation either);
* ``separate``: as slip, but only when v_n < 0 (the node moves into the
  solid); a node moving away is left free;

and slip and separate apply Coulomb friction to the tangential part
v_t = v_r - v_n n: |v_t| shrinks by mu |v_n| and stops at zero,
    v_i = u + max(0, 1 - mu |v_n| / |v_t|) v_t.

A collider may move with a constant ``velocity`` [m/s] while
``start <= t < end`` [s]; its shape is then displaced by
u (clamp(t, start, end) - start). Shapes (every one 2D and 3D except the mesh):

  half_space  the solid behind a plane through ``point`` with outward ``normal``
  wedge       the intersection of two half-spaces through ``point`` (a ridge)
  box         axis-aligned box ``center``, ``half_size``
  sphere      ball ``center``, ``radius`` (``inside: true``: a spherical container)
  cylinder    capped cylinder ``center``, ``radius``, ``half_height`` along ``axis``
  cup         open cylindrical cup: inner bottom centre ``center``, inner
              ``radius`` and ``depth``, wall ``thickness``, opening along ``axis``
  bowl        spherical cap shell: sphere ``center``, inner ``radius``,
              ``thickness``, cut by the rim plane ``rim`` [m] above the centre
              along ``axis`` (the opening)
  mesh        a closed triangle mesh (3D), placed as mpm.meshes.MeshShape

``inside: true`` turns any shape into a container (the solid is everything
outside it). The kernels compile only the shapes a scene has
(:func:`make_collide`, :func:`kinds_of`).
"""

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import warp as wp

from .launch import warp_kernel
from .types import Types

KINDS = ("half_space", "wedge", "box", "sphere", "cylinder", "cup", "bowl", "mesh")
BOUNDARIES = ("sticky", "slip", "separate")
HALF_SPACE, WEDGE, BOX, SPHERE, CYLINDER, CUP, BOWL, MESH = range(len(KINDS))
STICKY, SLIP, SEPARATE = range(len(BOUNDARIES))
INSIDE_DEPTH = 1.0
"""a particle counts as inside a collider when deeper than this many cells:
the nodes inside a collider stop particles within about a cell of its
surface (a fast splash particle in a container reaches 0.3-0.85 cells deep,
tests/mpm/test_colliders.py), so deeper ones have gone through it"""


def _unit(v) -> tuple[float, ...]:
    v = np.asarray(v, float)
    return tuple(v / np.linalg.norm(v))


def axis_vector(axis, dim: int) -> tuple[float, ...]:
    """A coordinate axis (0, 1, 2) or a direction vector, as a unit vector."""
    if isinstance(axis, (int, np.integer)):
        e = np.zeros(dim)
        e[int(axis)] = 1.0
        return tuple(e)
    return _unit(axis)


@dataclass(frozen=True)
class Collider:
    """One rigid collider (see the module docstring for the shapes). Lengths
    in metres; ``normal``, ``normals`` and ``axis`` need not be unit length
    (``axis`` may also be a coordinate index)."""

    kind: str
    boundary: str = "slip"
    friction: float = 0.0  # Coulomb coefficient mu
    name: str = ""
    inside: bool = False  # the solid is the outside of the shape (a container)
    point: Sequence[float] | None = None  # half_space, wedge
    normal: Sequence[float] | None = None  # half_space: outward
    normals: Sequence[Sequence[float]] | None = None  # wedge: two outward normals
    center: Sequence[float] | None = None
    half_size: Sequence[float] | None = None  # box
    radius: float = 0.0
    half_height: float = 0.0  # cylinder
    depth: float = 0.0  # cup
    thickness: float = 0.0  # cup, bowl
    rim: float = 0.0  # bowl: rim plane's height above the centre along the axis
    axis: int | Sequence[float] = 1
    mesh: object | None = None  # mpm.meshes.MeshShape
    velocity: Sequence[float] | None = None  # [m/s]
    start: float = 0.0  # [s]
    end: float = float("inf")  # [s]

    def speed(self) -> float:
        return float(np.linalg.norm(self.velocity)) if self.velocity is not None else 0.0

    def offset(self, t: float) -> np.ndarray:
        """Displacement of the shape at time ``t`` [s]."""
        if self.velocity is None:
            return 0.0
        return np.asarray(self.velocity, float) * (min(max(t, self.start), self.end) - self.start)

    def record(self, dim: int) -> dict:
        """The packed fields of :func:`make_collider_data` (numbers only)."""
        z = (0.0,) * dim
        r = dict(kind=KINDS.index(self.kind), boundary=BOUNDARIES.index(self.boundary),
                 friction=self.friction, invert=int(self.inside), p=z, n0=z, n1=z, h=z,
                 r=self.radius, a=0.0, w=self.thickness, u=tuple(self.velocity or z),
                 window=(self.start, min(self.end, 1e30)))
        if self.kind in ("half_space", "wedge"):
            r["p"] = tuple(self.point)
            if self.kind == "half_space":
                r["n0"] = _unit(self.normal)
            else:
                r["n0"], r["n1"] = _unit(self.normals[0]), _unit(self.normals[1])
        else:
            r["p"] = tuple(self.center) if self.center is not None else z
        if self.kind == "box":
            r["h"] = tuple(self.half_size)
        if self.kind in ("cylinder", "cup", "bowl"):
            r["n0"] = axis_vector(self.axis, dim)
            r["a"] = {"cylinder": self.half_height, "cup": self.depth, "bowl": self.rim}[self.kind]
        return r


# ------------------------------------------------------------------ device
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
def make_sdf(t: Types, kinds: tuple[str, ...]):
    """``sdf(c, q) -> (phi, n)``: signed distance [m] of the point ``q`` (in
    the collider's own frame, i.e. already moved back by its displacement)
    and the outward normal; only the shapes in ``kinds`` are compiled."""
    S = t.scalar
    vec = t.vec
    Data = make_collider_data(t)
    has = set(kinds)
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

    @wp.func
    def sdf(c: Data, q: vec):
        d = q - c.p
        phi = S(0.0)
        n = c.n0
        if wp.static("half_space" in has):
            if c.kind == HALF_SPACE:
                phi = wp.dot(d, c.n0)
        if wp.static("wedge" in has):
            if c.kind == WEDGE:
                p0 = wp.dot(d, c.n0)
                p1 = wp.dot(d, c.n1)
                phi = p0
                if p1 > p0:
                    phi = p1
                    n = c.n1
        if wp.static("box" in has):
            if c.kind == BOX:
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
                if big > S(0.0):
                    phi = wp.length(out)
                    n = out / phi
                else:
                    phi = big
                    n = vec()
                    n[k_max] = S(1.0)
                    if d[k_max] < S(0.0):
                        n[k_max] = S(-1.0)
        if wp.static("sphere" in has):
            if c.kind == SPHERE:
                rho = wp.length(d)
                phi = rho - c.r
                n = unit(d, c.n0)
        if wp.static("cylinder" in has):
            if c.kind == CYLINDER:
                s, rad = along_radial(d, c.n0)
                phi, n = capped(s, wp.length(rad), unit(rad, c.n1), c.n0, c.a, c.r)
        if wp.static("cup" in has):
            if c.kind == CUP:
                # outer capped cylinder from s = -w to s = depth, minus the cavity s >= 0, rho < r
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
        if wp.static("bowl" in has):
            if c.kind == BOWL:
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
        if wp.static("mesh" in has and t.dim == 3):
            if c.kind == MESH:
                qf = wp.vec3(wp.float32(q[0]), wp.float32(q[1]), wp.float32(q[2]))
                hit = wp.mesh_query_point_sign_winding_number(c.mesh, qf, wp.float32(1.0e6))
                if hit.result:
                    cp = wp.mesh_eval_position(c.mesh, hit.face, hit.u, hit.v)
                    dv = vec(S(qf[0] - cp[0]), S(qf[1] - cp[1]), S(qf[2] - cp[2]))
                    L = wp.length(dv)
                    phi = S(hit.sign) * L
                    nf = wp.mesh_eval_face_normal(c.mesh, hit.face)
                    n = unit(S(hit.sign) * dv, vec(S(nf[0]), S(nf[1]), S(nf[2])))
                else:
                    phi = S(1.0e30)
        if c.invert != 0:
            return -phi, -n
        return phi, n

    return sdf


@functools.cache
def make_motion(t: Types):
    """``motion(c, time) -> (displacement, velocity)`` of collider ``c``."""
    S = t.scalar
    vec = t.vec
    Data = make_collider_data(t)

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
    S = t.scalar
    vec = t.vec
    Data = make_collider_data(t)
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
    S = t.scalar
    vec, mat = t.vec, t.mat
    Data = make_collider_data(t)
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
    S = t.scalar
    Data = make_collider_data(t)
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
    return tuple(k for k in KINDS if any(c.kind == k for c in colliders))


def build_meshes(colliders: list[Collider], device) -> dict:
    """wp.Mesh (float32 points, with winding numbers) per mesh collider index."""
    out = {}
    for i, c in enumerate(colliders):
        if c.kind == "mesh":
            pts, tris = c.mesh.geometry
            out[i] = wp.Mesh(points=wp.array(pts.astype(np.float32), dtype=wp.vec3, device=device),
                             indices=wp.array(tris.reshape(-1).astype(np.int32), dtype=wp.int32,
                                              device=device),
                             support_winding_number=True)
    return out
