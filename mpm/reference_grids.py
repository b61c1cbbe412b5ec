"""Per-body reference grids ("configuration maps").

Each body has its own grid in its reference configuration - one per grid of
the kernel (two staggered ones for the compact kernel): the nodes of the
global lattice (spacing dx, node i of kernel grid g at (i + o_g) dx) inside a
box that covers the stencils of its reference positions X. Box b * G + g is
grid g of body b; all boxes are stored one after another in flat arrays; a
body's boxes are recomputed when its configuration is updated (every step for
the Eulerian scheme). Two bodies never share a node, so they interact only
through contact.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from .kernels import Kernel
from .lattice import pack_lattice
from .types import Types


FIT_SLACK = 1.0e-3
"""[cells] a box covers the stencils of positions this much beyond its
bounds: a particle on a node of a grid (the compact kernel's grids sit a
quarter cell off the lattice, where regular sampling puts particles) has its
first stencil node at a floor the kernels round in their own precision, and a
box that cut it off would clamp the stencil (mpm.stencil.make_locate) in one
layout and not in another (float32 rounds u = X / dx by about 1e-5 cells on
a 128-cell grid)."""


class GridLayout:
    """Boxes of the bodies' reference grids and the device tables (first node,
    nodes per axis, offset into the flat arrays) per box b * G + g."""

    def __init__(self, t: Types, kernel: Kernel, dx: float, cells: tuple[int, ...],
                 n_bodies: int, device: str, shared: bool = False):
        """``shared``: every body uses the same boxes (one grid for all, as in
        standard MPM); ``fit`` then grows them to cover all bodies."""
        self.t, self.kernel, self.dx, self.shared = t, kernel, dx, shared
        self.cells = np.asarray(cells)
        n_boxes = n_bodies * kernel.n_grids
        self.lo = np.zeros((n_boxes, t.dim), np.int32)  # first node (lattice index)
        self.shape = np.ones((n_boxes, t.dim), np.int32)  # nodes per axis
        self.offset = np.zeros(n_boxes, np.int32)
        self.n_nodes = 0
        self.version = 0  # commits that changed a box (a captured step must be captured again)
        self._changed = True  # a fit changed a box since the last commit (or none was made)
        G = kernel.n_grids
        self._shift = np.asarray(kernel.grids)[:, None] + kernel.offset  # [cells] per grid (row)
        self._last = self.cells - (kernel.support - 1)  # the highest first node of a stencil
        # (lo, shape) views per body [grid, axis]; shared: all bodies at once [body, grid, axis]
        by_body = (self.lo.reshape(n_bodies, G, t.dim), self.shape.reshape(n_bodies, G, t.dim))
        self._grids: Any = by_body if shared else [(by_body[0][b], by_body[1][b]) for b in range(n_bodies)]
        self._fitted: dict = {}  # shared: each body's last bounds
        with wp.ScopedDevice(device):
            self.lo_d = wp.zeros(n_boxes, dtype=t.ivec)
            self.shape_d = wp.zeros(n_boxes, dtype=t.ivec)
            self.offset_d = wp.zeros(n_boxes, dtype=wp.int32)

    def fit(self, body: int, xmin: np.ndarray, xmax: np.ndarray) -> None:
        """Make ``body``'s boxes cover every stencil of positions in [xmin, xmax]
        (left as they are if the bounds are not finite). Called every step
        for an Eulerian body: a few small NumPy operations, no copies."""
        xmin, xmax = np.asarray(xmin, float), np.asarray(xmax, float)
        if not (np.isfinite(xmin).all() and np.isfinite(xmax).all()):
            return
        k = self.kernel
        if self.shared:
            self._fitted[body] = (xmin, xmax)
            xmin = np.min([a for a, _ in self._fitted.values()], axis=0)
            xmax = np.max([b for _, b in self._fitted.values()], axis=0)
        # per grid (rows) the first stencil node of the lowest and highest position, either side of
        # a node the kernels' own rounding may put it on (FIT_SLACK)
        lo = np.floor(xmin / self.dx - self._shift - FIT_SLACK).clip(0, self._last).astype(np.int32)
        hi = np.floor(xmax / self.dx - self._shift + FIT_SLACK).clip(0, self._last).astype(np.int32)
        shape = hi - lo + np.int32(k.support)
        # shared: every body's rows take body 0's boxes
        rows = self._grids if self.shared else self._grids[body]
        if not ((rows[0] == lo).all() and (rows[1] == shape).all()):
            rows[0][...] = lo
            rows[1][...] = shape
            self._changed = True

    def commit(self) -> None:
        """Recompute offsets and upload the tables (after one or more ``fit``);
        nothing when no fit changed a box since the last commit (an Eulerian
        body's boxes change only when its bounds cross a cell)."""
        if not self._changed:
            return
        self._changed = False
        self.version += 1
        sizes = np.prod(self.shape.astype(np.int64), axis=1)
        if self.shared:  # the grids of body 0, for everyone
            G = self.kernel.n_grids
            first = np.concatenate([[0], np.cumsum(sizes[:G])[:-1]])
            self.offset[:] = np.tile(first, len(self.offset) // G)
            self.n_nodes = int(sizes[:G].sum())
        else:
            self.offset[:] = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            self.n_nodes = int(sizes.sum())
        self.lo_d.assign(self.lo)
        self.shape_d.assign(self.shape)
        self.offset_d.assign(self.offset)


class GridArrays:
    """The nodal fields of every box of a :class:`GridLayout`, flat: mass
    ``m``, momentum then velocity ``v``, mass-weighted then current node
    position ``q``, with kinematic regions the mass each node draws from
    a region ``kin`` and the region's number ``kin_id``, and with the FLIP
    transfer the momentum transferred alone ``p0``. The arrays grow
    (by half again) when the layout no longer fits; :meth:`live` views the
    layout's nodes. With the ``layout``, ``lattice`` holds the arrays and
    its tables as the grid kernels take them (mpm.lattice), packed anew
    whenever the arrays are."""

    def __init__(self, t: Types, device, regions: bool, flip: bool = False, layout: GridLayout | None = None,
                 gradients: bool = False):
        self.t, self.device, self.regions, self.flip, self.layout = t, device, regions, flip, layout
        self.gradients = gradients
        self.capacity = 0
        self.m = self.v = self.q = self.kin = self.kin_id = self.p0 = self.lattice = self.G = None
        self._views = None  # (node count, m, views) of live()

    def reserve(self, n: int) -> None:
        """Room for ``n`` nodes (new arrays when it grows: views taken before are stale)."""
        if n <= self.capacity:
            return
        t = self.t
        self.capacity = int(1.5 * n) if self.capacity else n
        with wp.ScopedDevice(self.device):
            self.m = wp.zeros(self.capacity, dtype=t.scalar)
            self.v = wp.zeros(self.capacity, dtype=t.vec)
            self.q = wp.zeros(self.capacity, dtype=t.vec)
            n_kin = self.capacity if self.regions else 1
            self.kin = wp.zeros(n_kin, dtype=t.scalar)
            self.kin_id = wp.zeros(n_kin, dtype=wp.int32)
            self.p0 = wp.zeros(self.capacity if self.flip else 1, dtype=t.vec)
            self.G = wp.zeros(self.capacity if self.gradients else 1, dtype=t.mat)
        if self.layout is not None:
            self.lattice = pack_lattice(self.layout, self)

    def live(self, n: int) -> tuple:
        """Views (m, v, q, kin, kin_id, p0) of the first ``n`` nodes (kept while the
        node count and the arrays stay: slicing a Warp array every step costs
        more host time than zeroing the 2D ball's grid)."""
        if self._views is None or self._views[0] != n or self._views[1] is not self.m:
            arrays: tuple = (self.m, self.v, self.q, self.kin, self.kin_id, self.p0)  # (reserved)
            self._views = (n, self.m, tuple(a[:n] if len(a) >= n else a for a in arrays))
        return self._views[2]

    def clear(self, n: int, positions: bool) -> None:
        """Zero the first ``n`` nodes' fields (the positions only if ``positions``)."""
        m, v, q, kin, kin_id, p0 = self.live(n)
        m.zero_()
        v.zero_()
        if self.flip:
            p0.zero_()
        if self.gradients:
            assert self.G is not None, "reserve() first"
            self.G[:n].zero_()
        if positions:
            q.zero_()
        if self.regions:
            kin.zero_()
            kin_id.zero_()
