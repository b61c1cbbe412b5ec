"""Stepping a solver with the project's stability policy, from Python.

A :class:`Driver` advances a :class:`mpm.Solver`'s state until a number of
steps or a simulated time (:class:`StepPolicy`), choosing every step's size
and stopping a run that goes unstable:

* the step: the explicit stable step of every body from the last step's
  figures (mpm.stepping.timestep: wave speed at the most compressed particle, the
  narrowest reference cell, viscosity, strain rate), capped by ``dt_max``;
  under the implicit integrator a displacement limit, halved after a failed
  (or narrowly missed) Newton solve and recovering by 2 per step; or a fixed ``dt``; the last
  step lands on the duration;
* the run stops ``unstable`` when the adaptive step collapses below
  ``dt_collapse`` of the first one, when a particle's position, velocity or
  F^sn is not finite or a particle leaves the domain, when a Newton solve
  fails after its halvings, or when the blow-up detection (mpm.stepping.detection)
  fires with action ``stop`` (``warn``: an event, the run goes on).

The policy runs on the device (mpm.stepping.policy), after every step, from the
step's own figures: the host reads back once every ``sync_every`` = k steps
(a history of k rows, one per step), and the steps after a halt in a batch
change no state, so the detection stops a blow-up at the same step as when
the host reads every step. A fixed-size scene's k steps can be captured as a
CUDA graph and replayed (``graph``). The implicit integrator (its Newton
loop reads back) and a manufactured solution's host-side body force take
k = 1.

What happens is reported to :class:`Observer` objects (recording, metrics,
progress live outside ``mpm``): every completed step's report, events
(warnings, halvings), and the end; an observer may ask for the state at a
step or a time (:meth:`Observer.wants`: a batch ends there). A short run::

    driver = Driver(solver, state, StepPolicy(duration=0.5))
    outcome = driver.run()
"""

from __future__ import annotations

import collections
import math
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from .. import checkpoint
from ..launch import load
from ..params import instance_problem, param, violations
from .policy import Policy
from .detection import Detection, Detector
from .outcome import Event, Outcome
from .status import COLLAPSE, DETECTION, DONE, NONFINITE, OUTSIDE, TRIP_SIZE, StepReport
from .timestep import BINDINGS, CRUSHED, collapse_reason  # noqa: F401 (CRUSHED: the driver's limit)

SYNC_EVERY_CUDA = 10  # the default k on CUDA (batched solvers)


@dataclass
class StepPolicy:
    """How the steps are chosen and when a run ends (exactly one of
    ``steps`` and ``duration``)."""

    steps: int | None = param(None, "number of steps [-]", ge=1)
    duration: float | None = param(None, "simulated time [s]", gt=0.0)
    dt: float | None = param(None, "fixed step [s]; None: adaptive", gt=0.0)
    cfl: float = param(0.4, "CFL number of the adaptive explicit step [-]", gt=0.0, le=1.0)
    dt_max: float = param(1.0e-3, "largest adaptive step [s]", gt=0.0)
    dt_collapse: float = param(1.0e-4, "unstable when the adaptive step falls below this fraction "
                                       "of the first [-]", ge=0.0, le=1.0)

    def problems(self) -> list[tuple[str, str]]:
        """(field, message) for each field out of its range, a step count
        that is not an integer, or not exactly one of ``steps`` and ``duration``."""
        out = [(name, f"{value!r}; accepted: {accepted}") for name, value, accepted in violations(self)]
        if self.steps is not None and (isinstance(self.steps, bool) or not isinstance(self.steps, (int, np.integer))):
            out.append(("steps", f"{self.steps!r}; accepted: an integer >= 1"))
        if (self.steps is None) == (self.duration is None):
            given = "both" if self.steps is not None else "neither"
            out.append(("steps", f"{given} of steps and duration given; accepted: exactly one of them"))
        return out


class Observer:
    """What a driver reports; every method does nothing unless overridden.
    The state on the device is the driver's current one only while
    ``driver.current`` (the last step of a batch, or at the start)."""

    def on_start(self, driver: "Driver") -> None:
        """The initial state, prepared (``driver.initial``: its diagnostics)."""

    def on_step(self, driver: "Driver", report: StepReport) -> None:
        """A completed step; ``driver.step`` and ``driver.time`` are after it."""

    def on_event(self, driver: "Driver", event: Event) -> None:
        """A warning or notice."""

    def on_resume(self, driver: "Driver") -> None:
        """The state of a checkpoint restored (mpm.checkpoint.resume), in place of :meth:`on_start`."""

    def on_stop(self, driver: "Driver", outcome: Outcome) -> None:
        """The run ended unstable (``outcome.report``: the step that failed, if any)."""

    def wants(self, driver: "Driver") -> tuple[float, float]:
        """The next step count and time [s] at which this observer needs the
        state (a batch of steps ends there); inf: none."""
        return math.inf, math.inf


class Driver:
    """Steps ``solver`` on ``state`` under ``policy``.

    ``detection`` (None: mpm.stepping.detection's defaults) needs the solver's
    ``track_energy`` (and ``track_J`` for models that cannot invert) unless
    its action is off. ``sync_every``: the host reads back every k steps
    (None: 10 on CUDA for a batched solver, else 1; k > 1 needs
    ``SolverOptions(batched=True)``). ``graph``: replay the k steps as a CUDA
    graph (None: on CUDA when batched). ``measure``: the diagnostics of every
    state reached (mpm.diagnostics) arrive with each step's report."""

    def __init__(self, solver, state, policy: StepPolicy, detection: Detection | None = None,
                 observers: list[Observer] | tuple = (), sync_every: int | None = None, graph: bool | None = None,
                 measure: bool = False):
        if not isinstance(policy, StepPolicy):
            example = "StepPolicy(duration=1.0)"
            raise TypeError(f"policy: {instance_problem(policy, StepPolicy, 'a StepPolicy', example)}")
        for name, message in policy.problems():
            raise ValueError(f"policy.{name}: {message}")
        if detection is not None:
            if not isinstance(detection, Detection):
                raise TypeError(f"detection: {instance_problem(detection, Detection, 'a Detection', 'Detection()')}")
            for name, message in detection.problems():
                raise ValueError(f"detection.{name}: {message}")
        solver.fit(policy)  # what the solver left to the step policy (compensated sums: mpm.precision)
        opt, device = solver.options, wp.get_device(solver.model.device)
        k = sync_every if sync_every is not None else (SYNC_EVERY_CUDA if opt.batched and device.is_cuda else 1)
        if k > 1 and not opt.batched:
            raise ValueError(f"sync_every {k} needs a batched solver (SolverOptions(batched=True)); accepted: 1")
        self.solver, self.state, self.policy, self.k = solver, state, policy, int(k)
        self.detection = detection if detection is not None else Detection()
        self.observers = list(observers)
        rigid = getattr(getattr(solver, "conditions", None), "rigid", None)
        host_step = bool(getattr(rigid, "reads_step", False))  # joints: each step read back (mpm.joints)
        self.graph = bool(graph if graph is not None else opt.batched and device.is_cuda and not host_step) \
            and self.k > 1
        if self.graph and host_step:
            raise ValueError("graph: a scene with joints or rigid contact reads each step back for Newton's solver "
                             "(mpm.joints), which a CUDA graph cannot hold; accepted: false or null")
        if self.graph and not device.is_cuda:
            raise ValueError("graph: CUDA graphs need a CUDA device; accepted on the CPU: false")
        if self.detection.action != "off" and not opt.track_energy:
            raise ValueError("detection: the blow-up detection needs the step's energies "
                             "(SolverOptions(track_energy=True)), or Detection(action='off')")
        self.measure = measure
        self.device_policy = Policy(solver, policy, self.detection, self.k, measured=measure and opt.batched,
                                    batched=opt.batched)
        self.step, self.time = 0, 0.0
        self.outcome = Outcome()
        self.detector: Detector | None = None
        self.halvings = opt.integrator.halvings if solver.implicit is not None and policy.dt is None else 0
        self.dt = math.inf  # [s] the next step
        self.dt_fresh = math.inf  # [s] the step a freshly updated reference would allow
        self.dt_first: float | None = None  # [s] the first adaptive step
        self.dts: list[float] = []  # [s] every step taken
        self.binding: collections.Counter = collections.Counter()  # steps per binding term of the rule
        self.reference_factors: list[float] = []  # per step: dt / fresh dt of the binding body
        self.halved = 0  # implicit steps retried with half the step
        self.unsettled = 0  # implicit steps whose contact rounds ran out unsettled (mpm.implicit.solve ROUNDS)
        self.initial: np.ndarray | None = None  # diagnostics of the initial state (mpm.diagnostics)
        self.v0 = 0.0  # [m/s] the fastest initial particle
        self.current = True  # the device holds the state of driver.step (observers may read it)
        self.syncs = 0  # read-backs of the step history
        self._landing = False  # the last step was shortened to land on the duration
        self._scale = 1.0  # the implicit step's factor after halvings
        self._wanted = (None, None)
        self._graph = self._graph_key = None

    # ------------------------------------------------------------ state
    @property
    def running(self) -> bool:
        return self.outcome.status == "running"

    @property
    def done(self) -> bool:
        """The policy's end is reached."""
        p = self.policy
        if p.steps is not None:
            return self.step >= p.steps
        assert p.duration is not None, "StepPolicy.problems(): steps or duration"
        return self.time >= p.duration * (1 - 1e-12)

    def kernels(self) -> list:
        """Every kernel the run compiles: the solver's and the policy's."""
        return self.solver.kernels() + self.device_policy.kernels()

    def load(self) -> float:
        """Compile (or load from the cache) every kernel of the run; seconds taken."""
        return load(self.kernels(), self.solver.model.device)

    # ------------------------------------------------------------ run
    def run(self) -> Outcome:
        """Start (unless resumed), step until the end or an instability; the outcome."""
        if self.initial is None:
            self.start()
        while self.running:
            self.advance()
        return self.outcome

    def save(self, path, meta: dict | None = None):
        """Write this run's checkpoint to ``path`` between steps (mpm.checkpoint.save); the path."""
        return checkpoint.save(self, path, meta)

    def resume(self, path):
        """Continue this fresh driver from the checkpoint at ``path`` (mpm.checkpoint.resume);
        then :meth:`advance` or :meth:`run` as after :meth:`start`. The checkpoint read."""
        return checkpoint.resume(self, path)

    def start(self) -> None:
        """:meth:`prepare`, then tell the observers and end a run that cannot start."""
        problem, v = self.prepare()
        for o in self.observers:
            o.on_start(self)
        if problem is not None:
            message, criterion, body, values = problem
            self._stop(message, criterion, body, None, **values)
        elif int(v["halt"][0]) == COLLAPSE:
            self._stop(collapse_reason(self, v), "dt_collapse")
        elif self.done:
            self.outcome.status = "completed"

    def prepare(self) -> tuple:
        """Prepare the solver, measure the initial state, check it and choose the
        first step, telling no one (:meth:`start`; mpm.checkpoint.resume restores
        over it); (the problem that stops the run or None, the step buffer's values)."""
        s, state, p = self.solver, self.state, self.policy
        s.time = 0.0  # a run's clock starts at 0 (the device's too: mpm.stepping.policy.Policy.start)
        if self.k > 1:  # room for k steps of at most cfl cells each (a fixed step: one; the device checks)
            s.pad = math.ceil(self.k * (p.cfl if p.dt is None else 1.0)) * s.model.dx
        s.prepare(state)
        self.initial = initial = s.measure(state, elastic=False)
        names = s.diagnostics.names
        kinetic, potential = (float(initial[names.index(k)]) for k in ("kinetic_energy", "potential_energy"))
        self.v0 = float(np.max(np.linalg.norm(state.v.numpy(), axis=1)))
        problem = None
        if not (np.isfinite([kinetic, potential]).all() and np.isfinite(self.v0)):
            problem = (f"the initial state's kinetic or potential energy is not finite (fastest particle "
                       f"{self.v0:.3g} m/s in {s.model.types.precision}): velocities or positions overflow",
                       "nonfinite", None, {})
        elif self.detection.action != "off":
            m = s.model
            mass = m.mass.numpy().astype(np.float64)
            loads = m.loads.acceleration([mass[a:a + n].sum() for a, n in m.body_ranges]) if m.loads else 0.0
            self.detector = Detector(self.detection, m.scene, s.conditions.speed(), self.v0, m.kernel.n_grids,
                                     float(mass.sum()), load_acceleration=loads)
            trips = self.detector.initial(state.numpy()["F"], m.body.numpy())
            if trips:
                t = trips[0]
                problem = (t.message, t.criterion, t.body, {"value": t.value, "limit": t.limit})
        if problem is None:
            s.buffer.set(kinetic_last=kinetic, potential_last=potential)
            rigid = s.conditions.rigid  # the rigid bodies' surfaces move as fast as particles would
            self.device_policy.start(max(self.v0, rigid.speed() if rigid is not None else 0.0), self.detector)
            v = s.buffer.read()
            s.buffer.set(halt=0.0, skip=0.0)  # the host holds the state (a collapse at the start included)
            self._chosen(v)
        return problem, (v if problem is None else None)

    def advance(self) -> None:
        """A batch of up to ``sync_every`` steps (one under the implicit
        integrator, with its retries), one read-back, then the host's turn:
        the reports in order, the configuration updates the device left, the
        checks, and the observers. Only between :meth:`start` and the end
        (RuntimeError, one line, otherwise)."""
        if self.initial is None:
            raise RuntimeError("advance: the driver has not started; accepted: start() first (run() does both)")
        if not self.running:
            raise RuntimeError(f"advance: the run has ended ({self.outcome.status} at step {self.step}, "
                               f"t = {self.time:.6g} s); accepted: a new Driver to go on")
        if self.solver.implicit is not None:
            self._advance_implicit()
            return
        s, buffer = self.solver, self.solver.buffer
        self._request()
        t0 = time.perf_counter()
        if self.graph:
            self._replay()
        else:
            for _ in range(self.k):
                self._device_step()
        rows = self.device_policy.history.numpy()
        self.syncs += 1
        rows = sorted((r for r in rows if r[buffer.slices["step"]][0] > self.step),
                      key=lambda r: r[buffer.slices["step"]][0])
        wall = (time.perf_counter() - t0) / max(len(rows), 1)
        buffer.set(halt=0.0, skip=0.0)  # the host holds the state: kernels it runs now must run
        for i, row in enumerate(rows):
            v = buffer.values(row)
            report = s.report(v)
            report.wall_time = wall
            self.current = i == len(rows) - 1
            if not self._accept(report, v):
                return

    def _device_step(self) -> None:
        """One step on the device: the solver's stages, the criterion, the
        device's configuration updates, the diagnostics, the policy."""
        s = self.solver
        s.attempt(self.state)
        s.interpolate(self.state)
        s.decide()
        s.move(self.state)
        if self.measure and s.options.batched:
            s.diagnostics.launch_measure(self.state)
        self.device_policy.record()

    def _advance_implicit(self) -> None:
        """One implicit step: Newton's loop reads back, so the host takes the
        retries, then the policy runs on the device as for any step."""
        s, buffer = self.solver, self.solver.buffer
        s.time = self.time
        t0 = time.perf_counter()
        newton, dt, attempts = s.solve_step(self.state, self.dt, self.halvings)
        if not newton.converged:
            report = StepReport.failed(s.n_bodies, s.model.dim)
            report.dt, report.newton, report.halvings = dt, newton, attempts
            report.wall_time = time.perf_counter() - t0
            report.elastic = s.step_energy()
            self._stop(report.reason or "", "newton", report=report, newton_iterations=newton.newton,
                       cg_iterations=newton.cg, newton_residual=newton.residual, halvings=attempts)
            return
        s.interpolate(self.state)
        s.decide()
        if attempts:
            self.halved += attempts
            self._scale *= 0.5 ** attempts
        else:
            self._scale = min(1.0, 2.0 * self._scale)
        buffer.set(scale=self._scale)
        self.device_policy.record()
        v = buffer.values(self.device_policy.history.numpy()[0])
        self.syncs += 1
        buffer.set(halt=0.0, skip=0.0)
        report = s.report(v)
        report.newton, report.halvings = newton, attempts
        report.wall_time = time.perf_counter() - t0
        self.current = True
        self._accept(report, v)

    def _accept(self, report: StepReport, v: dict) -> bool:
        """The host's turn after one step of a batch: bookkeeping, the device's
        trips and halts, the observers; False when the run stopped."""
        s = self.solver
        self.step, self.time = report.step, report.time
        s.time = self.time
        self.dts.append(report.dt)
        self.reference_factors.append(float(v["factor_step"][0]))
        self._landing = bool(v["landing_step"][0])
        if self.detector is not None:
            self.detector.sync(v)
        if report.newton is not None and report.newton.unsettled:
            self.unsettled += 1
            if self.unsettled == 1:  # one line; the rest are counted (Driver.unsettled)
                self._event(f"implicit step {report.step}: {report.newton.unsettled} contact node(s) or bin(s) "
                            f"still changing after {report.newton.rounds} solves; the last solve kept (later "
                            "such steps are counted, not announced)", "WARN", "unsettled",
                            unsettled=report.newton.unsettled, rounds=report.newton.rounds)
        if report.halvings:
            self._event(f"implicit step halved {report.halvings} time(s) to {report.dt:.3g} s after a Newton "
                        "solve that failed or missed narrowly", "WARN", "halving", halvings=report.halvings,
                        dt=report.dt)
        if self.current:
            s.settle(self.state, report)
        else:
            s.removals.add(report)
        self.outcome.step, self.outcome.time = self.step, self.time
        if self.detector is not None and not report.nonfinite and report.trips is not None:
            for record in report.trips.reshape(-1, TRIP_SIZE):
                trip = self.detector.trip(record)
                if self.detection.action == "stop":
                    self._stop(trip.message, trip.criterion, trip.body, report=report, value=trip.value,
                               limit=trip.limit)
                    return False
                where = {"criterion": trip.criterion, **({"body": trip.body} if trip.body else {})}
                self._event(f"stability warning: {trip.message}", "WARN", "detection", **where,
                            value=trip.value, limit=trip.limit)
        if report.reason:
            self._stop(report.reason, "nonfinite" if report.nonfinite else "outside", report=report,
                       nonfinite=report.nonfinite, outside=report.outside)
            return False
        if report.halt == DONE:
            self.outcome.status = "completed"
        if self.measure:  # after the configuration updates, as the device does
            t0 = time.perf_counter()
            report.diagnostics = (s.measure(self.state, elastic=False) if not s.options.batched or report.host_update
                                  else s.diagnostics.named(report.diagnostics))
            report.measure_time = time.perf_counter() - t0
        else:
            report.diagnostics = None  # (the row holds none)
        for o in self.observers:
            o.on_step(self, report)
        if report.halt in (DONE, NONFINITE, OUTSIDE, DETECTION):
            return self.running
        self._chosen(v)
        if report.halt == COLLAPSE:
            self._stop(collapse_reason(self, v), "dt_collapse")
            return False
        return True

    # ------------------------------------------------------------ the step rule's choices
    def _chosen(self, v: dict) -> None:
        """The next step the device chose (mpm.stepping.policy), counted by its binding term."""
        self.dt, self.dt_fresh = float(v["dt"][0]), float(v["dt_fresh"][0])
        self.binding[BINDINGS[int(v["binding"][0])]] += 1
        if v["dt0_set"][0]:
            self.dt_first = float(v["dt0"][0])

    def _request(self) -> None:
        """The observers' next wants: the device pauses there."""
        wants = [o.wants(self) for o in self.observers]
        wanted = (min((w[0] for w in wants), default=math.inf), min((w[1] for w in wants), default=math.inf))
        if wanted != self._wanted:
            self.solver.buffer.set(stop_step=float(wanted[0]), stop_time=float(wanted[1]))
            self._wanted = wanted

    def _replay(self) -> None:
        """The k steps as a CUDA graph, captured again when the grids changed."""
        s = self.solver
        key = (s.layout.n_nodes, s.layout.version, id(s.grid.m))
        if self._graph is None or key != self._graph_key:
            if self._graph is None:
                self.load()  # no module may load inside a capture
            with wp.ScopedCapture(device=s.model.device, force_module_load=False) as capture:
                for _ in range(self.k):
                    self._device_step()
            self._graph, self._graph_key = capture.graph, key
        assert self._graph is not None
        wp.capture_launch(self._graph)

    # ------------------------------------------------------------ reporting
    def _event(self, text: str, level: str = "INFO", kind: str = "", **values) -> None:
        e = Event(self.step, self.time, text, level, values, kind)
        for o in self.observers:
            o.on_event(self, e)

    def _stop(self, reason: str, criterion: str, body: str | None = None, report: StepReport | None = None,
              **values) -> None:
        self.outcome = Outcome("unstable", f"step {self.step} (t = {self.time:.6g} s): {reason}", self.step,
                               self.time, criterion, body, values, report)
        for o in self.observers:
            o.on_stop(self, self.outcome)

    @staticmethod
    def no_steps() -> dict:
        """:meth:`summary` of a run that never stepped."""
        return {"dt": None, "dt_min": None, "dt_max": None, "dt_binding": {}, "dt_reference_factor": None}

    def summary(self) -> dict:
        """The steps' figures for metrics: mean, smallest and largest step
        (the last one, shortened to land on the duration, is not one the rule
        chose), the binding terms, the reference's cost."""
        dts = self.dts[:-1] if self._landing and len(self.dts) > 1 else self.dts
        return {"dt": self.time / self.step if self.step else None,
                "dt_min": min(dts) if dts else None, "dt_max": max(self.dts) if self.dts else None,
                "dt_binding": dict(self.binding),
                "dt_reference_factor": float(np.mean(self.reference_factors)) if self.reference_factors else None}
