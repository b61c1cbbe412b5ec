"""The MPM step, as a short list of named stages.

One formulation serves every scheme (mpm.schemes): each body has its own
reference grid (mpm.layout); a step rasterises the particles to it (mpm.p2g),
updates the nodal velocities - forward Euler, or backward Euler by Newton's
method (mpm.integrators, mpm.implicit) - applies contact (mpm.contact) and
the boundary conditions (mpm.conditions), interpolates back (mpm.g2p) and
leaves the configuration update (mpm.configuration) to the scheme's rule.

The solver compiles only what the model uses (mpm.plan lists it): one P2G
per material model present, one configuration update per body's
projection, one G2P, grid update and diagnostics kernel for the dimension
and precision; contact, separate boundary passes and the implicit
integrator's kernels only when the scene needs them.
"""

import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .conditions import Conditions
from .configuration import References
from .contact import Contact
from .diagnostics import Diagnostics
from .fracture import FractureMeasure
from .implicit import ImplicitSolve, NewtonReport
from .integrators import Explicit, Implicit
from .launch import Launches
from .layout import GridArrays, GridLayout
from .memory import array_bytes
from .model import Model, State
from .schemes import AULMPM, EMPM, scene_kind
from .status import StatusBuffer, StepReport
from .stencil import fuse
from .timestep import StepRule
from .transfer import TRANSFERS, GridConstants, Transfers


@dataclass
class SolverOptions:
    record_dJ: bool = False
    """write the per-particle dJ field every step (for logging)"""
    transfer: str = "mls"
    """mls | apic | pic (mpm.transfer.TRANSFERS)"""
    integrator: Explicit | Implicit = field(default_factory=Explicit)
    """forward or backward Euler on the grid velocities (mpm.integrators)"""
    track_J: bool = False
    """report every body's smallest det F and smallest singular value of F
    (for inversion detection, mpm.stability)"""
    track_energy: bool = False
    """report the new state's kinetic and potential energy and each body's
    fastest particle every step (mpm.stability)"""
    fuse: bool | None = None
    """the explicit Eulerian scheme locates stencils in P2G and G2P instead
    of caching them, and (when its bodies share one projection) G2P does
    the every-step configuration update, so that no update pass runs; the
    same results bit for bit after every completed step. None: where it
    costs no time on this project's CPU (pipelines.bench "fused") and saves
    a launch per step and the stencil cache's memory (20-26 %): the
    quadratic and cubic kernels (a constant moment); not the compact kernel,
    whose sines (and K_p at the new position) would be evaluated twice more
    per step, nor the linear one"""


class Solver:
    """Advances a :class:`State` of a :class:`Model` with a scheme.

    Public parts, for the integrators, observers and tests: ``layout`` and
    ``grid`` (the reference grids and their nodal fields), ``const`` (the
    discretisation's constants), ``status`` (the step's figures,
    mpm.status), ``transfers``, ``conditions``, ``contact`` (None without),
    ``references``, ``implicit`` (the Newton solve, None when explicit),
    ``timestep`` (the step limits), ``fracture`` and ``diagnostics``."""

    def __init__(self, model: Model, scheme=None, options: SolverOptions | None = None):
        self.model = model
        scheme = scheme or EMPM()
        if isinstance(scheme, AULMPM):
            scheme = scheme.resolved(scene_kind(b.material for b in model.scene.bodies))
        self.scheme, self.options = scheme, options or SolverOptions()
        opt, t, k, dev, scene = self.options, model.types, model.kernel, model.device, model.scene
        if opt.transfer not in TRANSFERS:
            raise ValueError(f"transfer {opt.transfer!r}; accepted: {', '.join(TRANSFERS)}")
        if scene.contact == "shared" and not isinstance(scheme, EMPM):
            raise ValueError("contact 'shared' (one grid for all bodies) needs the Eulerian scheme")
        nb = self.n_bodies = len(scene.bodies)
        self.body_counts = np.array([c for _, c in model.body_ranges])  # particles not removed, per body
        self.removed = np.zeros(nb, np.int64)  # per body: particles removed at open faces so far
        self.kept: np.ndarray | None = None  # the particles not removed, by number (None: all of them)
        implicit = isinstance(opt.integrator, Implicit)
        eulerian = isinstance(scheme, EMPM)
        self.launch = Launches(dev)  # the step's launches, repacking only what changed
        self.const = GridConstants.of(model)
        self.layout = GridLayout(t, k, model.dx, model.cells, nb, dev, shared=scene.contact == "shared")
        self.grid = GridArrays(t, dev, regions=len(scene.regions) > 0)
        self.status = StatusBuffer(nb, t.dim, dev)
        self.contact = Contact(model, self.launch, implicit) if nb > 1 and scene.contact == "frictionless" else None
        # the conditions act in the grid update, or after contact or the implicit solve
        self.conditions = Conditions(model, self.launch, separate=self.contact is not None or implicit,
                                     implicit=implicit, lattice=eulerian)
        # a moving grid needs node positions only where a condition can reach a node: with walls
        # alone, P2G sums them only in steps where a body comes near a closed face (_positions_needed)
        self.free_flight = not (eulerian or self.conditions.regions or scene.colliders or self.contact
                                or implicit)
        projections = {b.material.project for b in scene.bodies}
        fused = (opt.fuse if opt.fuse is not None else k.moment is not None and len(projections) == 1)
        self.fused = fused and eulerian and not implicit
        # fused EMPM: G2P does the configuration update too when the bodies share one projection
        self.g2p_commits = self.fused and len(projections) == 1 and scheme.affine == "keep"
        forcing = scene.solution if getattr(scene.solution, "has_body_force", False) else None
        self.transfers = Transfers(
            model, self.launch, opt.transfer, lagrangian=not eulerian, fused=self.fused,
            commit=self.g2p_commits, with_stress=not implicit, regions=self.conditions.regions,
            forcing=forcing, record_dJ=opt.record_dJ, marks=scheme.tracks_marks(),
            epsilon=getattr(scheme, "epsilon", None) or 0.0, track_energy=opt.track_energy,
            track_J=opt.track_J, removal=self.conditions.open, bound_reach=self.free_flight,
            project=next(iter(projections)) if self.g2p_commits else None)
        per_particle_K = k.moment is None and opt.transfer != "pic"  # K_p cached per particle
        self.references = References(model, self.launch, self.layout, self.grid,
                                     transform=scheme.affine == "transform",
                                     gradients=opt.transfer != "mls" or k.gradient_affine, fused=self.fused,
                                     moment=per_particle_K)
        self.diagnostics = Diagnostics(model, self.launch, per_particle_K)
        self.fracture = FractureMeasure(model)
        self.implicit = ImplicitSolve(self, opt.integrator) if implicit else None
        self.timestep = StepRule(model, self.conditions.collider_speed)
        self._reach = model.dx * max(k.offset + 1.0, k.support - 1.0 - k.offset)  # [m] largest |r| of a stencil
        self._positions = 1  # P2G sums the node positions in the next step
        self._backup = None  # F^0s and history before an implicit step (plastic models, for a retry)
        self.time = 0.0  # [s] simulated time of the state (kinematic regions and colliders depend on it)
        self.X0 = None  # [m] initial positions, float64 (after prepare)

    # ------------------------------------------------------------------ setup
    def kernels(self) -> list:
        """Every kernel this run compiles."""
        parts = [self.transfers, self.conditions, self.contact, self.references, self.implicit]
        return ([k for part in parts if part is not None for k in part.kernels()]
                + [self.diagnostics.kernel, self.fracture.kernel])

    def load(self) -> float:
        """Compile (or load from the cache) every kernel this run uses; seconds taken."""
        t0 = time.perf_counter()
        modules = list({id(k.module): k.module for k in self.kernels()}.values())
        wp.force_load(device=self.model.device, modules=modules, max_workers=2)
        return time.perf_counter() - t0

    def prepare(self, state: State) -> None:
        """Take the initial positions as every body's reference configuration
        and record the neighbour pairs of the fracture measure."""
        m = self.model
        x = state.x.numpy()
        self._positions = 1  # no bound before the first step
        self.X0 = x.astype(np.float64)
        self.diagnostics.prepare(self.X0)
        self.fracture.prepare(x)
        if self.fused:
            fuse(state.stencils, m.types, m.kernel, state.X, self.layout.lo_d, self.layout.offset_d, m.dx)
        lo = [x[s:s + c].min(axis=0) for s, c in m.body_ranges]
        hi = [x[s:s + c].max(axis=0) for s, c in m.body_ranges]
        self.references.fit(range(self.n_bodies), lo, hi)
        self.references.move(state, range(self.n_bodies), self.const)

    # ------------------------------------------------------------------ step
    def advance(self, state: State, dt: float, halvings: int = 0) -> StepReport:
        """One step of ``dt`` [s], then the configuration updates the scheme
        asks for. An implicit step whose Newton solve fails is retried with
        half the step up to ``halvings`` times (the state is restored first);
        ``report.dt`` is the step taken."""
        for attempt in range(halvings + 1):
            newton = self.step(state, dt)
            if newton is None or newton.converged or attempt == halvings:
                break
            self._restore(state)
            dt *= 0.5
        if newton is not None and not newton.converged:
            self._restore(state)  # the state the failed step started from
            report = StepReport.failed(self.n_bodies)
        else:
            self._interpolate(state, self.model.types.scalar(dt))
            report = self.report()
        report.dt, report.newton, report.halvings = dt, newton, attempt
        report.positioned = bool(self._positions)
        if report.removed is not None:
            self._count_removed(report)
        if report.reason is not None:
            self._positions = 1  # no bound from a failed step
        else:
            t0 = time.perf_counter()
            report.updated = [b for b in range(self.n_bodies) if self.body_counts[b] > 0
                              and self.scheme.updates(int(report.marked[b]), int(self.body_counts[b]),
                                                     float(report.max_dJ[b]), float(report.min_stretch[b]))]
            if report.updated:  # (G2P has moved the fused Eulerian references: only their grids follow)
                self.references.fit(report.updated, report.box_lo, report.box_hi)
                if not self.g2p_commits:
                    self.references.move(state, report.updated, self.const)
            report.update_time = time.perf_counter() - t0
            self._positions = self._positions_needed(report)
        return report

    def step(self, state: State, dt: float) -> NewtonReport | None:
        """Advance the grid of ``state`` by ``dt`` [s] in the current reference
        configurations, up to the grid velocities (G2P follows in
        :meth:`advance`); the implicit solve's report, or None (explicit)."""
        t0 = self.time
        self.step_time = self.model.types.scalar(t0)  # the conditions' clock [s]
        self.time += dt
        dt = self.model.types.scalar(dt)
        self._clear()
        self._apply_forcing(t0)
        self._save(state)
        self._rasterize(state, dt)
        self._update_grid(dt)
        newton = self._solve(state, dt)
        if newton is not None and not newton.converged:
            self.time = t0
            return newton
        self._resolve_contact()
        self._apply_boundary()
        return newton

    # the stages
    def _clear(self) -> None:
        """Zero the grid (the node positions unless on the lattice) and the step's figures."""
        lattice = isinstance(self.scheme, EMPM)
        self.grid.clear(self.layout.n_nodes, positions=not lattice and bool(self._positions))
        self.status.reset()

    def _apply_forcing(self, t0: float) -> None:
        """A manufactured solution's body force at the step's start ``t0`` [s] (host)."""
        if self.transfers.forcing is not None:
            self.transfers.apply_forcing(self.X0, t0)

    def _rasterize(self, state: State, dt, write: bool = True) -> None:
        """P2G (mpm.p2g); the plastic return mapping stored when ``write``."""
        self.transfers.rasterize(state, self.grid, self.layout, self.const, dt, self.status.status, write,
                                 self._positions)

    def _update_grid(self, dt) -> None:
        """Momentum to velocity, gravity, and the conditions unless they come later."""
        self.conditions.update_grid(self.grid, self.layout, self.const, dt, self.step_time, self.status.status,
                                    self._positions)

    def _solve(self, state: State, dt) -> NewtonReport | None:
        """Backward Euler by Newton's method (mpm.implicit); None when explicit."""
        return self.implicit.solve(state, dt) if self.implicit is not None else None

    def _resolve_contact(self) -> None:
        """Frictionless contact between bodies (mpm.contact)."""
        if self.contact is not None:
            self.contact.resolve(self.grid, self.layout, self.status.status)

    def _apply_boundary(self) -> None:
        """The conditions after contact or the implicit solve."""
        if self.conditions.boundary is not None:
            self.conditions.apply(self.grid, self.layout, self.step_time, self.status.status)

    def _interpolate(self, state: State, dt) -> None:
        """G2P (mpm.g2p): velocities, affine matrices, positions, F^sn, the step's figures."""
        self.transfers.interpolate(state, self.grid, self.layout, self.const, dt, self.status.status)

    def _save(self, state: State) -> None:
        """Keep F^0s and the history before an implicit step of a plastic
        model: P2G's return mapping overwrites them."""
        if self.implicit is None or not self.model.plastic:
            return
        if self._backup is None:
            self._backup = (wp.empty_like(state.F0s), wp.empty_like(state.history))
        wp.copy(self._backup[0], state.F0s)
        wp.copy(self._backup[1], state.history)

    def _restore(self, state: State) -> None:
        """Undo a failed implicit step (the grid is scratch; only P2G's plastic
        write-back and the clock changed the state)."""
        if self._backup is not None:
            wp.copy(state.F0s, self._backup[0])
            wp.copy(state.history, self._backup[1])

    # ------------------------------------------------------------ read back
    def report(self) -> StepReport:
        """Stability figures and criterion counts of the last step (one small
        device-to-host copy)."""
        return StepReport.of(self.status.read(), self.model.dim, energy=self.options.track_energy,
                             reach=self.free_flight)

    def _positions_needed(self, report: StepReport) -> int:
        """Whether the next step's P2G must sum the node positions (1) or
        no boundary condition can reach a node (0). With walls alone (no
        regions, colliders, contact or implicit solve) a condition acts on a
        node closer than the wall band to a closed face. A node sits at a
        mass-weighted mean of x_p + F^sn r over its particles, |(F^sn r)_d| <=
        |F^sn|_inf max_k |r_k|, so every node of body b lies in its particles'
        box grown by |F^sn|_inf (1 after a configuration update) times the
        stencil's reach."""
        if not self.free_flight or report.max_F_norm is None:
            return 1
        reach = self._reach * np.maximum(report.max_F_norm, 1.0)[:, None]  # [m] per body
        near = self.conditions.near_wall(report.box_lo - reach, report.box_hi + reach)
        live = self.body_counts > 0
        return int(bool(np.any(near[live])) or not np.all(np.isfinite(reach[live])))

    def _count_removed(self, report: StepReport) -> None:
        """Per body, the particles G2P removed at open faces (mass 0): the
        counts the criterion divides by shrink with them."""
        mass = self.model.mass.numpy()
        alive = np.array([int(np.count_nonzero(mass[start:start + count]))
                          for start, count in self.model.body_ranges])
        report.removed = self.body_counts - alive
        self.removed += report.removed
        self.body_counts = alive
        self.kept = np.flatnonzero(mass > 0)

    def step_energy(self) -> float:
        """Elastic energy [J] of the state the last step started from (P2G
        evaluates it with the stress)."""
        return float(self.transfers.energy.numpy()[0])

    def measure(self, state: State, elastic: bool = True) -> np.ndarray:
        """Diagnostics of ``state`` in the order of mpm.diagnostics.diagnostic_names
        (float64). ``elastic=False`` leaves the elastic energy NaN (take it
        from :meth:`step_energy` of the next step); ``elastic=True`` runs a
        P2G pass for it, which overwrites the scratch grid (harmless between
        steps)."""
        out = self.diagnostics.measure(state)
        if elastic:
            self._clear()
            self._rasterize(state, self.model.types.scalar(0.0), write=False)
            out[self.diagnostics.names.index("elastic_energy")] = self.step_energy()
        return out

    def memory_bytes(self, state: State) -> int:
        """Bytes of the Warp arrays of the model, ``state`` and the solver
        (grids at their current capacity, caches, scratch; mpm.memory)."""
        return array_bytes(self.model, state, self)
