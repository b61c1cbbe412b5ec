"""Grid velocity update: momentum to velocity, gravity, box walls.

v_i = (m_i v_i) / m_i + dt g  on every node with mass, then for nodes within
``wall_cells`` of a face: sticky walls set v_i = 0, slip walls remove the
velocity component pointing into the wall (separation and tangential motion
are free), open faces do nothing.
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
def make_grid_update(t: Types):
    S = t.scalar
    dim = t.dim
    wall = make_wall(t)

    @wp.kernel(module="unique")
    def grid_update(
        grid_m: wp.array(dtype=S),
        gravity: t.vec,
        dt: S,
        cells: t.ivec,
        strides: t.ivec,
        wall_lo: t.ivec,
        wall_hi: t.ivec,
        wall_cells: int,
        grid_v: wp.array(dtype=t.vec),  # in: momentum, out: velocity
    ):
        i = wp.tid()
        m = grid_m[i]
        if m <= S(0.0):
            return
        vi = grid_v[i] / m + dt * gravity
        rest = i
        for d in range(wp.static(dim)):
            n = rest // strides[d]
            rest -= n * strides[d]
            if n < wall_cells:
                vi = wall(vi, d, S(-1.0), wall_lo[d])
            if n > cells[d] - wall_cells:
                vi = wall(vi, d, S(1.0), wall_hi[d])
        grid_v[i] = vi

    return grid_update
