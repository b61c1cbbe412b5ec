"""The domain's walls on the grid.

Each face of the domain box [0, L_d] is a wall of its type
(mpm.scene.WALL_TYPES): sticky (the body stops), slip (the velocity into
the wall is removed; sliding along it and leaving it are free) or open
(nothing). Under the surface rule (``Scene.boundary_rule = "surface"``,
mpm.surface) a wall is the solid behind a plane, its face, ``wall_cells``
cells inside the domain's face (at wall_cells dx and L_d - wall_cells dx),
and acts on a node where the body touches it; under the node rule
("nodes", the rule of earlier versions) it acts on every node closer than
``(wall_cells - 1/2) dx`` to the domain's face, i.e. the first
``wall_cells`` lattice nodes. Walls are frictionless, and act on the
node's own velocity.
"""

import functools

import warp as wp

from .collider_device import make_remove_direction
from .scene import WALL_TYPES
from .surface import APART, CONTACT, make_profile_type, make_surface
from .types import Types

STICKY = WALL_TYPES.index("sticky")
SLIP = WALL_TYPES.index("slip")


@functools.cache
def make_wall(t: Types):
    """``wall(v, n, kind) -> v``: a wall of type ``kind`` with the outward
    (into the domain) normal ``n`` on a node in contact with it."""
    S = t.scalar

    @wp.func
    def wall(v: t.vec, n: t.vec, kind: int):
        if kind == STICKY:
            return t.vec()
        vn = wp.dot(v, n)
        if kind == SLIP and vn < S(0.0):
            return v - vn * n
        return v

    return wall


@functools.cache
def make_faces(t: Types, rule: str):
    """``face(q, V, d, side, domain, band, face_lo, face_hi, profile) ->
    (state, n)``: whether a node at ``q`` (body volume fraction ``V``)
    touches the wall on axis ``d``'s low (``side`` 0) or high side, or lies
    behind its face (mpm.surface's APART, CONTACT, DEEP), and the wall's
    normal into the domain (module docstring; ``band`` the node rule's). The
    walls act alike on the nodes in contact and those behind their face
    (frictionless, on the node's own velocity)."""
    S, vec = t.scalar, t.vec
    Profile = make_profile_type(t)
    solid_share, touching, _ = make_surface(t)

    @wp.func
    def face(q: vec, V: S, d: int, side: int, domain: vec, band: S, face_lo: vec, face_hi: vec,
             profile: Profile):
        n = vec()
        phi = q[d] - face_lo[d]
        n[d] = S(1.0)
        if side == 1:
            phi = face_hi[d] - q[d]
            n[d] = S(-1.0)
        if wp.static(rule == "nodes"):
            inside = q[d] < band
            if side == 1:
                inside = q[d] > domain[d] - band
            state = APART
            if inside:
                state = CONTACT
            return state, n
        return touching(phi, V, solid_share(phi, profile), profile), n

    return face


@functools.cache
def make_walls(t: Types, rule: str):
    """``walls(v, q, V, domain, band, wall_lo, wall_hi, face_lo, face_hi,
    profile) -> v``: every closed wall on a node (module docstring)."""
    S, vec = t.scalar, t.vec
    Profile = make_profile_type(t)
    face = make_faces(t, rule)
    wall = make_wall(t)

    @wp.func
    def walls(v: vec, q: vec, V: S, domain: vec, band: S, wall_lo: t.ivec, wall_hi: t.ivec, face_lo: vec,
              face_hi: vec, profile: Profile):
        for d in range(wp.static(t.dim)):
            for side in range(2):
                kind = wall_lo[d]
                if side == 1:
                    kind = wall_hi[d]
                state, n = face(q, V, d, side, domain, band, face_lo, face_hi, profile)
                if state != APART:
                    v = wall(v, n, kind)
        return v

    return walls


@functools.cache
def make_wall_constraints(t: Types, rule: str):
    """``constrain(v, Pi, q, V, domain, band, wall_lo, wall_hi, face_lo,
    face_hi, profile, remove_direction) -> (v, Pi)``: the walls as
    constraints of the implicit solve at the predicted velocity: a sticky
    wall in contact fixes the node (v = 0, Pi = 0), a slip wall the node
    moves into fixes the normal velocity (v . n = 0, n removed from Pi)."""
    S, vec, mat = t.scalar, t.vec, t.mat
    Profile = make_profile_type(t)
    face = make_faces(t, rule)
    remove_direction = make_remove_direction(t)

    @wp.func
    def constrain(v: vec, Pi: mat, q: vec, V: S, domain: vec, band: S, wall_lo: t.ivec, wall_hi: t.ivec,
                  face_lo: vec, face_hi: vec, profile: Profile):
        for d in range(wp.static(t.dim)):
            for side in range(2):
                kind = wall_lo[d]
                if side == 1:
                    kind = wall_hi[d]
                state, n = face(q, V, d, side, domain, band, face_lo, face_hi, profile)
                if state != APART:
                    if kind == STICKY:
                        v = vec()
                        Pi = mat()
                    elif kind == SLIP and wp.dot(v, n) < S(0.0):
                        v = v - wp.dot(v, n) * n
                        Pi = remove_direction(Pi, n)
        return v, Pi

    return constrain
