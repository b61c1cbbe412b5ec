"""Stepping a solver with the project's stability policy, from Python.

A :class:`Driver` advances a :class:`mpm.Solver`'s state until a number of
steps or a simulated time (:class:`StepPolicy`), choosing every step's size
and stopping a run that goes unstable:

* the step: the explicit stable step of every body from the last step's
  figures (mpm.timestep: wave speed at the most compressed particle, the
  narrowest reference cell, viscosity, strain rate), capped by ``dt_max``;
  under the implicit integrator a displacement limit, halved after a failed
  Newton solve and recovering by 2 per step; or a fixed ``dt``; the last
  step lands on the duration;
* the run stops ``unstable`` when the adaptive step collapses below
  ``dt_collapse`` of the first one, when a particle's position, velocity or
  F^sn is not finite or a particle leaves the domain, when a Newton solve
  fails after its halvings, or when the blow-up detection (mpm.stability)
  fires with action ``stop`` (``warn``: an event, the run goes on).

What happens is reported to :class:`Observer` objects (recording, metrics,
progress live outside ``mpm``): every completed step's report, events
(warnings, halvings), and the end. A short run::

    driver = Driver(solver, state, StepPolicy(duration=0.5))
    outcome = driver.run()
"""

from __future__ import annotations

import collections
import math
import time
from dataclasses import dataclass, field

import numpy as np

from .params import param
from .stability import Detection, Detector
from .status import StepReport

STATUSES = ("running", "completed", "unstable")


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
        if (self.steps is None) == (self.duration is None):
            return [("steps", "give exactly one of steps and duration")]
        return []


@dataclass
class Event:
    """Something a person should read: a warning, a halved step."""

    step: int
    time: float  # [s]
    text: str
    level: str = "INFO"  # INFO | WARN | ERROR
    values: dict = field(default_factory=dict)
    kind: str = ""  # "detection": a warning of the blow-up detection; "halving": an implicit step halved


@dataclass
class Outcome:
    """How a run ended (``status`` running while it has not)."""

    status: str = "running"  # one of STATUSES
    reason: str = ""
    step: int = 0  # steps completed
    time: float = 0.0  # [s]
    criterion: str | None = None  # nonfinite, outside, dt_collapse, newton, or a detection criterion
    body: str | None = None  # the body it names, if any
    values: dict = field(default_factory=dict)
    report: StepReport | None = None  # the step that failed (None: none was taken)


class Observer:
    """What a driver reports; every method does nothing unless overridden."""

    def on_start(self, driver: "Driver") -> None:
        """The initial state, prepared (``driver.initial``: its diagnostics)."""

    def on_step(self, driver: "Driver", report: StepReport) -> None:
        """A completed step; ``driver.step`` and ``driver.time`` are after it."""

    def on_event(self, driver: "Driver", event: Event) -> None:
        """A warning or notice."""

    def on_stop(self, driver: "Driver", outcome: Outcome) -> None:
        """The run ended unstable (``outcome.report``: the step that failed, if any)."""


class Driver:
    """Steps ``solver`` on ``state`` under ``policy``; ``detection`` (None:
    mpm.stability's defaults) needs the solver's ``track_energy`` (and
    ``track_J`` for models that cannot invert) unless its action is off."""

    def __init__(self, solver, state, policy: StepPolicy, detection: Detection | None = None,
                 observers: list[Observer] | tuple = ()):
        self.solver, self.state, self.policy = solver, state, policy
        self.detection = detection if detection is not None else Detection()
        self.observers = list(observers)
        for name, message in policy.problems():
            raise ValueError(f"{name}: {message}")
        self.step, self.time = 0, 0.0
        self.outcome = Outcome()
        self.detector: Detector | None = None
        integrator = solver.options.integrator
        self.halvings = integrator.halvings if solver.implicit is not None and policy.dt is None else 0
        self.dt = math.inf  # [s] the next step
        self.dt_fresh = math.inf  # [s] the step a freshly updated reference would allow
        self.dt_first: float | None = None  # [s] the first adaptive step
        self.dts: list[float] = []  # [s] every step taken
        self.binding: collections.Counter = collections.Counter()  # steps per binding term of the rule
        self.reference_factors: list[float] = []  # per step: dt / fresh dt of the binding body
        self.halved = 0  # implicit steps retried with half the step
        self.initial: np.ndarray | None = None  # diagnostics of the initial state (mpm.diagnostics)
        self.v0 = 0.0  # [m/s] the fastest initial particle
        self._last: StepReport | None = None
        self._landing = False  # the last step was shortened to land on the duration
        self._limit = math.inf  # [s] the rule's step (before landing on the duration)
        self._factor = 1.0  # reference factor of the next step
        self._scale = 1.0  # the implicit step's factor after halvings
        self._energies = (0.0, 0.0)  # kinetic and potential energy [J] of the last state reached

    # ------------------------------------------------------------ state
    @property
    def running(self) -> bool:
        return self.outcome.status == "running"

    @property
    def done(self) -> bool:
        """The policy's end is reached."""
        p = self.policy
        return self.step >= p.steps if p.steps is not None else self.time >= p.duration * (1 - 1e-12)


    # ------------------------------------------------------------ run
    def run(self) -> Outcome:
        """Start, step until the end or an instability; the outcome."""
        self.start()
        while self.running:
            self.advance()
        return self.outcome

    def start(self) -> None:
        """Prepare the solver, measure the initial state, check it, and tell the observers."""
        s, state = self.solver, self.state
        s.prepare(state)
        self.initial = s.measure(state, elastic=False)
        names = s.diagnostics.names
        kinetic, potential = (float(self.initial[names.index(k)]) for k in ("kinetic_energy", "potential_energy"))
        self.v0 = float(np.max(np.linalg.norm(state.v.numpy(), axis=1)))
        self._energies = (kinetic, potential)
        problem = None
        if not (np.isfinite([kinetic, potential]).all() and np.isfinite(self.v0)):
            problem = (f"the initial state's kinetic or potential energy is not finite (fastest particle "
                       f"{self.v0:.3g} m/s in {s.model.types.precision}): velocities or positions overflow",
                       "nonfinite", None, {})
        elif self.detection.action != "off":
            m = s.model
            self.detector = Detector(self.detection, m.scene, s.conditions.speed(), self.v0, m.kernel.n_grids,
                                     float(m.mass.numpy().astype(np.float64).sum()))
            trips = self.detector.initial(state.numpy()["F"], m.body.numpy())
            if trips:
                t = trips[0]
                problem = (t.message, t.criterion, t.body, {"value": t.value, "limit": t.limit})
        if problem is None:
            self._choose_dt()
        for o in self.observers:
            o.on_start(self)
        if problem is not None:
            message, criterion, body, values = problem
            self._stop(message, criterion, body, **values)
        elif self.done:
            self.outcome.status = "completed"

    def advance(self) -> None:
        """One step (with its retries), its checks, and the observers' turn."""
        s = self.solver
        collapse = self._collapsed()
        if collapse:
            self._stop(collapse, "dt_collapse")
            return
        t0 = time.perf_counter()
        report = s.advance(self.state, self.dt, self.halvings)
        report.wall_time = time.perf_counter() - t0
        report.elastic = s.step_energy()  # of the state the step started from
        trips = []
        failed = report.newton is not None and not report.newton.converged
        if self.detector is not None and not failed:
            # the state the step started from: its kinetic and potential energy from the last G2P,
            # its elastic energy from this step's P2G
            trips = self.detector.energy(self._energies[0], report.elastic, self._energies[1])
            self._energies = (report.kinetic, report.potential)
        if failed:  # the state is the step's start
            n = report.newton
            self._stop(report.reason, "newton", report=report, newton_iterations=n.newton, cg_iterations=n.cg,
                       newton_residual=n.residual, halvings=report.halvings)
            return
        self.dts.append(report.dt)
        self.reference_factors.append(self._factor)
        self._landing = self.dt < self._limit
        report.dt_fresh = self.dt_fresh
        self.step += 1
        self.time += report.dt
        self._last = report
        if report.newton is not None:
            self._halvings(report)
        # the detection names the cause when particles also left the domain in this step
        if self.detector is not None and not report.nonfinite:
            for trip in trips + self.detector.step(report):
                if self.detection.action == "stop":
                    self._stop(trip.message, trip.criterion, trip.body, report=report, value=trip.value,
                               limit=trip.limit)
                    return
                where = {"criterion": trip.criterion, **({"body": trip.body} if trip.body else {})}
                self._event(f"stability warning: {trip.message}", "WARN", "detection", **where, value=trip.value,
                            limit=trip.limit)
        if report.reason:
            self._stop(report.reason, "nonfinite" if report.nonfinite else "outside", report=report,
                       nonfinite=report.nonfinite, outside=report.outside)
            return
        self.outcome.step, self.outcome.time = self.step, self.time
        if self.done:
            self.outcome.status = "completed"
        for o in self.observers:
            o.on_step(self, report)
        if self.running:
            self._choose_dt()

    # ------------------------------------------------------------ the step rule
    def _choose_dt(self) -> None:
        """The next step: the solver's stable step (mpm.timestep) capped by
        dt_max, unless the policy fixes it; the implicit integrator's step is
        the displacement limit instead, times a factor that halves with a
        failed solve and recovers; the last step ends on the duration."""
        s, p, report = self.solver, self.policy, self._last
        if s.implicit is not None:
            limit = self._scale * s.timestep.displacement_dt(s.options.integrator.displacement, report, self.v0)
            self.dt_fresh, self._factor, binding = limit, 1.0, "displacement"
        else:
            limits = s.timestep.limits(p.cfl, report, self.v0)
            lim = min(limits, key=lambda x: x.dt)
            self.dt_fresh = min(p.dt_max, min(x.fresh for x in limits))
            self._factor = lim.reference_factor
            limit, binding = lim.dt, lim.binding
        if p.dt is not None:
            dt = p.dt
            self.binding["fixed"] += 1
        else:
            dt = min(p.dt_max, limit)
            self.binding["dt_max" if p.dt_max <= limit else binding] += 1
            if self.dt_first is None:
                self.dt_first = dt
        self._limit = dt
        self.dt = dt if p.duration is None else min(dt, p.duration - self.time)

    def _collapsed(self) -> str | None:
        """Why the step cannot be taken: the adaptive step fell below
        dt_collapse of the first (a particle's strain rate or compression is
        running away), or it is not a positive finite number."""
        dt, dt0, p = self._limit, self.dt_first, self.policy
        if p.dt is None and dt0 is not None and not (dt >= p.dt_collapse * dt0):  # NaN and 0 included
            return (f"time step collapsed to {dt:.3g} s, below {p.dt_collapse:g} of the first "
                    f"step ({dt0:.3g} s): a particle's strain rate or compression is running away")
        if not (0.0 < self.dt < math.inf):  # a step of 0 would never end the run (or end it at t = 0)
            speed = self._last.max_speed if self._last is not None else self.v0
            return f"the time step is {self.dt:.3g} s (fastest particle {speed:.3g} m/s): the run cannot advance"
        return None

    def _halvings(self, report: StepReport) -> None:
        """An implicit step's halvings: an event, and the next steps' factor."""
        if report.halvings:
            self.halved += report.halvings
            self._scale *= 0.5 ** report.halvings
            self._event(f"implicit step halved {report.halvings} time(s) to {report.dt:.3g} s after a failed "
                        "Newton solve", "WARN", "halving", halvings=report.halvings, dt=report.dt)
        else:
            self._scale = min(1.0, 2.0 * self._scale)

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
