"""The grid side of a step as the grid kernels take it (mpm.grid,
mpm.contact): one Warp struct with the nodal fields of every box
(mpm.reference_grids.GridArrays), the layout's tables per box and the global
lattice (spacing dx, ``cells`` + 1 nodes per axis, flat index by
``strides``). It is packed where the grid's arrays are allocated
(:func:`pack_lattice`, again at every reallocation), not at every launch.
"""

import functools

import numpy as np
import warp as wp

from .stepping.status import StepControl
from .types import Types


@functools.cache
def make_lattice(t: Types):
    """The struct type ``Lattice`` for Types ``t``."""
    S = t.scalar

    @wp.struct
    class Lattice:
        m: wp.array(dtype=S)  # node mass [kg]
        v: wp.array(dtype=t.vec)  # momentum [kg m/s], then velocity [m/s]
        q: wp.array(dtype=t.vec)  # mass-weighted position [kg m], then position [m]
        G: wp.array(dtype=t.mat)  # mass-weighted velocity gradient [kg/s], then gradient [1/s] (surface rule)
        kin: wp.array(dtype=S)  # mass drawn from a kinematic region [kg] (one entry without regions)
        kin_id: wp.array(dtype=wp.int32)  # that region's number + 1 (0: none)
        lo: wp.array(dtype=t.ivec)  # per box b * n_grids + g: its first node (lattice index)
        shape: wp.array(dtype=t.ivec)  # per box: nodes per axis
        offset: wp.array(dtype=wp.int32)  # per box: its first flat node
        n_boxes: int  # n_bodies * n_grids
        n_bodies: int
        n_grids: int  # the kernel's grids (every one carries a body's full mass)
        dx: S  # [m]
        inv_dx: S  # [1/m]
        cells: t.ivec  # lattice cells per axis
        strides: t.ivec  # lattice node (idx_0, ...) is flat node sum_d idx_d strides_d
        n_global: int  # lattice nodes

    return Lattice


def pack_lattice(layout, grid):
    """The ``Lattice`` of ``grid``'s arrays (GridArrays, after ``reserve``)
    and ``layout``'s tables (GridLayout)."""
    t = layout.t
    nodes = np.asarray(layout.cells) + 1
    lat = make_lattice(t)()
    lat.m, lat.v, lat.q, lat.kin, lat.kin_id = grid.m, grid.v, grid.q, grid.kin, grid.kin_id
    lat.G = grid.G
    lat.lo, lat.shape, lat.offset = layout.lo_d, layout.shape_d, layout.offset_d
    lat.n_boxes = len(layout.lo)
    lat.n_grids = layout.kernel.n_grids
    lat.n_bodies = lat.n_boxes // lat.n_grids
    lat.dx = t.scalar(layout.dx)
    lat.inv_dx = t.scalar(1.0 / layout.dx)
    lat.cells = t.ivec(*(int(c) for c in layout.cells))
    lat.strides = t.ivec(*(int(np.prod(nodes[d + 1:])) for d in range(t.dim)))
    lat.n_global = int(np.prod(nodes))
    return lat


@functools.cache
def make_node_mass(t: Types, batched: bool = False):
    """``node_mass(lat, control, i) -> m``: node i's mass [kg], 0 in a step
    the driver skips (``batched``: ``control.skip``): the grid kernels pass
    over a node without mass."""
    Lattice = make_lattice(t)

    @wp.func
    def node_mass(lat: Lattice, control: StepControl, i: int):
        if wp.static(batched):
            if control.skip[0] != wp.float64(0.0):
                return t.scalar(0.0)
        return lat.m[i]

    return node_mass
