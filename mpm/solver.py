"""The MPM step, as a short list of named stages.

One formulation serves every scheme (mpm.schemes): each body has its own
reference grid (mpm.reference_grids); a step rasterises the particles to it (mpm.p2g),
updates the nodal velocities - forward Euler, or backward Euler by Newton's
method (mpm.integrators, mpm.implicit) - applies contact (mpm.contact) and
the boundary conditions (mpm.conditions), interpolates back (mpm.g2p), and
the criterion (mpm.stepping.criterion) decides the configuration updates
(mpm.reference_update) on the device.

Every stage reads the step and the time from the device's control block
(mpm.stepping.status), so a step needs nothing from the host: :class:`mpm.Driver`
runs k steps and reads back once. :meth:`Solver.advance` is the host's
single step (the time and step given, the figures read back), for scripts
and tests that step by hand.

The solver compiles only what the model uses (mpm.stepping.plan lists it): one P2G
per material model present, one configuration update per body's
projection, one G2P, grid update and diagnostics kernel for the dimension
and precision; contact, separate boundary passes and the implicit
integrator's kernels only when the scene needs them.
"""

import dataclasses
import time
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from .conditions import Conditions, Removals, needs_gradients
from .reference_update import References
from .contact.passes import Contact
from .stepping.criterion import Criterion
from .diagnostics import Diagnostics, diagnostic_names
from .elastic_contact import elastic
from .fracture import FractureMeasure
from .implicit.solve import ImplicitSolve, NewtonReport
from .integrators import Explicit, Implicit
from .launch import Launches, load
from .reference_grids import GridArrays, GridLayout
from .memory import array_bytes
from .model import Model, State
from .precision import compensates, for_policy
from .params import instance_problem, violations
from .rigid import solids
from .schemes import AULMPM, EMPM, TLMPM, scene_kind
from .stepping.status import StepBuffer, StepReport
from .stencil import fuse
from .stepping.timestep import StepRule
from .transfer import AFFINE_FREE, TRANSFERS, GridConstants, Transfers


@dataclass
class SolverOptions:
    """How a :class:`Solver` steps: the transfer, the integrator, what each
    step measures. The defaults work with :class:`mpm.Driver`'s defaults
    (its blow-up detection reads the tracked energies and, for models that
    cannot invert, det F)."""

    record_dJ: bool = False
    """write the per-particle dJ field every step (for logging)"""
    transfer: str = "mls"
    """mls | apic | pic | flip (mpm.transfer.TRANSFERS)"""
    flip: float = 0.95
    """the flip transfer's blend: the share of the particle's velocity updated
    by the grid's change (1: FLIP, 0: PIC)"""
    integrator: Explicit | Implicit = field(default_factory=Explicit)
    """forward or backward Euler on the grid velocities (mpm.integrators)"""
    track_J: bool | None = None
    """report every body's smallest det F and smallest singular value of F
    (for inversion detection, mpm.stepping.detection); None: where a body's
    model cannot invert (what :class:`mpm.Driver`'s default detection reads)"""
    track_energy: bool | None = None
    """report the new state's kinetic and potential energy and each body's
    fastest particle every step (mpm.stepping.detection); None: on (the
    default detection of :class:`mpm.Driver` needs it; False saves a few
    atomic sums per particle when the detection is off)"""
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
    batched: bool = False
    """compile the early exits and the device's configuration updates that
    let :class:`mpm.Driver` run several steps between two read-backs
    (its ``sync_every`` > 1; explicit integrator only)"""
    compensate: bool | None = None
    """keep the positions and the deformation gradient as compensated (Kahan)
    sums in G2P (mpm.g2p), so that a step's increments below the precision's
    spacing (mpm.precision) are not rounded away: float32 then gives
    float64's result where a step's strain is below float32's 2^-24 (the
    small-deflection cantilevers), for 0-8 % more time a step and 24 (2D) or
    48 (3D) bytes more a particle. None: on exactly when the precision is
    float32 and :func:`mpm.precision.resolution` (its default step) finds the
    scene unresolved; True/False force it (False: the code and results of a
    run without it, bit for bit). With it the Eulerian scheme runs fused
    (``fuse`` None), where G2P commits F^0s as a compensated sum; its F^0s is
    not compensated where the update is a pass of its own (``fuse`` False,
    the implicit integrator, bodies with different projections) nor where a
    projection (a fluid's, a plastic model's) rewrites it: x's sum is."""

    def check(self) -> None:
        """ValueError naming the option for a transfer or blend out of range."""
        if self.transfer not in TRANSFERS:
            raise ValueError(f"options.transfer: {self.transfer!r}; accepted: {', '.join(TRANSFERS)}")
        if not 0.0 <= self.flip <= 1.0:
            raise ValueError(f"options.flip: {self.flip!r}; accepted: 0 <= flip <= 1")


def _check_part(key: str, value, classes: tuple, what: str, example: str) -> None:
    """TypeError unless ``value`` is an instance of ``classes``; ValueError for
    a field out of its range (mpm.params) or one of its ``problems()``."""
    problem = instance_problem(value, classes, what, example)
    if problem:
        raise TypeError(f"{key}: {problem}")
    for name, given, accepted in violations(value):
        raise ValueError(f"{key}.{name}: {given!r}; accepted: {accepted}")
    for name, message in value.problems():
        raise ValueError(f"{key}.{name}: {message}")


def check_solver_inputs(model, scheme, options) -> None:
    """TypeError or ValueError, one line naming the argument, for a model
    that is not mpm.build's, a scheme or options that are not instances
    (a class given for its instance, a name), or out of range."""
    problem = instance_problem(model, Model, "the Model of mpm.build", "mpm.build(scene, mpm.QUADRATIC)[0]")
    if problem:
        raise TypeError(f"model: {problem}")
    if scheme is not None:
        _check_part("scheme", scheme, (EMPM, TLMPM, AULMPM), "a scheme instance",
                    "mpm.EMPM(), mpm.TLMPM(), mpm.AULMPM()")
    if options is not None:
        problem = instance_problem(options, SolverOptions, "SolverOptions", "mpm.SolverOptions(transfer='apic')")
        if problem:
            raise TypeError(f"options: {problem}")
        _check_part("options.integrator", options.integrator, (Explicit, Implicit), "an integrator instance",
                    "mpm.Explicit(), mpm.Implicit()")
        options.check()
    scene = model.scene
    if scene.contact == "shared" and scheme is not None and not isinstance(scheme, EMPM):
        raise ValueError("scheme: contact 'shared' (one grid for all bodies) needs the Eulerian scheme; "
                         "accepted: mpm.EMPM()")
    if options is not None and isinstance(options.integrator, Implicit) and (
            getattr(scene, "joints", None) or getattr(scene, "rigid_contact", "none") != "none"):
        raise ValueError("options.integrator: joints and rigid contact (mpm.joints, mpm.rigid_contact) are "
                         "advanced under the explicit integrator only; accepted: mpm.Explicit(), or no joints "
                         "and rigid_contact 'none'")
    if options is not None and isinstance(options.integrator, Implicit) and (elastic(scene)
                                                                             or scene.contact == "elastic"):
        raise ValueError("options.integrator: elastic colliders and contact (boundary or contact 'elastic', "
                         "mpm.elastic_contact, mpm.body_springs) act under the explicit integrator only; accepted: "
                         "mpm.Explicit(), or no boundary or contact 'elastic'")
    if options is not None and options.batched and (isinstance(options.integrator, Implicit) or getattr(
            scene.solution, "has_body_force", False)):
        raise ValueError("options.batched: batched steps need the explicit integrator and no host-side body "
                         "force; accepted: batched=False")


def resolved_scheme(scheme, scene):
    """The scheme a solver steps by: EMPM for None, A-ULMPM's null parameters
    taken for the scene's kind (mpm.schemes.scene_kind)."""
    scheme = scheme or EMPM()
    if isinstance(scheme, AULMPM):
        scheme = scheme.resolved(scene_kind(b.material for b in scene.bodies))
    return scheme


def fit(solver, policy) -> None:
    """:meth:`Solver.fit`: where ``compensate`` was left to the solver and
    ``policy``'s step decides otherwise than the default policy's, the
    solver is built again with the decision (nothing is compiled before a
    run starts, so this costs only the allocations)."""
    scheme, options = solver.given
    if options is not None and options.compensate is not None:
        return
    model = solver.model
    decided = resolved(options or SolverOptions(), model.scene, model.types.precision, policy).compensate
    if decided != solver.options.compensate:
        solver.__init__(model, scheme, options, policy)


def resolved(options: SolverOptions, scene, precision: str = "float32", policy=None) -> SolverOptions:
    """``options`` with the tracking and the compensation left to the solver (None)
    decided for ``scene`` in ``precision``, at the step of ``policy`` (an
    mpm.StepPolicy; None: its defaults) and the integrator (mpm.precision.for_policy)."""
    compensate = options.compensate
    if compensate is None:
        compensate = compensates(None, precision, for_policy(scene, precision, policy, options.integrator))
    return dataclasses.replace(
        options, track_energy=True if options.track_energy is None else options.track_energy,
        track_J=(any(not b.material.invertible for b in scene.bodies) if options.track_J is None
                 else options.track_J), compensate=compensate)


class Solver:
    """Advances a :class:`State` of a :class:`Model` with a scheme. Its parts are public: ``layout``,
    ``grid``, ``const``, ``buffer`` (mpm.stepping.status), ``transfers``, ``conditions``, ``contact`` (or None),
    ``references``, ``criterion``, ``implicit`` (or None), ``timestep`` (the host's step rule),
    ``removals``, ``fracture``, ``diagnostics``. :meth:`prepare` a state before stepping it."""

    def __init__(self, model: Model, scheme=None, options: SolverOptions | None = None, policy=None):
        check_solver_inputs(model, scheme, options)
        self.model, self.given = model, (scheme, options)  # (as given: Solver.fit decides again)
        scheme = resolved_scheme(scheme, model.scene)
        self.scheme, self.options = scheme, resolved(options or SolverOptions(), model.scene, model.types.precision,
                                                     policy)
        opt, t, k, dev, scene = self.options, model.types, model.kernel, model.device, model.scene
        implicit, eulerian, batched = isinstance(opt.integrator, Implicit), isinstance(scheme, EMPM), opt.batched
        forcing = scene.solution if getattr(scene.solution, "has_body_force", False) else None
        nb = self.n_bodies = len(scene.bodies)
        self.removals = Removals(model)  # particles removed at open faces
        self.launch = Launches(dev)  # the step's launches, repacking only what changed
        self.const = GridConstants.of(model)
        self.layout = GridLayout(t, k, model.dx, model.cells, nb, dev, shared=scene.contact == "shared")
        self.grid = GridArrays(t, dev, regions=len(scene.regions) > 0, flip=opt.transfer == "flip", layout=self.layout,
                               gradients=needs_gradients(scene))  # the conditions read the velocity gradients
        self.buffer = StepBuffer(nb, t.dim, len(diagnostic_names(t.dim)), dev, n_loads=model.n_loads,
                                 n_colliders=len(solids(scene)))
        self.contact = (Contact(model, self.launch, implicit, self.buffer.control, batched, lagrangian=not eulerian)
                        if nb > 1 and scene.contact in ("frictionless", "friction") else None)
        # the conditions act in the grid update, or after contact or the implicit solve
        self.conditions = Conditions(model, self.launch, self.buffer.control, implicit=implicit, lattice=eulerian,
                                     separate=self.contact is not None or implicit, batched=batched)
        # node positions only where a condition can reach a node (walls alone: near a face, mpm.stepping.criterion)
        self.free_flight = not (eulerian or self.conditions.regions or solids(scene) or self.contact or implicit)
        projections = {b.material.project for b in scene.bodies}
        fused = opt.fuse if opt.fuse is not None else (k.moment is not None or opt.compensate) and len(projections) == 1
        self.fused = bool(fused and eulerian and not implicit)
        # fused EMPM: G2P does the configuration update too when the bodies share one projection
        self.g2p_commits = self.fused and len(projections) == 1 and scheme.affine == "keep"
        self.transfers = Transfers(
            model, self.launch, self.buffer, opt.transfer, lagrangian=not eulerian, fused=self.fused,
            commit=self.g2p_commits, with_stress=not implicit, regions=self.conditions.regions, forcing=forcing,
            record_dJ=opt.record_dJ, marks=scheme.tracks_marks(), epsilon=getattr(scheme, "epsilon", None) or 0.0,
            track_energy=bool(opt.track_energy), track_J=bool(opt.track_J), removal=self.conditions.open,
            bound_reach=self.free_flight, project=next(iter(projections)) if self.g2p_commits else None,
            batched=batched, flip=opt.flip, compensate=bool(opt.compensate), gradients=self.grid.gradients,
            boundary=self.conditions.data, keep_out=self.conditions.keep_out, rigid=self.conditions.rigid)
        per_particle_K = k.moment is None and opt.transfer not in AFFINE_FREE  # K_p cached per particle
        self.references = References(model, self.launch, self.layout, self.grid, self.buffer.control,
                                     affine=str(scheme.affine), gradients=opt.transfer != "mls" or k.gradient_affine,
                                     fused=self.fused, moment=per_particle_K, compensate=bool(opt.compensate))
        self.criterion = Criterion(model, self.launch, self.buffer, self.layout, scheme, self.conditions,
                                   free_flight=self.free_flight, commits=self.g2p_commits, batched=batched)
        self.diagnostics = Diagnostics(model, self.launch, self.buffer, per_particle_K, batched)
        self.fracture = FractureMeasure(model)
        self.implicit = ImplicitSolve(self, opt.integrator) if implicit else None
        self.timestep = StepRule(model, self.conditions.collider_speed)
        self.device_moves = batched and not self.g2p_commits and scheme.name != "tlmpm"  # (batches; a moving scheme)
        self.pad = 0.0  # [m] grids grown by this much on every side at a refit (batches: room for k steps)
        self.time = 0.0  # [s] simulated time of the state, on the host (the device's is control.t)
        self.X0 = None  # [m] initial positions, float64 (after prepare)
        self.buffer.set(alive=self.removals.counts)

    # ------------------------------------------------------------------ setup
    def fit(self, policy) -> None:
        """Decide for the step ``policy`` (mpm.Driver's) what the options left to the solver (:func:`fit`)."""
        fit(self, policy)

    def kernels(self) -> list:
        """Every kernel this run compiles."""
        parts = [self.transfers, self.conditions, self.contact, self.implicit]
        return ([k for part in parts if part is not None for k in part.kernels()]
                + self.references.kernels() + (self.references.kernels(gated=True) if self.device_moves else [])
                + [self.criterion.kernel, self.diagnostics.kernel, self.fracture.kernel])

    def load(self) -> float:
        """Compile (or load from the cache) every kernel this run uses; seconds taken."""
        return load(self.kernels(), self.model.device)

    def prepare(self, state: State) -> None:
        """Take the initial positions as every body's reference, and the fracture measure's neighbour pairs."""
        m, x = self.model, state.x.numpy()
        self.buffer.set(positions=1.0)  # no bound before the first step
        self.X0 = x.astype(np.float64)
        self.diagnostics.prepare(self.X0)
        self.fracture.prepare(x)
        state.stencils.offset = self.layout.offset_d  # (the cached stencils are relative to their boxes)
        state.compensated(bool(self.options.compensate))  # (the sums' running errors, where it compensates)
        if self.fused:
            fuse(state.stencils, m.types, m.kernel, state.X, self.layout.lo_d, self.layout.offset_d, m.dx)
        lo = [x[s:s + c].min(axis=0) for s, c in m.body_ranges]
        hi = [x[s:s + c].max(axis=0) for s, c in m.body_ranges]
        self.references.fit(range(self.n_bodies), lo, hi, self.pad)
        self.references.move(state, range(self.n_bodies), self.const)

    def restored(self, state: State) -> None:
        """After mpm.checkpoint restored the state and the parts: the grid sized to the restored layout."""
        self.grid.reserve(self.layout.n_nodes)

    # ------------------------------------------------------------------ a step on the device
    def attempt(self, state: State) -> NewtonReport | None:
        """Advance the grid of ``state`` by the device's step (``control.dt``, from ``control.t``) in the current
        reference configurations, up to the grid velocities; the implicit solve's report, or None (explicit)."""
        self.step_time = self.model.types.scalar(self.time)  # the implicit constraints' clock [s]
        self.buffer.reset()
        self.conditions.place(self.buffer.status)  # the rigid bodies at their pose
        self._clear()
        self._apply_forcing(state)
        self._rasterize(state)
        self._update_grid()
        newton = self._solve(state)
        if newton is not None and not newton.converged:
            return newton
        self._resolve_contact()
        self._apply_boundary()
        return newton

    def interpolate(self, state: State) -> None:
        """G2P (mpm.g2p): velocities, affine matrices, positions, F^sn, the step's figures."""
        self.transfers.interpolate(state, self.grid, self.layout, self.const)

    def decide(self) -> None:
        """The criterion: configuration updates, alive counts, positions (mpm.stepping.criterion)."""
        self.criterion.decide()

    def move(self, state: State) -> None:
        """The configuration updates the criterion asked for, where the grids cover them (batches)."""
        if self.device_moves:
            self.references.move(state, range(self.n_bodies), self.const, gated=True)

    # the stages of an attempt
    def _clear(self) -> None:
        """Zero the grid (the node positions unless on the lattice or not summed)."""
        self.grid.clear(self.layout.n_nodes, positions=not isinstance(self.scheme, EMPM))

    def _apply_forcing(self, state: State) -> None:
        """The body force at the step's start: loads', a manufactured solution's, springs' (mpm.elastic_contact)."""
        if self.transfers.forced:
            self.transfers.apply_forcing(state, cast(np.ndarray, self.X0), self.time)  # (set by prepare)

    def _rasterize(self, state: State, write: bool = True) -> None:
        """P2G (mpm.p2g); the plastic return mapping stored when ``write``."""
        self.transfers.rasterize(state, self.grid, self.layout, self.const, write)

    def _update_grid(self) -> None:
        """Momentum to velocity, gravity, and the conditions unless they come later."""
        self.conditions.update_grid(self.grid, self.layout, self.const, self.buffer.status)

    def _solve(self, state: State) -> NewtonReport | None:
        """Backward Euler by Newton's method (mpm.implicit); None when explicit."""
        if self.implicit is None:
            return None
        return self.implicit.solve(state, self.model.types.scalar(self.dt))

    def _resolve_contact(self) -> None:
        """Contact between bodies (mpm.contact)."""
        if self.contact is not None:
            self.contact.resolve(self.grid, self.layout, self.buffer.status)

    def _apply_boundary(self) -> None:
        """The conditions after contact or the implicit solve."""
        if self.conditions.boundary is not None:
            self.conditions.apply(self.grid, self.layout, self.buffer.status)

    # ------------------------------------------------------------------ the host's side
    def advance(self, state: State, dt: float, halvings: int = 0) -> StepReport:
        """One step of ``dt`` [s] from ``self.time``, then the configuration
        updates the scheme asks for. An implicit step whose Newton solve
        fails is retried with half the step up to ``halvings`` times (the
        state is restored first); ``report.dt`` is the step taken."""
        if self.X0 is None:
            raise RuntimeError("Solver.advance: call Solver.prepare(state) first (it takes the references)")
        self.schedule(dt)
        newton, dt, attempts = self.solve_step(state, dt, halvings)
        if newton is not None and not newton.converged:
            report = StepReport.failed(self.n_bodies, self.model.dim)
        else:
            self.interpolate(state)
            self.decide()
            self.move(state)
            report = self.report()
            self.time += dt
        report.dt, report.newton, report.halvings = dt, newton, attempts
        self.settle(state, report)
        return report

    def schedule(self, dt: float) -> None:
        """The device's next step: ``dt`` [s] from the host's time (for :meth:`attempt` by hand)."""
        self.dt = dt
        self.buffer.set(t=self.time, dt=dt)

    def solve_step(self, state: State, dt: float, halvings: int) -> tuple[NewtonReport | None, float, int]:
        """:meth:`attempt` with up to ``halvings`` retries at half the step after a failed solve or a
        near miss (the device's ``control.dt`` follows; a plastic state restored first); (report, step
        taken, retries)."""
        if self.implicit is not None:
            self.implicit.save(state)
        for attempt in range(halvings + 1):
            self.dt = dt
            newton = self.attempt(state)
            if newton is None or newton.outcome == "converged" or attempt == halvings or self.implicit is None:
                break
            self.implicit.restore(state)
            dt *= 0.5
            self.buffer.set(dt=dt)
        if newton is not None and not newton.converged and self.implicit is not None:
            self.implicit.restore(state)  # the state the failed step started from
        return newton, dt, attempt

    def settle(self, state: State, report: StepReport) -> None:
        """The host's part of a completed step: the particles removed at open
        faces, and the configuration updates the device left to it (every
        update when the steps are not batched: the grids follow tightly)."""
        self.removals.add(report)
        self.removals.refresh()
        if report.reason is not None:
            return
        t0 = time.perf_counter()
        bodies = report.regrid if self.options.batched else report.updated
        if bodies:
            self.references.fit(bodies, report.box_lo, report.box_hi, self.pad)
            if not self.g2p_commits:  # (G2P has moved the fused Eulerian references)
                self.references.move(state, bodies, self.const)
        if report.host_update or report.regrid:
            self.buffer.set(host_update=0.0, regrid=np.zeros(self.n_bodies))
        report.update_time = time.perf_counter() - t0

    def report(self, values: dict | None = None) -> StepReport:
        """The step's report: the buffer read back, or a history row's ``values``."""
        v = values if values is not None else self.buffer.read()
        return StepReport.of(v, self.model.dim, energy=bool(self.options.track_energy), reach=self.free_flight)

    def step_energy(self) -> float:
        """Elastic energy [J] of the state the last step started from (its P2G)."""
        return float(self.buffer.view("elastic").numpy()[0])

    def measure(self, state: State, elastic: bool = True) -> np.ndarray:
        """Diagnostics of ``state`` in the order of mpm.diagnostics.diagnostic_names
        (float64). ``elastic=False`` leaves the elastic energy NaN (take it
        from the next step's P2G); ``elastic=True`` runs a P2G pass for it,
        which overwrites the scratch grid (harmless between steps)."""
        out = self.diagnostics.measure(state)
        if elastic:
            self.buffer.reset()
            self._clear()
            self._rasterize(state, write=False)
            out[self.diagnostics.names.index("elastic_energy")] = self.step_energy()
        return out

    def memory_bytes(self, state: State) -> int:
        """Bytes of the model's, the state's and the solver's Warp arrays (mpm.memory)."""
        return array_bytes(self.model, state, self)
