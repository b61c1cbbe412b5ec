"""The pipeline's observer of a run (mpm.stepping.driver): what a step leaves in the
recording (scalars, particle frames, events, the fracture measure) and in
``metrics.json``.

The solver and the driver never see a sink: :class:`Recorder` turns what the
driver reports into rows and events of a :class:`pipelines.sinks.Sink`, and
summarises the run at the end (:meth:`Recorder.finish`).
"""

from __future__ import annotations

import math
import sys
import threading
import time
from pathlib import Path
from typing import cast

import numpy as np

import mpm
from mpm import analytic

from . import announce, run_metrics
from .progress import Progress
from .collider_track import ColliderForces
from .load_track import LoadTrack
from .rigid_track import RigidTrack
from .run_metrics import ClosedForm, Drift, median, particle_fields, peak_rss_mb
from ..config.validate import RunSpec
from ..recording.sinks import RunMeta, Sink


class Recorder(mpm.Observer):
    """One run's recording and metrics: builds the model and solver of
    ``spec`` (:meth:`build`), observes the driver, and writes the summary
    into ``metrics`` (:meth:`finish`)."""

    solver: mpm.Solver  # these three: made by build(), read once it has run
    state: mpm.State
    drift: Drift
    solution: ClosedForm | None  # closed-form solution of the scene, if any (mpm.analytic)
    X0: np.ndarray  # made by on_start

    def __init__(self, spec: RunSpec, out_dir: Path, properties: dict, sink: Sink):
        self.spec, self.out_dir, self.properties, self.sink = spec, out_dir, properties, sink
        self.metrics: dict = {"status": "failed", "reason": "did not start", "steps": 0, "sim_time": 0.0}
        self.driver: mpm.Driver | None = None
        self.built = False  # build() completed: finish() may summarise the run
        self.step_ms: list[float] = []
        self.log_ms: list[float] = []
        self.update_ms: list[float] = []
        self.newton: list[tuple] = []  # per step: Newton and CG iterations, residual, a near miss
        self.fracture = None  # (overall, per body) at the last evaluation
        self.fracture_step = -1
        self._pieces = None  # (fracture per body, fragments per body) at the last count
        self.inside_max = None  # per collider: the most particles seen inside it
        self.loads: LoadTrack | None = None  # the external loads' track
        self.forces: ColliderForces | None = None  # the colliders' forces
        self.rigid: RigidTrack | None = None  # the rigid bodies' states and forces
        self.solution = None
        self.error_last: dict | None = None
        self._error_step = -1
        self._pending: list = []  # the last state's scalar row, waiting for its elastic energy
        self.progress: Progress | None = None
        self.started = False  # the driver reported the initial state: finish() may summarise the state

    @property
    def step(self) -> int:
        return self.driver.step if self.driver is not None else 0

    @property
    def t(self) -> float:
        return self.driver.time if self.driver is not None else 0.0

    # ------------------------------------------------------------ build
    def build(self, policy: mpm.StepPolicy, options: mpm.SolverOptions, sync_every: int = 1,
              graph: bool | None = None) -> None:
        """The model, the state, the solver (compiled) and the driver (reading
        back every ``sync_every`` steps; ``graph``: as a CUDA graph)."""
        spec, run, log = self.spec, self.spec.run, self.spec.log  # (the checked particles: not sampled again)
        self.model, self.state = mpm.build(spec.scene, spec.kernel, run.precision, run.device, spec.seed,
                                           samples=spec.take_samples())
        self.solver = mpm.Solver(self.model, spec.scheme, options)
        self.implicit = self.solver.implicit is not None
        self.scheme = self.solver.scheme  # defaults resolved
        self.metrics.update(particles=self.model.n_particles, domain_nodes=self.model.n_nodes,
                            scene=spec.scene_name, resolution=spec.scene.resolution, dx=self.model.dx,
                            precision=run.precision, device=run.device,
                            body_volumes={b.name or f"body{i}": v for i, (b, v) in
                                          enumerate(zip(spec.scene.bodies, self.model.body_volumes))})
        # a first run compiles its kernels (Warp caches them): say so when it takes a while
        notice = threading.Timer(1.0, lambda: print("compiling kernels (first run only; Warp caches them) ...",
                                                    file=sys.stderr, flush=True))
        if Progress.shown(log.progress):
            notice.start()
        self.driver = mpm.Driver(self.solver, self.state, policy, spec.detect, [self], sync_every=sync_every,
                                 graph=graph, measure=log.scalars)
        try:
            self.metrics["compile_time_s"] = self.driver.load()
        finally:
            notice.cancel()
        self.mass0 = self.model.mass.numpy().astype(np.float64)  # [kg] (removed particles' mass becomes 0)
        self.solution = cast("ClosedForm | None", spec.scene.solution)  # one of mpm.analytic's (config.scene)
        self.error_max = {"displacement": 0.0, "velocity": 0.0}
        self.names = self.solver.diagnostics.names
        self.drift = Drift(self.names)
        bodies = [b.name for b in spec.scene.bodies]

        def per_body(name: str) -> list[str]:  # one scalar, or one per body
            return [name] if len(bodies) == 1 else [f"{name}/{b}" for b in bodies]

        self.marked_names = per_body("marked_fraction")
        self.stretch_names = per_body("min_stretch")
        self.updates = np.zeros(len(bodies), np.int64)
        self.update_steps = 0  # steps at which at least one body was updated
        self.contact_work = 0.0  # [J] the contact's work on the grid so far (mpm.contact; <= 0)
        self.responses = mpm.responses.Tracker(spec.responses, self.model) if spec.responses else None
        self.metrics["sync_every"] = self.driver.k
        self.built = True

    def meta(self) -> RunMeta:
        return announce.run_meta(self)

    # ------------------------------------------------------------ the driver's reports
    def on_start(self, driver: mpm.Driver) -> None:
        """The initial state: its scalars, particles, fracture measure, and the scheme's announcement."""
        log = self.spec.log
        self.on_resume(driver)
        assert driver.initial is not None  # measured by driver.start() before it reports
        self._pending[:] = [0, 0.0, driver.initial.copy(), {
            "config_updates": 0.0, **(self.errors() if self.solution is not None else {})}]
        if log.particles:
            self.particles()
            self._next_frame = 1.0 / log.fps
        self.log_fracture()
        if self.responses is not None:
            self.responses.update(self.state.x.numpy(), self.t, self.solver.removals.kept)
        self.announce_scheme()
        if driver.running and 0.0 < driver.dt < math.inf:
            self.warn_size(driver.dt)

    def on_resume(self, driver: mpm.Driver) -> None:
        """The parts a run's tracks need, nothing logged (after a checkpoint's restore, the tracks' own
        state comes back from it: pipelines.run.checkpoints)."""
        self.started = True
        assert self.solver.X0 is not None  # the driver prepared the solver
        self.X0 = self.solver.X0  # initial positions [m], float64
        self.loads = LoadTrack(self.model, self.X0) if self.model.loads is not None else None
        self.forces = (ColliderForces(self.collider_names(), self.model.dim, self.model.kernel.n_grids)
                       if self.spec.scene.colliders else None)
        coupler = self.solver.conditions.rigid
        self.rigid = RigidTrack(self.spec.scene, coupler, self.model.kernel.n_grids) if coupler is not None else None
        self.progress = Progress(*self.spec.end, self.spec.log.progress)
        self.metrics["status"], self.metrics["reason"] = "running", ""

    def on_step(self, driver: mpm.Driver, report: mpm.StepReport) -> None:
        """A completed step: the last state's scalar row, events, this state's
        row, a particle frame when due, the fracture measure every
        log.fracture_every steps."""
        log = self.spec.log
        self.step_ms.append(1e3 * report.wall_time)
        self.update_ms.append(1e3 * report.update_time)
        if self._pending:
            self.emit(report.elastic)
        if report.newton is not None:
            n = report.newton
            self.newton.append((n.newton, n.cg, n.residual, n.outcome == "near_miss", n.rounds, n.unsettled))
        if report.removed is not None:
            self.record_removed(report)
        self.record_updates(report)
        self.contact_work += report.contact_work
        row = self.loads.add(report) if self.loads is not None else {}  # the step's start: load, load point
        if self.forces is not None:  # the colliders' forces over the step
            row.update(self.forces.add(report))
        if self.rigid is not None:  # the rigid bodies' coupling forces over the step
            row.update(self.rigid.forces(report))
        if row and log.scalars:
            self.sink.scalars(max(report.step - 1, 0), report.time - report.dt, row)
        self.sink.timings(self.step, self.t, {"step_time_ms": self.step_ms[-1], **(
            {"update_ms": self.update_ms[-1]} if report.updated else {})})
        t1 = time.perf_counter()
        last = not driver.running
        if log.scalars or last:
            self.measure(self.row_extra(report, driver.current), report.diagnostics)
        if not driver.current:  # the device has moved on: the state is read at the batch's last step
            return
        if self.responses is not None:
            self.responses.update(self.state.x.numpy(), report.time, self.solver.removals.kept)
        if log.particles and self.frame_due(last):
            self.particles()
            # the frame and this state's diagnostics (measured by the driver on the host at k = 1)
            self.log_ms.append(1e3 * (time.perf_counter() - t1 + report.measure_time))
        if self.step % log.fracture_every == 0:
            self.log_fracture()
        assert self.progress is not None  # made by on_start
        self.progress.update(self.step, self.t, self.step_ms[-1])

    def wants(self, driver: mpm.Driver) -> tuple[float, float]:
        """The next particle frame and fracture measure: the steps of a batch end there."""
        log = self.spec.log
        step = (self.step // log.fracture_every + 1) * log.fracture_every
        when = math.inf
        if log.particles:
            if log.every is not None:
                step = min(step, (self.step // log.every + 1) * log.every)
            else:
                when = self._next_frame
        return float(step), when

    def on_event(self, driver: mpm.Driver, event: mpm.Event) -> None:
        self.sink.event(event.step, event.time, event.text, level=event.level, **event.values)
        if event.kind == "detection":  # a warning of the blow-up detection (action warn)
            v = event.values
            self.metrics.setdefault("detect_warnings", []).append(
                {"step": event.step, "time": event.time, "criterion": v["criterion"], "body": v.get("body"),
                 "message": event.text.removeprefix("stability warning: ")})

    def on_stop(self, driver: mpm.Driver, outcome: mpm.Outcome) -> None:
        """The run ends unstable at this step (the last state's row first, when a step was taken)."""
        if outcome.report is not None:
            self.step_ms.append(1e3 * outcome.report.wall_time)
            if outcome.criterion != "newton":
                self.update_ms.append(1e3 * outcome.report.update_time)
            if self._pending:
                self.emit(outcome.report.elastic)
        m = self.metrics
        m["status"], m["reason"] = "unstable", outcome.reason
        m["unstable_step"], m["unstable_time"] = outcome.step, outcome.time
        m["unstable_criterion"], m["unstable_body"] = outcome.criterion, outcome.body
        if self.spec.log.particles:
            self.particles()
        where = {"criterion": outcome.criterion, **({"body": outcome.body} if outcome.body else {})}
        self.sink.event(self.step, self.t, f"unstable: {outcome.reason}", level="ERROR", **where, **outcome.values)

    # ------------------------------------------------------------ scalars
    def measure(self, extra: dict, diagnostics: np.ndarray | None = None) -> None:
        """The state just reached (its ``diagnostics``, as the driver measured them, or measured now); its
        elastic energy arrives with the next step's P2G (or from :meth:`finish`)."""
        d = diagnostics.copy() if diagnostics is not None else self.solver.measure(self.state, elastic=False)
        self._pending[:] = [self.step, self.t, d, extra]

    def emit(self, elastic_energy: float) -> None:
        step, t, d, extra = self._pending
        d[self.names.index("elastic_energy")] = elastic_energy
        self.drift.add(d)
        if self.spec.log.scalars:
            E = self.drift.energy(d)  # [J] the material's; with the rigid bodies' at a frame (rigid_track)
            row = {**dict(zip(self.names, d.tolist())), "total_energy": E, **extra,
                   **(self.rigid.system(step, E) if self.rigid is not None else {})}
            self.sink.scalars(step, t, row)
        self._pending.clear()

    def row_extra(self, report: mpm.StepReport, current: bool = True) -> dict:
        """The step's scalars besides the diagnostics (the errors against a
        closed-form solution only where the state is ``current``)."""
        extra = {"dt": report.dt, "dt_fresh": report.dt_fresh, "max_speed": report.max_speed,
                 "config_updates": float(self.updates.sum())}
        if self.scheme.tracks_marks():
            for name, m, n in zip(self.marked_names, report.marked, self.solver.removals.counts):
                extra[name] = float(m / max(n, 1))
        if self.scheme.name != "empm":  # the narrowest reference cell (1 in EMPM)
            for name, s in zip(self.stretch_names, report.min_stretch):
                extra[name] = float(s)
        if self.solution is not None and current:
            extra.update(self.errors())
        if report.boundary_impulse is not None:  # [N s] the walls', colliders' and regions' impulse on the bodies
            J = report.boundary_impulse / self.model.kernel.n_grids  # (every kernel grid carries the full mass)
            extra.update({f"boundary_impulse_{a}": float(j) for a, j in zip("xyz", J)})
        if self.solver.contact is not None:  # body nodes in contact in this step (mpm.contact)
            extra["contact_nodes"] = float(report.contact_nodes)
            extra["contact_work"] = self.contact_work  # [J] so far: the kinetic energy the contact took
        if self.solver.conditions.open:
            extra["removed"] = float(self.solver.removals.removed.sum())
        if (n := report.newton) is not None:
            extra.update(newton_iterations=float(n.newton), cg_iterations=float(n.cg), newton_residual=n.residual,
                         solve_rounds=float(n.rounds), unsettled=float(n.unsettled))
        return extra

    def errors(self) -> dict:
        """RMS error of the particles against the closed-form solution at the
        current time: E = sqrt(sum_p |phi_p - phi(X_p, t)|^2 / n_p)."""
        x = self.state.x.numpy().astype(np.float64)
        v = self.state.v.numpy().astype(np.float64)
        sol = self.solution
        assert sol is not None  # called only for a scene with a solution
        e = {"displacement": analytic.rms(x - self.X0, sol.displacement(self.X0, self.t)),
             "velocity": analytic.rms(v, sol.velocity(self.X0, self.t))}
        for k, val in e.items():
            self.error_max[k] = max(self.error_max[k], val)
        self.error_last, self._error_step = e, self.step
        return {f"error/{k}": val for k, val in e.items()}

    # ------------------------------------------------------------ particles
    def particles(self) -> None:
        """Particles, dJ and the plastic fields of the current state."""
        # copies: on the CPU .numpy() is a view of memory the next step overwrites, and the sink may serialise later
        x = self.state.x.numpy().copy()
        dJ = self.state.dJ.numpy().copy() if self.solver.options.record_dJ else None
        log = self.spec.log
        fields = particle_fields(self.model, self.state, speed="speed" in (log.color, *log.channels))
        index = self.solver.removals.kept  # the particles left inside, once some were removed at open walls
        if index is not None:
            x, dJ = x[index], (dJ[index] if dJ is not None else None)
            fields = {k: v[index] for k, v in fields.items()}
        if self.rigid is None:
            self.sink.particles(self.step, self.t, x, dJ, fields, index)
            return
        poses, row = self.rigid.frame(self.rigid.state(), self.step)  # the rigid bodies' state at the frame
        if log.scalars:
            self.sink.scalars(self.step, self.t, row)
        self.sink.particles(self.step, self.t, x, dJ, fields, index, rigid=poses)

    def frame_due(self, last: bool) -> bool:
        """Whether this step's particles are logged: every ``log.every`` steps,
        or (log.every null) at the first step at or past each multiple of
        1 / log.fps in simulated time; the last step always."""
        every = self.spec.log.every
        if every is not None:
            return every > 0 and (self.step % every == 0 or last)
        if self.t >= self._next_frame * (1.0 - 1e-9) or last:
            self._next_frame = (math.floor(self.t * self.spec.log.fps * (1.0 + 1e-9)) + 1) / self.spec.log.fps
            return True
        return False

    def warn_size(self, dt: float) -> None:
        """Say so before a run whose recording would pass log.size_warning_mb."""
        mb, frames, steps = run_metrics.recording_estimate(self.spec, self.model, self.state, len(self.names), dt)
        limit = self.spec.log.size_warning_mb
        if mb > limit:
            text = (f"the recording will be about {mb:,.0f} MB ({frames} particle frames of "
                    f"{self.model.n_particles} particles, scalars for about {steps} steps), over "
                    f"log.size_warning_mb={limit:g}: lower log.fps or raise log.every (log.every=0: no particles)")
            print(f"warning: {text}", file=sys.stderr, flush=True)
            self.sink.event(0, 0.0, text, level="WARN", estimated_mb=mb)
        self.metrics["recording_estimate_mb"] = mb

    # ------------------------------------------------------------ events
    def record_removed(self, report: mpm.StepReport) -> None:
        """Particles that left through open walls: an event per body, counted."""
        assert report.removed is not None  # on_step calls this only then
        for b, n in enumerate(report.removed):
            if n:
                name = self.spec.scene.bodies[b].name
                total = int(self.solver.removals.removed[b])
                self.sink.event(self.step, self.t, f"{n} particles of {name} left through an open wall and were "
                                                   f"removed ({total} so far)",
                                body=name, removed=int(n), removed_total=total)

    def record_updates(self, report: mpm.StepReport) -> None:
        counts = self.solver.removals.counts
        if report.updated:
            self.update_steps += 1
            self.updates[report.updated] += 1
        if not isinstance(self.scheme, mpm.AULMPM):
            return  # EMPM: every step, logged as the count; TLMPM: never
        for b in report.updated:
            name = self.spec.scene.bodies[b].name
            frac = report.marked[b] / counts[b]
            self.sink.event(self.step, self.t,
                            f"configuration update of {name}: {100 * frac:.1f}% of its particles have "
                            f"dJ >= {self.scheme.epsilon:g}",
                            body=name, marked_fraction=float(frac), update_step=self.step, update_time=self.t)

    def announce_scheme(self) -> None:
        for text, params in announce.opening_events(self.scheme, self.spec.integrator if self.implicit else None,
                                                    self.spec.run.dt):
            self.sink.event(0, 0.0, text, **params)

    # ------------------------------------------------------------ fracture
    def log_fracture(self) -> np.ndarray:
        """The fracture measure and the pieces per body (recounted only when a
        body's fraction of broken pairs changed: the count is a host-side graph
        search, 0.1 s for 100K particles)."""
        frac = self.solver.fracture.measure(self.state)
        pairs = self.solver.fracture.pair_counts
        overall = float(np.sum(frac * pairs) / max(pairs.sum(), 1))
        if self._pieces is None or not np.array_equal(frac, self._pieces[0]):
            self._pieces = (frac.copy(), self.solver.fracture.fragments())
        pieces = self._pieces[1]
        row = {"fracture": overall, "fragments": float(pieces.sum())}
        if len(frac) > 1:
            row.update({f"fracture/{b.name}": float(f) for b, f in zip(self.spec.scene.bodies, frac)})
            row.update({f"fragments/{b.name}": float(c) for b, c in zip(self.spec.scene.bodies, pieces)})
        inside = self.solver.conditions.inside_colliders(self.state.x, self.solver.time)
        if len(inside):
            names = self.collider_names()
            row["inside_colliders"] = float(inside.sum())
            if len(inside) > 1:
                row.update({f"inside_colliders/{n}": float(c) for n, c in zip(names, inside)})
            self.inside_max = inside if self.inside_max is None else np.maximum(self.inside_max, inside)
            self.inside_last = inside
        self.sink.scalars(self.step, self.t, row)
        self.fracture, self.fracture_step = (overall, frac), self.step
        return frac

    def collider_names(self) -> list[str]:
        return [c.name or f"{c.type}{i}" for i, c in enumerate(self.spec.scene.colliders)]

    # ------------------------------------------------------------ finish
    def finish(self) -> None:
        """Complete the last scalar row and summarise the run into ``metrics``."""
        m = self.metrics
        if self.progress is not None:
            self.progress.close()
        if self.started and m["status"] != "failed":
            self._final_state()
        if m["status"] in ("interrupted", "preempted"):
            self.sink.event(self.step, self.t, f"{m['status']}: {m['reason']}", level="WARN")
        steps = self.step
        m.update(steps=steps, sim_time=self.t)
        # (the last step, shortened to land on the duration, is not a step the rule chose; dt_reference_factor:
        # the stable step against what a fresh reference would allow)
        m.update(self.driver.summary() if self.driver is not None else mpm.Driver.no_steps())
        m.update(step_time_ms=median(self.step_ms), log_time_ms=median(self.log_ms),
                 loop_time_s=sum(self.step_ms) / 1e3)
        if m["step_time_ms"] and "particles" in m:
            m["particle_steps_per_s"] = m["particles"] / (m["step_time_ms"] / 1e3)
        if not self.built:
            return
        assert self.driver is not None  # made by build()
        names = [b.name for b in self.spec.scene.bodies]
        m.update(
            scheme=self.scheme.name, kernel=self.spec.kernel.name, transfer=self.spec.transfer,
            grid_nodes=self.solver.layout.n_nodes,
            config_updates={"total": int(self.updates.sum()), **{n: int(c) for n, c in zip(names, self.updates)}},
            updates_per_1e4_steps=1e4 * self.update_steps / steps if steps else None,
            update_time_ms=float(np.mean(self.update_ms)) if self.update_ms else None,
            memory_mb=self.solver.memory_bytes(self.state) / 1e6, peak_rss_mb=peak_rss_mb())
        if isinstance(self.scheme, mpm.AULMPM):
            m.update(epsilon=self.scheme.epsilon, eta=self.scheme.eta, affine=self.scheme.affine)
        m["integrator"] = self.spec.integrator.name
        if self.solver.contact is not None:  # [J] the kinetic energy the contact between bodies took (<= 0)
            m["contact_work"] = self.contact_work
        if self.responses is not None:  # the scene's physical responses (mpm.responses)
            m["responses"] = self.responses.summary([b.name for b in self.spec.scene.bodies])
        if self.implicit:
            m["implicit"] = run_metrics.implicit_summary(self.spec.integrator, self.newton, self.driver.halved)
        m.update(self.drift.summary())
        if self.rigid is not None and "energy_final" in m:  # the bodies' energy in the balance (rigid_track)
            m.update(self.rigid.balance(m["energy_initial"], m["energy_final"]))
        if self.solver.conditions.open:  # particles that left through open walls take their mass along
            kept = self.solver.removals.kept if self.solver.removals.kept is not None else slice(None)
            lost = float(self.mass0.sum() - self.mass0[kept].sum())
            m["removed"] = {"total": int(self.solver.removals.removed.sum()),
                            **{b: int(c) for b, c in zip(names, self.solver.removals.removed)}, "mass": lost}
            if self.drift.first is not None and self.drift.last is not None and self.drift.first[0]:
                m["mass_drift"] = abs(self.drift.last[0] + lost - self.drift.first[0]) / self.drift.first[0]
        if self.driver.detector is not None:
            m["detect"] = self.driver.detector.summary()
            m.update(run_metrics.energy_change(m))

    def _final_state(self) -> None:
        """The last state reached: its scalar row (elastic energy by one more
        P2G pass), frame, fracture, and the metrics that describe it."""
        m = self.metrics
        if not self._pending:
            self.measure({"config_updates": float(self.updates.sum())})
        self.emit(self.solver.measure(self.state)[self.names.index("elastic_energy")])
        if m["status"] == "interrupted" and self.spec.log.particles:
            self.particles()
        # (pre-empted: the resumed run logs what comes next, into the same recording)
        if self.fracture is None or self.fracture_step != self.step and m["status"] != "preempted":
            self.log_fracture()
        assert self.fracture is not None  # set by log_fracture()
        overall, per_body = self.fracture
        names = [b.name for b in self.spec.scene.bodies]
        m["fracture"] = {"total": overall, **{n: float(f) for n, f in zip(names, per_body)}}
        if self.inside_max is not None:  # particles more than a cell deep in a collider
            m["inside_colliders"] = {n: {"final": int(a), "max": int(b)} for n, a, b in
                                     zip(self.collider_names(), self.inside_last, self.inside_max)}
        spilled = run_metrics.spilled(self.model, self.state, self.X0)
        if spilled:
            m["spilled"] = spilled
        if self.loads is not None:
            m["loads"] = self.loads.summary(self.state.x.numpy().astype(np.float64), self.t)
        if self.forces is not None:
            m["collider_forces"] = self.forces.summary()
        if self.rigid is not None:  # the rigid bodies' final state
            m["rigid_bodies"] = self.rigid.summary(self.rigid.state())
        pieces = self.solver.fracture.fragments()  # exact at the end
        m["fragments"] = {"total": int(pieces.sum()), **{n: int(c) for n, c in zip(names, pieces)}}
        run_metrics.save_final_state(self.out_dir / "final_state.npz", self.model, self.state, self.X0, self.step,
                                     self.t)
        if self.model.plastic:
            m["plastic"] = run_metrics.plastic_summary(self.model, self.state)
        if self.spec.run.reference is not None and m["status"] == "completed":
            m["error"] = e = run_metrics.reference_errors(self.spec.run.reference, self.state, self.X0, self.t)
            if "problem" not in e:  # also the last step's error/* scalars
                self.sink.scalars(self.step, self.t, {f"error/{k}": e[k] for k in ("displacement", "velocity")})
        elif self.solution is not None:
            if self.error_last is None or self._error_step != self.step:
                self.errors()
            assert self.error_last is not None  # set by errors()
            u, v = self.solution.scales()
            m["error"] = {"displacement": self.error_last["displacement"], "velocity": self.error_last["velocity"],
                          "displacement_max": self.error_max["displacement"],
                          "velocity_max": self.error_max["velocity"],
                          "displacement_scale": u, "velocity_scale": v, "solution": self.solution.name}
