"""Grid velocity update: momentum to velocity, gravity, box walls.

On every node with mass:
    v_i = (m_i v_i) / m_i + dt g,    q_i = (m_i q_i) / m_i,
then (after contact, when bodies can touch: mpm.contact) the boundary
conditions: walls act on nodes whose current position q_i lies within the wall band
of a face: closer than ``(wall_cells - 1/2) dx`` to it, i.e. the first
``wall_cells`` lattice nodes of an Eulerian grid. Sticky walls set v_i = 0,
slip walls remove the velocity component pointing into the wall (separation
and tangential motion are free), open faces do nothing.
"""

import functools

import warp as wp

from .scene import WALL_TYPES
from .types import Types

STICKY = WALL_TYPES.index("sticky")
SLIP = WALL_TYPES.index("slip")


@functools.cache
def make_wall(t: Types):
    S = t.scalar
    vec = t.vec

    @wp.func
    def wall(v: t.vec, d: int, outward: S, kind: int):
        if kind == STICKY:
            return vec()
        if kind == SLIP and v[d] * outward > S(0.0):
            v[d] = S(0.0)
        return v

    return wall


@functools.cache
def make_walls(t: Types):
    """``walls(v, q, domain, band, wall_lo, wall_hi) -> v``."""
    S = t.scalar
    wall = make_wall(t)

    @wp.func
    def walls(v: t.vec, q: t.vec, domain: t.vec, band: S, wall_lo: t.ivec, wall_hi: t.ivec):
        for d in range(wp.static(t.dim)):
            if q[d] < band:
                v = wall(v, d, S(-1.0), wall_lo[d])
            if q[d] > domain[d] - band:
                v = wall(v, d, S(1.0), wall_hi[d])
        return v

    return walls


@functools.cache
def make_grid_update(t: Types, with_walls: bool):
    """Momentum to velocity and gravity; the walls too unless ``with_walls`` is
    False (contact comes first, then :func:`make_boundary`)."""
    S = t.scalar
    walls = make_walls(t)

    @wp.kernel(module="unique")
    def grid_update(
        grid_m: wp.array(dtype=S),
        gravity: t.vec,
        dt: S,
        domain: t.vec,
        band: S,
        wall_lo: t.ivec,
        wall_hi: t.ivec,
        grid_v: wp.array(dtype=t.vec),  # in: momentum, out: velocity
        grid_q: wp.array(dtype=t.vec),  # in: mass-weighted position, out: position
    ):
        i = wp.tid()
        m = grid_m[i]
        if m <= S(0.0):
            return
        vi = grid_v[i] / m + dt * gravity
        qi = grid_q[i] / m
        if wp.static(with_walls):
            vi = walls(vi, qi, domain, band, wall_lo, wall_hi)
        grid_v[i] = vi
        grid_q[i] = qi

    return grid_update


@functools.cache
def make_boundary(t: Types):
    """The walls as a pass of their own (after contact)."""
    S = t.scalar
    walls = make_walls(t)

    @wp.kernel(module="unique")
    def boundary(
        grid_m: wp.array(dtype=S),
        grid_q: wp.array(dtype=t.vec),
        domain: t.vec,
        band: S,
        wall_lo: t.ivec,
        wall_hi: t.ivec,
        grid_v: wp.array(dtype=t.vec),
    ):
        i = wp.tid()
        if grid_m[i] <= S(0.0):
            return
        grid_v[i] = walls(grid_v[i], grid_q[i], domain, band, wall_lo, wall_hi)

    return boundary
