"""After G2P, on the device: what the step's figures decide for the solver.

One thread (:func:`make_criterion`) reads the step's figures (mpm.stepping.status)
and writes into the control block, so that no host decision is needed
before the next step:

* per body, the particles still alive (those removed at open faces leave
  the counts the criterion divides by);
* per body, whether its reference configuration moves (``update``): the
  scheme's rule (mpm.schemes ``make_update_rule``) on the body's marked
  count, largest dJ and narrowest reference cell, never after a failed step
  (a non-finite value or a particle outside the domain);
* whether the new reference lies inside the body's grids (the layout's
  boxes): if not (``regrid``), the host refits the grids and does the update
  before the next step (``host_update``; the host also does every update
  when the driver reads back after every step, mpm.stepping.driver);
* with walls alone, whether the next P2G must sum node positions
  (``positions``): a condition acts on a node closer than the wall band to
  a closed face, and every node of body b lies in its particles' box grown
  by |F^sn|_inf (1 after an update) times the stencil's reach.
"""


import functools

import numpy as np
import warp as wp

from ..kernels import Kernel
from ..launch import warp_kernel
from ..reference_grids import FIT_SLACK
from ..schemes import RuleParams, make_update_rule, rule_kind, rule_params
from .status import StepControl, StepStatus
from ..types import Types


@functools.cache
def make_bounds(t: Types, kernel: Kernel):
    """``covered(status, b, lo, shape, inv_dx, shifts, last)``: whether body
    b's grids hold every stencil of its new positions; ``near_wall(status,
    b, reach, band, domain, closed_lo, closed_hi)``: whether its nodes can
    reach the wall band of a closed face (arguments: :func:`make_criterion`'s
    kernel)."""
    f64 = wp.float64
    dim, G, support = t.dim, kernel.n_grids, kernel.support
    Fv = wp.types.vector(G, f64)
    Dv = wp.types.vector(dim, f64)

    @wp.func
    def first_node(x: f64, inv_dx: f64, shift: f64, last: int):
        """The first stencil node of coordinate x along an axis, with the
        layout's slack (mpm.reference_grids.GridLayout.fit, FIT_SLACK)."""
        return wp.clamp(int(wp.floor(x * inv_dx - shift)), 0, last)

    @wp.func
    def covered(status: StepStatus, b: int, lo: wp.array(dtype=t.ivec), shape: wp.array(dtype=t.ivec),
                inv_dx: f64, shifts: Fv, last: t.ivec):
        """Whether body b's grids hold every stencil of its new positions."""
        for d in range(wp.static(dim)):
            x0 = status.box_lo[b * dim + d]
            x1 = status.box_hi[b * dim + d]
            if not (wp.isfinite(x0) and wp.isfinite(x1)):
                return True  # (a failed step; the layout ignores such bounds)
        for g in range(wp.static(G)):
            box = b * G + g
            for d in range(wp.static(dim)):
                a = first_node(status.box_lo[b * dim + d], inv_dx, shifts[g] + f64(FIT_SLACK), last[d])
                z = first_node(status.box_hi[b * dim + d], inv_dx, shifts[g] - f64(FIT_SLACK), last[d])
                if a < lo[box][d] or z > lo[box][d] + shape[box][d] - support:
                    return False
        return True

    @wp.func
    def near_box(status: StepStatus, b: int, reach: f64, band: f64, domain: Dv, closed_lo: t.ivec,
                 closed_hi: t.ivec):
        """Whether body b's box grown by ``reach`` [m] meets the wall band of a closed face."""
        for d in range(wp.static(dim)):
            lo = status.box_lo[b * dim + d] - reach
            hi = status.box_hi[b * dim + d] + reach
            if (lo < band and closed_lo[d] != 0) or (hi > domain[d] - band and closed_hi[d] != 0):
                return True
        return False

    @wp.func
    def near_wall(status: StepStatus, b: int, reach: f64, band: f64, domain: Dv, closed_lo: t.ivec,
                  closed_hi: t.ivec):
        """Whether body b's nodes can reach the wall band of a closed face: its
        box grown by the stencil's ``reach`` [m] times max(|F^sn|_inf, 1)."""
        norm = status.max_F_norm[b]  # max(|F^sn|_inf, 1), NaN kept
        if not (norm > f64(1.0)) and not wp.isnan(norm):
            norm = f64(1.0)
        r = reach * norm
        return not wp.isfinite(r) or near_box(status, b, r, band, domain, closed_lo, closed_hi)

    return covered, near_wall


@functools.cache
def make_criterion(t: Types, kernel: Kernel, n_bodies: int, kind: str, free_flight: bool, commits: bool,
                   device_moves: bool, batched: bool):
    """The decision kernel (module docstring), one thread; ``kind``: the
    scheme's rule (mpm.schemes.rule_kind); ``free_flight``: walls alone (the
    positions test runs); ``commits``: G2P has moved the references (fused
    EMPM), only the grids may have to follow; ``device_moves``: the update
    kernels run on the device where the grids cover the new reference (else
    the host refits and moves every updated body); ``batched``: nothing in a
    step the driver skips."""
    f64 = wp.float64
    dim, G = t.dim, kernel.n_grids
    updates = make_update_rule(kind)
    covered, near_wall = make_bounds(t, kernel)
    Fv = wp.types.vector(G, f64)
    Dv = wp.types.vector(dim, f64)

    @warp_kernel
    def criterion(
        status: StepStatus,
        control: StepControl,
        rule: RuleParams,  # pyright: ignore[reportGeneralTypeIssues]
        lo: wp.array(dtype=t.ivec),  # the layout's boxes
        shape: wp.array(dtype=t.ivec),
        inv_dx: f64,
        shifts: Fv,  # per kernel grid: its offset plus the kernel's [cells]
        last: t.ivec,  # the highest first node of a stencil per axis
        reach: f64,  # [m] the stencil's largest |r|
        band: f64,  # [m] the wall band, with room for round-off
        domain: Dv,  # [m]
        closed_lo: t.ivec,
        closed_hi: t.ivec,
    ):
        if wp.static(batched):
            if control.skip[0] != f64(0.0):
                return
        failed = status.nonfinite[0] > f64(0.0) or status.outside[0] > f64(0.0)
        status.positioned[0] = control.positions[0]
        host = f64(0.0)
        near = bool(False)
        for b in range(n_bodies):
            alive = control.alive[b] - status.removed[b]
            control.alive[b] = alive
            fire = bool(False)
            if not failed and alive > f64(0.0):
                fire = updates(status.marked[b], alive, status.max_dJ[b], wp.sqrt(status.min_stretch2[b]), rule)
            control.update[b] = wp.where(fire, f64(1.0), f64(0.0))
            control.regrid[b] = f64(0.0)
            if fire:
                if wp.static(device_moves or commits):
                    # the device moves the reference where the grids cover it (commits: G2P has)
                    if not covered(status, b, lo, shape, inv_dx, shifts, last):
                        control.regrid[b] = f64(1.0)
                        if wp.static(not commits):
                            host = f64(1.0)
                else:  # the host refits and moves every updated body
                    control.regrid[b] = f64(1.0)
                    host = f64(1.0)
            if wp.static(free_flight):
                if alive > f64(0.0):
                    if near_wall(status, b, reach, band, domain, closed_lo, closed_hi):
                        near = True
        control.host_update[0] = host
        if wp.static(free_flight):
            control.positions[0] = wp.where(near and not failed, f64(1.0), f64(0.0))
            if failed:
                control.positions[0] = f64(1.0)  # no bound from a failed step

    return criterion


class Criterion:
    """The decision after every step for one solver: its kernel and what it reads."""

    def __init__(self, model, launch, buffer, layout, scheme, conditions, *, free_flight: bool, commits: bool,
                 batched: bool):
        t, k = model.types, model.kernel
        self.model, self.launch, self.buffer, self.layout = model, launch, buffer, layout
        self.kernel = make_criterion(t, k, len(model.scene.bodies), rule_kind(scheme), free_flight, commits,
                                     device_moves=batched, batched=batched)
        self.rule = rule_params(scheme)
        self.inv_dx = 1.0 / model.dx
        shifts = np.asarray(k.grids, float) + k.offset
        self.shifts = wp.types.vector(k.n_grids, wp.float64)(*shifts)
        self.last = t.ivec(*(np.asarray(model.cells) - (k.support - 1)))
        self.reach = model.dx * max(k.offset + 1.0, k.support - 1.0 - k.offset)
        self.band = conditions.wall_reach + 1e-3 * model.dx
        self.domain = wp.types.vector(t.dim, wp.float64)(*model.domain)
        self.closed = (t.ivec(*conditions.closed[0].astype(int)), t.ivec(*conditions.closed[1].astype(int)))

    def decide(self) -> None:
        lay, b = self.layout, self.buffer
        self.launch(self.kernel, 1, [b.status, b.control, self.rule, lay.lo_d, lay.shape_d, self.inv_dx,
                                     self.shifts, self.last, self.reach, self.band, self.domain, *self.closed])
