"""The MPM step, as a short list of named stages.

One formulation serves every scheme (mpm.schemes): each body has its own
reference grid (mpm.layout); a step rasterises the particles to it, updates
the nodal velocities - forward Euler, or backward Euler by Newton's method
(mpm.integrators, mpm.implicit) - applies contact and the boundary
conditions, interpolates back and leaves the configuration update to the
scheme's rule, evaluated by :meth:`Solver.advance`.

The solver compiles only what the model uses: one P2G per material model
present, one configuration update per distinct plasticity projection, one
G2P, grid update and diagnostics kernel for the dimension and precision;
the implicit integrator's kernels only when it is chosen.
"""

import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .colliders import INSIDE_DEPTH, build_meshes, kinds_of, make_inside_count, pack
from .configuration import make_update
from .diagnostics import about_center_of_mass, diagnostic_names, make_measure
from .fracture import fragments, make_fracture, neighbour_pairs
from .contact import make_contact
from .grid import make_boundary, make_boundary_data, make_constraints, make_grid_update, region_types
from .implicit import ImplicitSolve, NewtonReport
from .integrators import Explicit, Implicit
from .launch import Launches, kernel_name
from .layout import GridLayout
from .memory import array_bytes
from .stencil import fuse
from .model import Model, State
from .scene import WALL_TYPES
from .schemes import AULMPM, EMPM, scene_kind
from .timestep import StepLimits, displacement_dt, step_limits
from .transfer import (STATUS_CONTACT, STATUS_HEADER, STATUS_KINETIC, STATUS_MAX_V2, STATUS_NONFINITE,
                       STATUS_OUTSIDE, STATUS_REMOVED,
                       STATUS_F_NORM, STATUS_F_STRETCH, STATUS_PER_BODY, STATUS_POTENTIAL, STATUS_SPEED,
                       STATUS_WORK, TRANSFERS,
                       make_g2p, make_p2g)


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


@dataclass
class StepReport:
    """What one step left behind: stability figures, the criterion per body,
    the configuration updates it triggered."""

    max_speed: float  # [m/s]
    nonfinite: int  # particles with a non-finite position, velocity or F^sn
    outside: int  # particles that left the domain interior
    marked: np.ndarray  # per body: particles with dJ >= epsilon (A-ULMPM), else 0
    max_dJ: np.ndarray  # per body: the largest dJ (A-ULMPM), else 0
    min_J: np.ndarray  # per body: the smallest det F (compression, for the time step)
    min_stretch: np.ndarray  # per body: the smallest singular value of F^sn (for the time step)
    max_rate: np.ndarray  # per body: the largest velocity gradient |L| [1/s] (for the time step)
    stiffening: np.ndarray  # per body: the largest growth of the squared wave speed (0: none)
    box_lo: np.ndarray  # per body: bounding box of the new positions [m] (the next reference grids)
    box_hi: np.ndarray
    updated: list[int] = field(default_factory=list)  # bodies whose configuration was updated
    update_time: float = 0.0  # [s] deciding and updating
    dt: float = 0.0  # [s] the step taken (an implicit step may have been halved)
    newton: NewtonReport | None = None  # the implicit solve (None: explicit)
    halvings: int = 0  # times the implicit step was halved after a failed solve
    body_speed: np.ndarray | None = None  # per body: the fastest particle [m/s] (options.track_energy; else 0)
    min_F_stretch: np.ndarray | None = None  # per body: smallest singular value of F (options.track_J; else inf)
    boundary_work: float = 0.0  # [J] work of the boundary conditions on the grid (all grids)
    kinetic: float = float("nan")  # [J] kinetic energy of the new state (options.track_energy)
    potential: float = float("nan")  # [J] its gravitational potential energy, -sum m g . x
    removed: np.ndarray | None = None  # per body: particles removed at open faces in this step (None: none)
    max_F_norm: np.ndarray | None = None  # per body: the largest |F^sn|_inf (walls-only Lagrangian scenes; else None)
    contact_nodes: int = 0  # body nodes whose bin was in contact in this step (the explicit pass, mpm.contact)
    positioned: bool = True  # the node positions were available (False: not summed, no condition could reach them)

    @property
    def reason(self) -> str | None:
        if self.newton is not None and not self.newton.converged:
            return self.newton.reason
        if self.nonfinite:
            return f"{self.nonfinite} particles have non-finite position, velocity or F"
        if self.outside:
            return f"{self.outside} particles left the domain"
        return None


class Solver:
    """Advances a :class:`State` of a :class:`Model` with a scheme."""

    def __init__(self, model: Model, scheme=None, options: SolverOptions | None = None):
        self.model = model
        scheme = scheme or EMPM()
        if isinstance(scheme, AULMPM):
            scheme = scheme.resolved(scene_kind(b.material for b in model.scene.bodies))
        self.scheme = scheme
        self.options = options or SolverOptions()
        t, k, dev = model.types, model.kernel, model.device
        S = t.scalar
        nb = len(model.scene.bodies)
        self.n_bodies = nb
        self.body_counts = np.array([c for _, c in model.body_ranges])

        # constants of the launches
        self._dx = S(model.dx)
        self._inv_dx = S(1.0 / model.dx)
        # MLS moment inverse K_p when the kernel's moment is constant (else cached per particle)
        self._K = S(1.0 / (k.moment * model.dx**2) if k.moment is not None else 0.0)
        self._grid_offsets = wp.types.vector(k.n_grids, S)(*k.grids)
        if self.options.transfer not in TRANSFERS:
            raise ValueError(f"transfer {self.options.transfer!r}; accepted: {', '.join(TRANSFERS)}")
        transfer = self.options.transfer
        self._gravity = t.vec(*model.gravity)
        margin = k.margin * model.dx
        self._inside_lo = t.vec(*([margin] * t.dim))
        self._inside_hi = t.vec(*[L - margin for L in model.domain])
        open_code = WALL_TYPES.index("open")
        self._open_lo = t.vec(*[float(c == open_code) for c in model.wall_codes[0]])
        self._open_hi = t.vec(*[float(c == open_code) for c in model.wall_codes[1]])
        self.removal = open_code in model.wall_codes[0] + model.wall_codes[1]  # open faces remove particles
        self.removed = np.zeros(nb, np.int64)  # per body: particles removed at open faces so far
        self.kept: np.ndarray | None = None  # the particles not removed, by number (None: all of them)
        eps = getattr(scheme, "epsilon", None)
        self._epsilon = S(eps if eps is not None and np.isfinite(eps) else 0.0)

        # kernels specialised for what the model holds
        self.regions = len(model.scene.regions) > 0
        solution = model.scene.solution
        self.forcing = solution if getattr(solution, "has_body_force", False) else None
        self.implicit = isinstance(self.options.integrator, Implicit)
        # the Eulerian scheme (explicit) locates the stencils in the transfers: its reference moves every step
        projections = {b.material.project for b in model.scene.bodies}
        fuse = self.options.fuse
        if fuse is None:
            fuse = k.moment is not None and len(projections) == 1
        self.fused = fuse and isinstance(scheme, EMPM) and not self.implicit
        shared = model.scene.contact == "shared"
        if shared and not isinstance(scheme, EMPM):
            raise ValueError("contact 'shared' (one grid for all bodies) needs the Eulerian scheme")
        self.contact = nb > 1 and model.scene.contact == "frictionless"
        colliders = model.scene.colliders
        self.collider_kinds = kinds_of(colliders)
        # the boundary conditions act in the grid update, or after contact or the implicit solve
        separate = self.contact or self.implicit
        # the Eulerian grid is the lattice: its node positions need no P2G sum
        self._lattice = isinstance(scheme, EMPM)
        # a moving grid needs its node positions only where a condition can reach a node: with walls
        # alone, P2G sums them only in steps where a body comes near a closed face (_positions_needed)
        self._free_flight = not (self._lattice or self.regions or colliders or self.contact or self.implicit)
        self._positions = 1
        self._reach = model.dx * max(k.offset + 1.0, k.support - 1.0 - k.offset)  # [m] largest |r_k| of a stencil
        self._band = (model.scene.wall_cells - 0.5) * model.dx  # [m] walls act on nodes closer than this
        self._closed = (np.array(model.wall_codes[0]) != open_code, np.array(model.wall_codes[1]) != open_code)
        self._domain = np.asarray(model.domain, float)  # [m]
        # fused EMPM: G2P does the configuration update too when the bodies share one projection
        # (the Eulerian scheme keeps its affine matrices: nothing to transform)
        self._g2p_commits = self.fused and len(projections) == 1 and scheme.affine == "keep"
        self._p2g = [(make_p2g(t, k, transfer, g.cls, self.regions, self.forcing is not None,
                               lagrangian=not isinstance(scheme, EMPM), with_stress=not self.implicit,
                               fused=self.fused), g)
                     for g in model.groups]
        self._g2p = make_g2p(t, k, transfer, self.options.record_dJ, scheme.tracks_marks(),
                             lagrangian=not isinstance(scheme, EMPM),
                             track_compression=any(b.material.stiffens for b in model.scene.bodies),
                             track_energy=self.options.track_energy, track_inversion=self.options.track_J,
                             removal=self.removal, fused=self.fused, bound_reach=self._free_flight,
                             commit=self._g2p_commits,
                             project=next(iter(projections)) if self._g2p_commits else None)
        self._grid_update = make_grid_update(t, not separate, self.regions, self.collider_kinds,
                                             lattice=self._lattice, n_grids=k.n_grids)
        self._contact = make_contact(t) if self.contact else ()
        self._boundary = make_boundary(t, self.regions, self.collider_kinds) if separate else None
        self._constraints = (make_constraints(t, self.regions, self.collider_kinds,
                                              any(c.friction > 0 for c in colliders))
                             if self.implicit else None)
        self._inside = make_inside_count(t, self.collider_kinds) if colliders else None
        self._collider_speed = max([c.speed() for c in colliders], default=0.0)  # [m/s], for the step
        # K_p per particle: the kernel's moment varies and the transfer has an affine term
        per_particle_K = k.moment is None and transfer != "pic"
        self._measure = make_measure(t, per_particle_K=per_particle_K)
        self._fracture = make_fracture(t)
        transform = scheme.affine == "transform"
        self._update = {b: make_update(t, k, model.scene.bodies[b].material.project, transform,
                                       gradients=transfer != "mls" or k.gradient_affine, fused=self.fused,
                                       moment=per_particle_K)
                        for b in range(nb)}

        self.launch = Launches(dev)  # the step's launches, repacking only what changed
        self.layout = GridLayout(t, k, model.dx, model.cells, nb, dev, shared=shared)
        with wp.ScopedDevice(dev):
            box = STATUS_HEADER + STATUS_PER_BODY * nb  # per-body figures, then the boxes
            n_status = box + 2 * nb * t.dim
            self.status = wp.zeros(n_status, dtype=wp.float64)
            reset = np.zeros(n_status)
            reset[STATUS_HEADER + 2 * nb: STATUS_HEADER + 4 * nb] = np.inf  # smallest J and stretch
            reset[STATUS_HEADER + STATUS_F_STRETCH * nb: STATUS_HEADER + (STATUS_F_STRETCH + 1) * nb] = np.inf
            reset[box: box + nb * t.dim] = np.inf
            reset[box + nb * t.dim:] = -np.inf
            self._status_reset = wp.array(reset, dtype=wp.float64)
            self.energy = wp.zeros(1, dtype=wp.float64)  # elastic energy seen by P2G
            # body force per unit mass [m/s^2] of a manufactured solution, set every step
            self.body_force = wp.zeros(model.n_particles if self.forcing else 1, dtype=t.vec)
            self._meshes = build_meshes(colliders, dev)  # kept alive for their ids
            self._boundary_data = self._make_boundary_data()
            self._inside_counts = wp.zeros(max(len(colliders), 1), dtype=wp.int32)
            if self.contact:  # per-body fields on the global lattice
                n_global = model.n_nodes
                self._cells = t.ivec(*model.cells)
                self._global_strides = t.ivec(*model.strides)
                self.contact_M = wp.zeros(nb * n_global, dtype=t.scalar)  # zero between steps
                self.contact_P = wp.zeros(nb * n_global, dtype=t.vec)
                self._rest_mass = wp.array([b.material.rho * model.dx**t.dim for b in model.scene.bodies],
                                           dtype=t.scalar)
                self._fill = t.scalar(model.scene.contact_fill)
            self.diagnostics = wp.zeros(len(diagnostic_names(t.dim)), dtype=wp.float64)
        self._solve = ImplicitSolve(self, self.options.integrator) if self.implicit else None
        self._backup = None  # F^0s and history before an implicit step (plastic models, for a retry)
        self._capacity = 0
        self._views = None  # (node count, grid_m, views) of _live_nodes
        self.grid_m = self.grid_v = self.grid_q = self.grid_kin = self.grid_kin_id = None
        self.time = 0.0  # [s] simulated time of the state (kinematic regions depend on it)
        self._center = np.zeros(t.dim)  # centre of mass [m]: at prepare, then at the last measure

    def _make_boundary_data(self):
        """Walls and kinematic regions (velocity, velocity gradient, centre,
        (start, end) per region) for the boundary kernels."""
        m = self.model
        t, d = m.types, m.dim
        rows = [(tuple(reg.velocity or (0.0,) * d), reg.gradient(d),
                 tuple(reg.center if reg.center is not None else 0.5 * np.add(*reg.select.bounds())),
                 (reg.start, reg.end)) for reg in m.scene.regions]
        if not rows:  # placeholders: the kernels compile the regions out
            rows = [((0.0,) * d, np.zeros((d, d)), (0.0,) * d, (0.0, 0.0))]
        data = make_boundary_data(t)()
        data.domain = t.vec(*m.domain)
        data.band = t.scalar(self._band)
        data.wall_lo = t.ivec(*m.wall_codes[0])
        data.wall_hi = t.ivec(*m.wall_codes[1])
        tables = [wp.array(np.array([r[k] for r in rows], dtype=state_dtype(m)), dtype=T)
                  for k, T in enumerate(region_types(t))]
        data.region_u, data.region_gradient, data.region_center, data.region_window = tables
        data.colliders = pack(m.scene.colliders, t, self._meshes, m.device)
        return data

    # ------------------------------------------------------------------ setup
    def kernels(self) -> list:
        ks = [k for k, _ in self._p2g] + [self._g2p, self._grid_update, self._measure,
                                          self._fracture]
        ks += list(self._contact) + ([self._boundary] if self._boundary else [])
        ks += [self._inside] if self._inside else []
        ks += [self._constraints] + self._solve.kernels() if self.implicit else []
        return ks + list(self._update.values())

    def plan(self) -> list[tuple[str, list[str]]]:
        """The stages of one step, in order, and the kernels each launches
        (what this scene compiles; an absent stage is work the scene does
        not need)."""
        def names(*ks):
            return [kernel_name(k) for k in ks if k is not None]

        sch = self.scheme
        stages = [("clear the grid", [])]
        if self.forcing is not None:
            stages.append(("body force of the closed-form solution (host)", []))
        positions = ("node positions on the lattice" if self._lattice else
                     "node positions summed only in steps near a wall" if self._free_flight else
                     "node positions summed")
        stages.append((f"P2G ({len(self._p2g)} material group(s); stencils "
                       f"{'located on the fly' if self.fused else 'from the cache'}; {positions})",
                       names(*[k for k, _ in self._p2g])))
        stages.append(("grid update: velocities, gravity, walls" + (", regions" if self.regions else "")
                       + (", colliders" if self.collider_kinds else ""), names(self._grid_update)))
        if self.implicit:
            stages.append(("implicit solve: Newton, CG", names(self._constraints, *self._solve.kernels())))
        if self.contact:
            stages.append(("contact between bodies", names(*self._contact)))
        if self._boundary is not None:
            stages.append(("boundary after contact", names(self._boundary)))
        g2p = "G2P" + (", removal at open walls" if self.removal else "") + (
            ", energy and speed for the detection" if self.options.track_energy else "") + (
            ", the configuration update" if self._g2p_commits else "")
        stages.append((g2p, names(self._g2p)))
        update = {"empm": "every step", "tlmpm": "never (initial reference)"}.get(
            sch.name, f"when the criterion fires (epsilon {getattr(sch, 'epsilon', 0):g})")
        if self._g2p_commits:
            update = "every step, in G2P; the grids follow (host); the update kernel only at the start"
        stages.append((f"configuration update: {update}", sorted(set(names(*self._update.values())))))
        stages.append(("diagnostics, fracture measure" + (", particles inside colliders" if self._inside else "")
                       + " (at logging cadence)", names(self._measure, self._fracture, self._inside)))
        return stages

    def load(self) -> float:
        """Compile (or load from the cache) every kernel this run uses; seconds taken."""
        t0 = time.perf_counter()
        modules = list({id(k.module): k.module for k in self.kernels()}.values())
        wp.force_load(device=self.model.device, modules=modules, max_workers=2)
        return time.perf_counter() - t0

    def prepare(self, state: State) -> None:
        """Take the initial positions as every body's reference configuration
        and record the neighbour pairs of the fracture measure."""
        x = state.x.numpy()
        self._positions = 1  # no bound before the first step
        self.X0 = x.astype(np.float64)  # [m] initial positions (the body force is evaluated there)
        mass = self.model.mass.numpy().astype(np.float64)
        self._center = mass @ self.X0 / mass.sum()  # the angular momentum scale's centre
        self._prepare_fracture(x)
        if self.fused:
            m = self.model
            fuse(state.stencils, m.types, m.kernel, state.X, self.layout.lo_d, self.layout.offset_d, m.dx)
        for b, (start, count) in enumerate(self.model.body_ranges):
            xb = x[start:start + count]
            self.layout.fit(b, xb.min(axis=0), xb.max(axis=0))
        self._commit_layout()
        for b in range(self.n_bodies):
            self._launch_update(state, b)

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
            report = StepReport(0.0, 0, 0, *([np.zeros(self.n_bodies)] * 8))
        else:
            self._interpolate(state, self.model.types.scalar(dt))
            report = self.check()
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
                                                     float(report.max_dJ[b]),
                                                     float(report.min_stretch[b]))]
            if report.updated:  # (G2P has moved the fused Eulerian references: only their grids follow)
                self.update_configuration(state, report.updated, report.box_lo, report.box_hi,
                                          refit_only=self._g2p_commits)
            report.update_time = time.perf_counter() - t0
            self._positions = self._positions_needed(report)
        return report

    def _positions_needed(self, report: StepReport) -> int:
        """Whether the next step's P2G must sum the node positions (1) or
        no boundary condition can reach a node (0). With walls alone (no
        regions, colliders, contact or implicit solve) a condition acts on a
        node closer than the wall band to a closed face. A node sits at a
        mass-weighted mean of x_p + F^sn r over its particles, |(F^sn r)_d| <=
        |F^sn|_inf max_k |r_k|, so every node of body b lies in its particles'
        box grown by |F^sn|_inf (1 after a configuration update) times the
        stencil's reach."""
        if not self._free_flight or report.max_F_norm is None:
            return 1
        reach = self._reach * np.maximum(report.max_F_norm, 1.0)[:, None]  # [m] per body
        lo, hi = report.box_lo - reach, report.box_hi + reach
        band = self._band + 1e-3 * self.model.dx  # with room for round-off
        near = (lo < band) & self._closed[0] | (hi > self._domain - band) & self._closed[1]
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

    def step(self, state: State, dt: float) -> NewtonReport | None:
        """Advance the grid of ``state`` by ``dt`` [s] in the current reference
        configurations, up to the grid velocities (G2P follows in
        :meth:`advance`); the implicit solve's report, or None (explicit)."""
        t0 = self.time
        self._time = self.model.types.scalar(t0)
        self.time += dt
        dt = self.model.types.scalar(dt)
        self._clear()
        if self.forcing is not None:
            self._apply_forcing(t0)
        if self.implicit and self.model.plastic:
            self._save(state)
        self._rasterize(state, dt)
        self._update_grid(dt)
        newton = None
        if self.implicit:
            newton = self._solve.solve(state, dt)
            if not newton.converged:
                self.time = t0
                return newton
        if self.contact:
            self._resolve_contact()
        if self._boundary is not None:
            self._apply_boundary()
        return newton

    def _save(self, state: State) -> None:
        """Keep F^0s and the history: P2G's return mapping overwrites them."""
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

    def _clear(self):
        """Zero the grid (the node positions unless on the lattice), the status
        buffer and the energy sum."""
        m, v, q, kin, kin_id = self._live_nodes()
        m.zero_()
        v.zero_()
        if not self._lattice and self._positions:
            q.zero_()
        if self.regions:
            kin.zero_()
            kin_id.zero_()
        wp.copy(self.status, self._status_reset)
        self.energy.zero_()

    def _live_nodes(self) -> tuple:
        """Views of the grid arrays over the layout's nodes (kept while the
        node count and the arrays stay: slicing a Warp array every step costs
        more host time than zeroing the 2D ball's grid)."""
        n = self.layout.n_nodes
        if self._views is None or self._views[0] != n or self._views[1] is not self.grid_m:
            arrays = (self.grid_m, self.grid_v, self.grid_q, self.grid_kin, self.grid_kin_id)
            self._views = (n, self.grid_m, tuple(a[:n] if len(a) >= n else a for a in arrays))
        return self._views[2]

    def _apply_forcing(self, t0: float):
        """The manufactured solution's body force at the step's start time t0 [s]."""
        b = self.forcing.body_force(self.X0, t0)
        self.body_force.assign(b.astype(state_dtype(self.model)))

    def _rasterize(self, state: State, dt, write: bool = True):
        """P2G: plastic return mapping (stored when ``write``), mass, momentum
        with the stress impulse, and node positions."""
        m = self.model
        for kernel, g in self._p2g:
            self.launch(kernel, g.count, [
                m.mass, m.volume, m.body, m.body_params, self.layout.shape_d,
                state.x, state.v, state.C, state.F0s, state.Fsn, self.body_force, state.history,
                state.stencils,
                self._dx, self._K, dt, g.start, int(write), self._positions,
                self.grid_m, self.grid_v, self.grid_q, m.region, self.grid_kin, self.grid_kin_id,
                self.energy, self.status, self.n_bodies])

    def _update_grid(self, dt):
        """Grid momentum to velocity, gravity, walls at the nodes' current positions."""
        lay = self.layout
        self.launch(self._grid_update, lay.n_nodes, [
            self.grid_m, self._gravity, dt, self._time, self._boundary_data, self.grid_kin,
            self.grid_kin_id, self.grid_v, self.grid_q, self.status,
            lay.lo_d, lay.shape_d, lay.offset_d, len(lay.lo), self._grid_offsets, self._dx, self._positions])

    def _resolve_contact(self):
        """Frictionless contact between bodies on the global lattice (its
        bins are zero between steps: ``clear`` empties the ones ``splat`` filled)."""
        splat, correct, clear = self._contact
        common = self._contact_args()
        self.launch(splat, self.layout.n_nodes, [
            self.grid_m, self.grid_v, self.grid_q, *common, self.contact_M, self.contact_P])
        self.launch(correct, self.layout.n_nodes, [
            self.grid_m, self.grid_q, *common, self._rest_mass, self._fill, self.contact_M, self.contact_P,
            self.grid_v, self.status])
        self.launch(clear, self.layout.n_nodes, [
            self.grid_m, self.grid_q, *common, self.contact_M, self.contact_P])

    def _contact_args(self) -> list:
        """What every contact pass reads: the layout's node boxes, the body
        count, the kernel's grids and the global lattice."""
        return [self.layout.offset_d, self.n_bodies, self.model.kernel.n_grids, self._inv_dx, self._cells,
                self._global_strides, self.model.n_nodes]

    def _apply_boundary(self):
        """Walls, after contact."""
        self.launch(self._boundary, self.layout.n_nodes, [
            self.grid_m, self.grid_q, self._time, self._boundary_data, self.grid_kin,
            self.grid_kin_id, self.grid_v, self.status])

    def _interpolate(self, state: State, dt):
        """G2P: velocities, affine matrices, positions, F^sn, the criterion."""
        m = self.model
        self.launch(self._g2p, m.n_particles, [
            m.body, self.layout.shape_d, self.n_bodies, self.grid_v,
            state.stencils,
            self._dx, self._K, dt, self._epsilon, self._inside_lo, self._inside_hi,
            state.x, state.v, state.C, state.Fsn, state.F0s, state.dJ, self.status, m.mass, self._gravity,
            m.volume, self._open_lo, self._open_hi, m.body_params])

    # -------------------------------------------------- configuration update
    def update_configuration(self, state: State, bodies: list[int], lo: np.ndarray,
                             hi: np.ndarray, refit_only: bool = False) -> None:
        """Move the reference configuration of ``bodies`` to the current one;
        ``lo``/``hi`` [body, axis] bound their current positions (from G2P);
        ``refit_only``: the particles' part is done (G2P's commit), fit the
        grids only."""
        for b in bodies:
            self.layout.fit(b, lo[b], hi[b])
        self._commit_layout()
        if not refit_only:
            for b in bodies:
                self._launch_update(state, b)

    def _launch_update(self, state: State, b: int) -> None:
        m = self.model
        start, count = m.body_ranges[b]
        self.launch(self._update[b], count, [
            m.body, m.body_params, self.layout.lo_d, self.layout.shape_d, self.layout.offset_d,
            self._grid_offsets, self._dx, start, state.x, state.X, state.C, state.F0s, state.Fsn,
            state.stencils])

    def _commit_layout(self) -> None:
        """Upload the boxes; grow the grid arrays (by half again) if they no longer fit."""
        self.layout.commit()
        n = self.layout.n_nodes
        if n > self._capacity:
            t = self.model.types
            self._capacity = int(1.5 * n) if self._capacity else n
            with wp.ScopedDevice(self.model.device):
                self.grid_m = wp.zeros(self._capacity, dtype=t.scalar)
                self.grid_v = wp.zeros(self._capacity, dtype=t.vec)
                self.grid_q = wp.zeros(self._capacity, dtype=t.vec)
                n_kin = self._capacity if self.regions else 1
                self.grid_kin = wp.zeros(n_kin, dtype=t.scalar)
                self.grid_kin_id = wp.zeros(n_kin, dtype=wp.int32)

    def boundary_speed(self) -> float:
        """The fastest collider or kinematic region [m/s] (a region's rotation
        and stretch bounded over the domain's diagonal)."""
        scene = self.model.scene
        diagonal = float(np.linalg.norm(scene.domain))
        regions = [float(np.linalg.norm(r.velocity if r.velocity is not None else 0.0))
                   + float(np.linalg.norm(r.gradient(scene.dim), 2)) * diagonal for r in scene.regions]
        return max([self._collider_speed] + regions)

    def displacement_dt(self, report: StepReport | None = None, max_speed: float = 0.0) -> float:
        """The implicit integrator's step limit [s]: a particle moves at most
        ``integrator.displacement`` cells per step at the speed of the last
        step (or ``max_speed`` before the first), the colliders' included;
        independent of the wave speed (mpm.timestep.displacement_dt)."""
        speed = report.max_speed if report is not None else max_speed
        return displacement_dt(self.model.dx, max(speed, self._collider_speed),
                               self.options.integrator.displacement)

    def stable_dt(self, cfl: float, report: StepReport | None = None, max_speed: float = 0.0) -> float:
        """The explicit step limit [s] after ``report``'s step (at rest without
        one): the smallest of :meth:`step_limits` over the bodies."""
        return min(lim.dt for lim in self.step_limits(cfl, report, max_speed))

    def step_limits(self, cfl: float, report: StepReport | None = None,
                    max_speed: float = 0.0) -> list[StepLimits]:
        """Per body, the terms of the step limit (mpm.timestep): the wave
        speed c(J_min) at the most compressed particle (grown by a stiffening
        material's factor), the narrowest reference cell s_min dx, viscous
        diffusion and the strain rate."""
        m = self.model
        limits = []
        for b, body in enumerate(m.scene.bodies):
            J, s, stiffening, rate = 1.0, 1.0, 1.0, 0.0
            if report is not None:
                J = float(report.min_J[b]) if np.isfinite(report.min_J[b]) else 1.0
                s = float(report.min_stretch[b]) if np.isfinite(report.min_stretch[b]) else 1.0
                if report.stiffening[b] > 0 and np.isfinite(report.stiffening[b]):
                    stiffening = float(report.stiffening[b])
                rate = float(report.max_rate[b])
            speed = report.max_speed if report is not None else max_speed
            speed = max(speed, self._collider_speed)
            c = body.material.wave_speed(min(max(J, 1e-3), 1.0)) * np.sqrt(stiffening)
            limits.append(step_limits(m.dx, min(max(s, 1e-3), 1.0), c, speed, cfl,
                                      body.material.kinematic_viscosity(), m.dim, rate))
        return limits

    # ------------------------------------------------------------ read back
    def check(self) -> StepReport:
        """Stability figures and criterion counts of the last step (one small
        device-to-host copy)."""
        s = self.status.numpy()
        nb, d = self.n_bodies, self.model.dim
        field_ = s[STATUS_HEADER:STATUS_HEADER + STATUS_PER_BODY * nb].reshape(STATUS_PER_BODY, nb)
        box = s[STATUS_HEADER + STATUS_PER_BODY * nb:].reshape(2, nb, d)
        return StepReport(
            max_speed=float(np.sqrt(s[STATUS_MAX_V2])), nonfinite=int(s[STATUS_NONFINITE]),
            outside=int(s[STATUS_OUTSIDE]), marked=field_[0].astype(np.int64),
            max_dJ=field_[1].copy(), min_J=field_[2].copy(), min_stretch=np.sqrt(field_[3]),
            max_rate=np.sqrt(field_[4]), stiffening=field_[5].copy(), box_lo=box[0].copy(),
            box_hi=box[1].copy(), body_speed=np.sqrt(field_[STATUS_SPEED]),
            min_F_stretch=np.sqrt(field_[STATUS_F_STRETCH]),
            max_F_norm=field_[STATUS_F_NORM].copy() if self._free_flight else None,
            boundary_work=float(s[STATUS_WORK]), contact_nodes=int(s[STATUS_CONTACT]),
            removed=np.zeros(nb, np.int64) if s[STATUS_REMOVED] > 0 else None,
            kinetic=float(s[STATUS_KINETIC]) if self.options.track_energy else float("nan"),
            potential=float(s[STATUS_POTENTIAL]) if self.options.track_energy else float("nan"))

    def _prepare_fracture(self, x: np.ndarray) -> None:
        m = self.model
        scene = m.scene
        spacing = np.array([scene.particle_dx / (b.ppc or scene.ppc) ** (1.0 / m.dim) for b in scene.bodies])
        body = m.body.numpy()
        p, q = neighbour_pairs(x, body, 1.5 * spacing)
        self.pair_counts = np.bincount(body[p], minlength=self.n_bodies)
        with wp.ScopedDevice(m.device):
            self._pair_p = wp.array(p, dtype=wp.int32)
            self._pair_q = wp.array(q, dtype=wp.int32)
            self._pair_offset = wp.array((x[q] - x[p]).astype(state_dtype(m)), dtype=m.types.vec)
            self._broken = wp.zeros(self.n_bodies, dtype=wp.float64)
            self._pair_broken = wp.zeros(len(p), dtype=wp.uint8)

    def fracture(self, state: State) -> np.ndarray:
        """Fraction of initially neighbouring pairs broken, per body (mpm.fracture)."""
        m = self.model
        self._broken.zero_()
        if len(self._pair_p):
            wp.launch(self._fracture, len(self._pair_p), device=m.device, inputs=[
                self._pair_p, self._pair_q, self._pair_offset, m.body, state.x, state.F0s,
                state.Fsn, self._dx, self._broken, self._pair_broken])
        return self._broken.numpy() / np.maximum(self.pair_counts, 1)

    def fragments(self) -> np.ndarray:
        """Pieces per body (connected components of its intact neighbour
        pairs) at the last :meth:`fracture` evaluation."""
        intact = self._pair_broken.numpy() == 0
        label = fragments(self.model.n_particles, self._pair_p.numpy(), self._pair_q.numpy(), intact)
        body = self.model.body.numpy()
        return np.array([len(np.unique(label[body == b])) for b in range(self.n_bodies)])

    def inside_colliders(self, state: State) -> np.ndarray:
        """Per collider, the particles deeper inside it than INSIDE_DEPTH cells."""
        m = self.model
        if self._inside is None:
            return np.zeros(0, np.int64)
        self._inside_counts.zero_()
        wp.launch(self._inside, m.n_particles, device=m.device, inputs=[
            state.x, m.types.scalar(self.time), m.types.scalar(INSIDE_DEPTH * m.dx),
            self._boundary_data.colliders, self._inside_counts])
        return self._inside_counts.numpy()[:len(m.scene.colliders)].astype(np.int64)

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
        D = m.types.scalar(m.kernel.moment * m.dx**2 if m.kernel.moment is not None else 0.0)
        self.launch(self._measure, m.n_particles, [
            m.mass, state.x, state.v, state.C, state.Fsn, D, state.stencils.K, self._gravity,
            m.types.vec(*self._center), self.diagnostics])
        out = about_center_of_mass(self.diagnostics.numpy(), m.dim)
        names = self.diagnostic_names()
        i = names.index("center_of_mass_x")
        self._center = out[i:i + m.dim].copy()
        i = names.index("elastic_energy")
        if elastic:
            self._clear()
            self._rasterize(state, m.types.scalar(0.0), write=False)
            out[i] = self.step_energy()
        else:
            out[i] = np.nan
        return out

    def diagnostic_names(self) -> list[str]:
        return diagnostic_names(self.model.dim)

    def memory_bytes(self, state: State) -> int:
        """Bytes of the Warp arrays of the model, ``state`` and the solver
        (grids at their current capacity, caches, scratch; mpm.memory)."""
        return array_bytes(self.model, state, self)


def state_dtype(model: Model):
    return np.float32 if model.types.precision == "float32" else np.float64
