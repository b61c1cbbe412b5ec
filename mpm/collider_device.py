"""Rigid colliders on the device (their description and rules:
mpm.colliders; their records and shapes: mpm.collider_shapes): the grid
rule, where a node is in contact with a collider (mpm.surface), the implicit
solve's constraints and the count of particles gone through a collider. The
kernels compile only the shapes present, and the rotation only where a
collider turns (:func:`kinds_of`; mpm.collider_motion)."""

import functools

import numpy as np
import warp as wp

from .collider_motion import make_beyond, make_box_face, make_centre, make_place
from .collider_shapes import make_collider_data
from .colliders import BOUNDARIES, ELASTIC, KINDS, RIGID, TURNING, Collider
from .launch import warp_kernel
from .rigid import solids
from .surface import APART, CONTACT, make_profile_type, make_surface
from .types import Types

STICKY, SLIP, SEPARATE, SPRINGS = range(len(BOUNDARIES))
OUTSIDE, BEHIND = 0.3, 0.1
"""make_edge: a node farther than OUTSIDE [cells] outside one face's plane
is acted on by no face whose plane it lies more than BEHIND [cells] behind
(RESULTS.md: 0.22-0.35 and 0.05-0.2 kept the incline's compact and cubic cases)."""
BOX = KINDS.index("box")


@functools.cache
def make_respond(t: Types):
    """``respond(v, u, n, c) -> v'``: the boundary rule of collider ``c``
    (velocity ``u``, outward normal ``n``) on the velocity ``v`` of a body in
    contact with it (mpm.colliders)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)

    @wp.func
    def respond(v: vec, u: vec, n: vec, c: Data):
        vr = v - u
        vn = wp.dot(vr, n)
        if c.boundary == STICKY:
            return u
        if c.boundary == SLIP or vn < S(0.0):
            vt = vr - vn * n
            lt = wp.length(vt)
            if c.friction > S(0.0) and lt > S(0.0):
                vt = vt * wp.max(S(0.0), S(1.0) - c.friction * wp.abs(vn) / lt)
            return u + vt
        return v

    return respond


@functools.cache
def make_reach(t: Types, rule: str, gradients: bool):
    """``reach(phi, n, V, G, v, profile) -> (in contact, v_s)``: whether a
    node at the signed distance ``phi`` [m] from a solid's surface (outward
    normal ``n``) is in contact with it, and the velocity the rule acts on:
    by mpm.surface's rule (``rule`` "surface": the node's body volume
    fraction ``V``; with ``gradients``, the velocity ``v`` extrapolated to the
    surface by the node's velocity gradient ``G``) or inside the solid
    (``rule`` "nodes": phi < 0, the node's own velocity)."""
    S = t.scalar
    Profile = make_profile_type(t)
    solid_share, touching, surface_velocity = make_surface(t)

    @wp.func
    def reach(phi: S, n: t.vec, V: S, G: t.mat, v: t.vec, profile: Profile):
        if wp.static(rule == "nodes"):
            state = APART
            if phi < S(0.0):
                state = CONTACT
            return state, v
        state = touching(phi, V, solid_share(phi, profile), profile)
        vs = v
        if wp.static(gradients):
            if state == CONTACT:
                vs = surface_velocity(v, G, phi, n)
        return state, vs

    return reach


@functools.cache
def make_edge(t: Types, rule: str, gradients: bool):
    """``edge(dv, v, q, V, G, time, c, profile) -> dv``: the change a rigid
    body's box ``c`` makes to the velocity ``v`` of a node at ``q`` in
    contact with it (``dv``: by its nearest face, :func:`make_collide`),
    where the node is near an edge: of the faces whose plane lies within
    half a cell of the node (and the node within half a cell of the face's
    extent along the other axes), each judged by mpm.surface's rule as the
    plane it lies in, the one whose rule changes the velocity least. The
    material at a box's edge may go round it: the nearest face alone, at a
    box resting on a slab with its bottom on a row of nodes, took the slab's
    top node at the box's front corner as touching the front face and swept
    it along, and the box stayed caught. A node more than OUTSIDE cells
    outside one face's plane passes over the faces whose planes it lies
    more than BEHIND cells behind: it lies in the first face's region (the
    compact kernel's nodes sit a quarter cell off a box resting on a row;
    one 0.4 cells under a dropped block's bottom and 0.25 inside its side
    took the side face, from which it moved away, lost the bottom's
    support, and the block tipped over; RESULTS.md)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    Profile = make_profile_type(t)
    solid_share, touching, surface_velocity = make_surface(t)
    rest, face = make_box_face(t)
    respond = make_respond(t)

    @wp.func
    def edge(dv: vec, v: vec, q: vec, V: S, G: t.mat, time: S, c: Data, profile: Profile):
        if wp.static(rule == "nodes"):
            return dv
        half = S(0.5) / profile.inv_dx
        clear, behind = S(OUTSIDE) / profile.inv_dx, S(BEHIND) / profile.inv_dx
        d = rest(c, q, time)
        best = wp.dot(dv, dv)
        outside = False  # the node clearly outside a face's plane
        for j in range(wp.static(t.dim)):
            if wp.abs(d[j]) - c.h[j] > clear:
                outside = True
        for j in range(wp.static(t.dim)):
            near = wp.abs(wp.abs(d[j]) - c.h[j]) < half
            for i in range(wp.static(t.dim)):
                if i != j and wp.abs(d[i]) - c.h[i] >= half:
                    near = False
            if outside and wp.abs(d[j]) - c.h[j] < -behind:
                near = False  # clearly behind this face's plane, clearly outside another's
            if near:
                phi, n, u = face(c, q, time, d, j)
                if touching(phi, V, solid_share(phi, profile), profile) == CONTACT:
                    vs = v
                    if wp.static(gradients):
                        vs = surface_velocity(v, G, phi, n)
                    dj = respond(vs, u, n, c) - vs
                    if wp.dot(dj, dj) < best:
                        best = wp.dot(dj, dj)
                        dv = dj
        return dv

    return edge


@functools.cache
def make_add_impulse(t: Types):
    """``add_impulse(impulse, k, J)``: collider k's impulse J [N s] into its
    row of ``impulse`` (StepStatus.collider_impulse, per collider and axis)."""
    S = t.scalar

    @wp.func
    def add_impulse(impulse: wp.array(dtype=wp.float64), k: int, J: t.vec):
        for d in range(wp.static(t.dim)):
            if J[d] != S(0.0):
                wp.atomic_add(impulse, k * wp.static(t.dim) + d, wp.float64(J[d]))

    return add_impulse


@functools.cache
def make_add_torque(t: Types):
    """``add_torque(torque, k, r, J)``: the angular impulse r x J [N m s] of
    the impulse J applied at r from collider k's centre into its three
    entries of ``torque`` (2D: about z, the third)."""
    S = t.scalar

    @wp.func
    def add_torque(torque: wp.array(dtype=wp.float64), k: int, r: t.vec, J: t.vec):
        if wp.static(t.dim == 2):
            tz = r[0] * J[1] - r[1] * J[0]
            if tz != S(0.0):
                wp.atomic_add(torque, 3 * k + 2, wp.float64(tz))
        else:
            L = wp.cross(r, J)
            for a in range(3):
                if L[a] != S(0.0):  # pyright: ignore[reportIndexIssue]
                    wp.atomic_add(torque, 3 * k + a, wp.float64(L[a]))  # pyright: ignore[reportIndexIssue]

    return add_torque


@functools.cache
def make_add_reaction(t: Types, rigid: bool):
    """``add_reaction(impulse, torque, colliders, k, q, time, J)``: the
    impulse J [N s] a constraint of the implicit solve gave a node at ``q``
    [m] against collider k into its row of ``impulse``
    (:func:`make_add_impulse`) and, with ``rigid`` (the scene has rigid
    bodies), its angular impulse about the collider's centre at ``time``,
    (q - centre) x J, into ``torque`` (:func:`make_add_torque`)."""
    Data = make_collider_data(t)
    add_impulse, add_torque, centre = make_add_impulse(t), make_add_torque(t), make_centre(t)

    @wp.func
    def add_reaction(impulse: wp.array(dtype=wp.float64), torque: wp.array(dtype=wp.float64),
                     colliders: wp.array(dtype=Data), k: int, q: t.vec, time: t.scalar, J: t.vec):
        add_impulse(impulse, k, J)
        if wp.static(rigid):
            add_torque(torque, k, q - centre(colliders[k], time), J)

    return add_reaction


@functools.cache
def make_collide(t: Types, kinds: tuple[str, ...], rule: str = "surface", gradients: bool = False):
    """``collide(v, q, m, V, G, time, colliders, profile, impulse, torque) -> v``:
    every collider's boundary condition on a node at ``q`` with velocity
    ``v``, mass ``m``, body volume fraction ``V`` and velocity gradient ``G``
    (:func:`make_reach`, mpm.colliders): the change the rule makes to the
    velocity in contact is the node's, and its momentum goes to the
    collider's row of ``impulse``; where the scene has rigid bodies
    (:data:`RIGID` among ``kinds``), its angular impulse about the
    collider's centre, r x J with r from the centre to the node, to
    ``torque`` (:func:`make_add_torque`). A rigid body's box in contact
    at a node near one of its edges (within half a cell of two faces' planes)
    acts by the face, of those the node touches, whose rule changes its
    velocity least (:func:`make_edge`)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    place = make_place(t, kinds)
    respond = make_respond(t)
    reach = make_reach(t, rule, gradients)
    edge = make_edge(t, rule, gradients)
    add_impulse, add_torque, centre = make_add_impulse(t), make_add_torque(t), make_centre(t)
    beyond = make_beyond(t)
    Profile = make_profile_type(t)

    @wp.func
    def collide(v: vec, q: vec, m: S, V: S, G: t.mat, time: S, colliders: wp.array(dtype=Data), profile: Profile,
                impulse: wp.array(dtype=wp.float64), torque: wp.array(dtype=wp.float64)):
        for k in range(colliders.shape[0]):
            c = colliders[k]
            if wp.static(ELASTIC in kinds):
                if c.boundary == SPRINGS:
                    continue  # it acts on the particles (mpm.elastic_contact)
            if wp.static(RIGID in kinds):
                if c.body != 0:  # a rigid body: a node half a cell beyond its reach is apart (make_beyond)
                    if beyond(c, q, time, S(0.5) / profile.inv_dx):
                        continue
            phi, n, u = place(c, q, time)
            state, vs = reach(phi, n, V, G, v, profile)
            if state == CONTACT:
                dv = respond(vs, u, n, c) - vs
                if wp.static(RIGID in kinds and "box" in kinds):
                    if c.body != 0 and c.kind == BOX:
                        dv = edge(dv, v, q, V, G, time, c, profile)
                v = v + dv
                add_impulse(impulse, k, m * dv)
                if wp.static(RIGID in kinds):
                    add_torque(torque, k, q - centre(c, time), m * dv)
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
def make_constrain(t: Types, kinds: tuple[str, ...], rule: str = "surface", gradients: bool = False,
                   first: int = 0):
    """``constrain(v, Pi, q, V, G, time, colliders, profile) -> (v, Pi, mu, u,
    n, shift, k)``: the colliders as constraints of an implicit solve, at the
    predicted velocity ``v`` of a node in contact (:func:`make_reach`): with
    a sticky collider the node is fixed (v_s = u, Pi = 0); with a slip
    collider, or a separating one it approaches, its normal velocity is
    fixed (v_s . n = u . n, n removed from the free subspace ``Pi``).
    Friction is decided by the solve (mpm.implicit.rough): the last
    frictional contact's coefficient ``mu``, velocity ``u``, normal ``n``
    and the extrapolation to the surface ``shift`` = v_s - v are returned
    for it (a stuck node is fixed at v = u - shift), and ``k`` the
    last collider in contact (-1: none), whose row of the step's
    collider_impulse takes the node's reaction. Unlike the
    explicit rule, the nodes more than half a cell inside the solid where
    the body has any mass (mpm.surface's DEEP) are constraints too: left
    free, over an implicit step ten times the explicit one their fringe
    mass moved into the solid and the nodes in contact carried its pull (a
    block sliding down a 30 degree wedge at mu = 0.3 went 5 % slow; with
    them, within 0.02 %). With friction they act at the surface point as a
    node in contact does (v_s extrapolated by G): held on their own
    velocity, a stuck one held the body's rolling at a point up to a cell
    below the surface, and a disk rolling on a collider under the implicit
    integrator slipped 0.15 cells over 0.3 s where it now slips 0.09 (64
    cells, EMPM). Rigid bodies (``kinds`` naming RIGID; the colliders from
    index ``first`` on, mpm.rigid.solids) hold their nodes in contact only,
    as the explicit rule does: a body a few cells thick has DEEP nodes
    whose nearest face is its far or side one, and holding the other
    body's fringe mass there at the body's velocity dragged it (a rigid
    block sliding on an elastic slab at 32 cells stalled at 0.27 m/s, the
    closed form's acceleration missed by 110 %; the keep-out,
    mpm.keep_out, puts back the particles that enter)."""
    S, vec, mat, Data = t.scalar, t.vec, t.mat, make_collider_data(t)
    place = make_place(t, kinds)
    remove_direction = make_remove_direction(t)
    reach = make_reach(t, rule, gradients)
    surface_velocity = make_surface(t)[2]
    Profile = make_profile_type(t)

    @wp.func
    def constrain(v: t.vec, Pi: t.mat, q: t.vec, V: S, G: t.mat, time: S, colliders: wp.array(dtype=Data),
                  profile: Profile):
        mu = S(0.0)
        uf = vec()
        nf = vec()
        sf = vec()
        hit = int(-1)
        for k in range(colliders.shape[0]):
            c = colliders[k]
            phi, n, u = place(c, q, time)
            state, vs = reach(phi, n, V, G, v, profile)
            held = state != APART  # (DEEP too: see the docstring)
            if wp.static(RIGID in kinds):
                if k >= first:  # a rigid body: the nodes in contact only (docstring)
                    held = state == CONTACT
            if held:
                if state != CONTACT and c.friction > S(0.0) and c.boundary != STICKY:
                    vs = surface_velocity(v, G, phi, n)  # friction acts at the surface point (docstring)
                hit = k
                vn = wp.dot(vs - u, n)
                extrapolated = vs - v
                if c.boundary == STICKY:
                    v = v + (u - vs)
                    Pi = mat()
                elif c.boundary == SLIP or vn < S(0.0):
                    v = v - vn * n
                    Pi = remove_direction(Pi, n)
                    if c.friction > S(0.0):
                        mu = c.friction
                        uf = u
                        nf = n
                        sf = extrapolated
        return v, Pi, mu, uf, nf, sf, hit

    return constrain


@functools.cache
def make_inside_count(t: Types, kinds: tuple[str, ...]):
    """Kernel: per collider, the particles deeper inside it than ``depth`` [m]."""
    S, Data = t.scalar, make_collider_data(t)
    place = make_place(t, kinds)

    @warp_kernel
    def inside_count(x: wp.array(dtype=t.vec), time: S, depth: S, colliders: wp.array(dtype=Data),
                     count: wp.array(dtype=wp.int32)):
        p = wp.tid()
        for k in range(colliders.shape[0]):
            phi, n, u = place(colliders[k], x[p], time)
            if phi < -depth:
                wp.atomic_add(count, k, 1)

    return inside_count


def kinds_of(colliders: list[Collider], rigid: bool = False) -> tuple[str, ...]:
    """The shapes present, in KINDS order, TURNING where a collider turns,
    ELASTIC where one acts through springs (mpm.elastic_contact) and RIGID
    last where the scene has rigid bodies (``rigid``; their shapes among
    ``colliders``): the kernels' specialisation key."""
    return (tuple(k for k in KINDS if any(c.type == k for c in colliders))
            + ((TURNING,) if any(c.turns for c in colliders) or rigid else ())
            + ((ELASTIC,) if any(c.boundary == ELASTIC for c in colliders) else ()) + ((RIGID,) if rigid else ()))


def scene_kinds(scene) -> tuple[str, ...]:
    """:func:`kinds_of` the scene's colliders and rigid bodies (mpm.rigid.solids)."""
    return kinds_of(solids(scene), bool(getattr(scene, "rigid_bodies", None)))


def build_meshes(colliders: list[Collider], device) -> dict:
    """wp.Mesh (float32 points, with winding numbers) per mesh collider index."""
    out = {}
    for i, c in enumerate(colliders):
        if c.type == "mesh":
            assert c.mesh is not None, "checked by Collider.problems()"
            pts, tris = c.mesh.geometry
            out[i] = wp.Mesh(points=wp.array(pts.astype(np.float32), dtype=wp.vec3, device=device),
                             indices=wp.array(tris.reshape(-1).astype(np.int32), dtype=wp.int32,
                                              device=device),
                             support_winding_number=True)
    return out
