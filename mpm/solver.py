"""The explicit MPM step, as a short list of named stages.

The solver compiles only what the model uses: one P2G per material model
present, one G2P per distinct plasticity projection, the grid update and the
diagnostics for the scene's dimension and precision.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from itertools import groupby

import numpy as np
import warp as wp

from .diagnostics import diagnostic_names, make_measure
from .grid import make_grid_update
from .model import MaterialGroup, Model, State
from .schemes import EMPM
from .transfer import make_g2p, make_p2g


@dataclass
class SolverOptions:
    record_dJ: bool = False
    """write the per-particle dJ field every step (for logging)"""


@dataclass
class Monitor:
    """Stability figures of the last step."""

    max_speed: float  # [m/s]
    nonfinite: int  # particles with a non-finite position, velocity or F
    outside: int  # particles that left the domain interior

    @property
    def reason(self) -> str | None:
        if self.nonfinite:
            return f"{self.nonfinite} particles have non-finite position, velocity or F"
        if self.outside:
            return f"{self.outside} particles left the domain"
        return None


class Solver:
    """Advances a :class:`State` of a :class:`Model` with a scheme."""

    def __init__(self, model: Model, scheme=None, options: SolverOptions | None = None):
        self.model = model
        self.scheme = scheme or EMPM()
        if not isinstance(self.scheme, EMPM):
            raise ValueError(f"scheme {self.scheme!r} not supported; accepted: empm")
        self.options = options or SolverOptions()
        t, k, dev = model.types, model.kernel, model.device
        S = t.scalar

        # constants of the launches
        self._inv_dx = S(1.0 / model.dx)
        self._cells = t.ivec(*model.cells)
        self._strides = t.ivec(*model.strides)
        self._K = S(1.0 / (k.moment * model.dx**2))  # MLS moment inverse K_p
        self._gravity = t.vec(*model.gravity)
        self._wall_lo = t.ivec(*model.wall_codes[0])
        self._wall_hi = t.ivec(*model.wall_codes[1])
        margin = k.margin * model.dx
        self._inside_lo = t.vec(*([margin] * t.dim))
        self._inside_hi = t.vec(*[L - margin for L in model.domain])

        # kernels specialised for what the model holds
        self._p2g = [(make_p2g(t, k, g.cls), g) for g in model.groups]
        self._g2p = [
            (make_g2p(t, k, proj, self.options.record_dJ), _merge(list(gs)))
            for proj, gs in groupby(model.groups, key=lambda g: g.cls.project)
        ]
        self._grid_update = make_grid_update(t)
        self._measure = make_measure(t)

        with wp.ScopedDevice(dev):
            self.grid_m = wp.zeros(model.n_nodes, dtype=S)
            self.grid_v = wp.zeros(model.n_nodes, dtype=t.vec)  # momentum, then velocity
            self.monitor = wp.zeros(3, dtype=wp.float64)
            self.energy = wp.zeros(1, dtype=wp.float64)  # elastic energy seen by P2G
            self.diagnostics = wp.zeros(len(diagnostic_names(t.dim)), dtype=wp.float64)
            self._no_dJ = wp.zeros(1, dtype=S)

    # ------------------------------------------------------------------ setup
    def kernels(self) -> list:
        return [k for k, _ in self._p2g] + [k for k, _ in self._g2p] + [self._grid_update,
                                                                         self._measure]

    def load(self) -> float:
        """Compile (or load from the cache) every kernel this run uses; seconds taken."""
        t0 = time.perf_counter()
        modules = list({id(k.module): k.module for k in self.kernels()}.values())
        wp.force_load(device=self.model.device, modules=modules, max_workers=2)
        return time.perf_counter() - t0

    def prepare(self, state: State) -> None:
        """Allocate the scheme's per-particle arrays in ``state``."""
        if self.options.record_dJ and state.dJ is None:
            state.dJ = wp.zeros(self.model.n_particles, dtype=self.model.types.scalar,
                                device=self.model.device)

    # ------------------------------------------------------------------ step
    def step(self, state: State, dt: float) -> None:
        """Advance ``state`` by ``dt`` [s]."""
        dt = self.model.types.scalar(dt)
        self._clear()
        self._rasterize(state, dt)
        self._update_grid(dt)
        self._interpolate(state, dt)

    def _clear(self):
        """Zero the grid, the stability monitor and the energy sum."""
        self.grid_m.zero_()
        self.grid_v.zero_()
        self.monitor.zero_()
        self.energy.zero_()

    def _rasterize(self, state: State, dt):
        """P2G: mass and momentum, with the stress impulse, to the grid."""
        m = self.model
        for kernel, g in self._p2g:
            wp.launch(kernel, g.count, device=m.device, inputs=[
                m.mass, m.volume, m.body, m.body_params,
                state.X, state.v, state.C, state.F0s,
                self._inv_dx, self._cells, self._strides, self._K, dt, g.start,
                self.grid_m, self.grid_v, self.energy])

    def _update_grid(self, dt):
        """Grid momentum to velocity, gravity, walls."""
        m = self.model
        wp.launch(self._grid_update, m.n_nodes, device=m.device, inputs=[
            self.grid_m, self._gravity, dt, self._cells, self._strides,
            self._wall_lo, self._wall_hi, m.scene.wall_cells, self.grid_v])

    def _interpolate(self, state: State, dt):
        """G2P: velocities, affine matrices, positions, deformation; fused
        Eulerian configuration update."""
        m = self.model
        dJ = state.dJ if state.dJ is not None else self._no_dJ
        for kernel, g in self._g2p:
            wp.launch(kernel, g.count, device=m.device, inputs=[
                m.body, m.body_params, self.grid_v,
                self._inv_dx, self._cells, self._strides, self._K, dt, g.start,
                self._inside_lo, self._inside_hi,
                state.x, state.v, state.C, state.F0s, dJ, self.monitor])

    # ------------------------------------------------------------ read back
    def check(self) -> Monitor:
        """Stability figures of the last step (one small device-to-host copy)."""
        v2, nonfinite, outside = self.monitor.numpy()
        return Monitor(float(np.sqrt(v2)), int(nonfinite), int(outside))

    def step_energy(self) -> float:
        """Elastic energy [J] of the state the last step started from (P2G
        evaluates it with the stress)."""
        return float(self.energy.numpy()[0])

    def measure(self, state: State, elastic: bool = True) -> np.ndarray:
        """Diagnostics of ``state`` in the order of :func:`diagnostic_names`
        (float64). ``elastic=False`` leaves the elastic energy NaN (take it
        from :meth:`step_energy` of the next step); ``elastic=True`` runs a
        P2G pass for it, which overwrites the scratch grid (harmless between
        steps)."""
        m = self.model
        self.diagnostics.zero_()
        D = m.types.scalar(m.kernel.moment * m.dx**2)
        wp.launch(self._measure, m.n_particles, device=m.device, inputs=[
            m.mass, state.x, state.v, state.C, D, self._gravity, self.diagnostics])
        out = self.diagnostics.numpy().copy()
        i = self.diagnostic_names().index("elastic_energy")
        if elastic:
            self._clear()
            self._rasterize(state, m.types.scalar(0.0))
            out[i] = self.step_energy()
        else:
            out[i] = np.nan
        return out

    def diagnostic_names(self) -> list[str]:
        return diagnostic_names(self.model.dim)


def _merge(groups: list[MaterialGroup]) -> MaterialGroup:
    """One launch range over consecutive groups."""
    return MaterialGroup(groups[0].cls, groups[0].start, sum(g.count for g in groups))
