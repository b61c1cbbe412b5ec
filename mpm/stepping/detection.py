"""Early detection of a blow-up, before any value is non-finite.

Three criteria, checked after every step (:class:`Detector`):

* energy: the total energy E = kinetic + elastic + potential (gravity's work
  is the potential's change) may not grow beyond what the boundaries put in,

      E(t) - E(0) - W_in(t) > energy_growth * scale,

  W_in the work of the boundary conditions on the grid, summed over the
  steps (per node and step the positive part of J . v_bc, J = m (v_bc -
  v_free) the boundary's impulse: an upper bound of the energy put in;
  static walls and colliders do none, mpm.grid) plus the external loads'
  work, the kinetic energy their impulses give the particles (mpm.loads), and
  ``scale`` the largest kinetic plus elastic energy of the earlier states, at least
  the floor 1/2 M (1e-3 c)^2 + M |g| dx (M the total mass, c the slowest
  wave speed): an oscillating or falling body moves energy between the
  terms, a blow-up creates it. Not applied with a body force (the
  manufactured solutions), whose work is not accounted;
* speed: a particle of body b faster than

      speed_factor * (c_b + u_boundary + sqrt(v0^2 + 2 (|g| + a_load) H)),

  c_b the body's wave speed at its most compressed particle (grown by a
  hardening material's factor), u_boundary the fastest collider or
  kinematic region, v0 the fastest initial particle, H the domain's
  largest extent (the speed a free fall through the domain adds) and a_load
  the largest acceleration an external load gives the bodies it acts on
  (mpm.loads.LoadTable.acceleration: a fall under the load too);
* inversion: det F <= ``min_J``, or a singular value of F below
  ``min_stretch`` (degenerate), at a particle of a model that cannot invert
  (every model but fixed corotated and snow: their energies take log J or
  log of the singular values); in 3D the singular value is G2P's lower
  bound (at least 1/sqrt(3) of the true one).

The energy of a state is complete one step later (G2P sums its kinetic and
potential energy, ``SolverOptions.track_energy``; its elastic energy comes
with the next step's P2G), so the energy criterion sees a state one step
behind the other two.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..params import param, violations
from .status import TRIP_SIZE, StepControl, StepStatus
from .timestep import BodyLaws, pymax, pymin, wave_speed

DETECTION_ACTIONS = ("stop", "warn", "off")
"""what a tripped criterion does: stop the run (unstable), warn (an event, the run goes on) or nothing"""
CRITERIA = ("energy", "speed", "inversion")
FLOOR_SPEED = 1.0e-3  # of the slowest wave speed: the kinetic-energy floor of the energy scale


@dataclass
class Detection:
    """Options of the blow-up detection."""

    action: str = param("stop", "stop: the run ends unstable; warn: an event, the run goes on; off",
                        choices=DETECTION_ACTIONS)
    energy_growth: float = param(0.5, "energy growth beyond the boundaries' work, in units of the energy "
                                      "scale [-]", gt=0.0)
    speed_factor: float = param(10.0, "particle speed limit, in units of the speed scale (module "
                                      "docstring) [-]", gt=0.0)
    min_J: float = param(0.0, "det F at or below this is inversion (models that cannot invert) [-]",
                         ge=0.0, lt=1.0)
    min_stretch: float = param(1.0e-3, "a singular value of F below this is degenerate (same models) [-]",
                               ge=0.0, lt=1.0)

    def problems(self) -> list[tuple[str, str]]:
        out = []
        if self.action not in DETECTION_ACTIONS:
            out.append(("action", f"{self.action!r} unknown; accepted: {', '.join(DETECTION_ACTIONS)}"))
        for name, value, accepted in violations(self):
            out.append((name, f"{value} out of range; accepted: {accepted}"))
        return out


@dataclass
class Trip:
    """A criterion that fired."""

    criterion: str  # one of CRITERIA
    body: str | None  # the body's name (None: the whole system)
    value: float
    limit: float
    message: str


class Detector:
    """The criteria for one run. ``scene``: mpm.Scene; ``boundary_speed``
    [m/s] the fastest collider or kinematic region; ``v0`` [m/s] the
    fastest initial particle; ``n_grids`` the kernel's grids (each carries
    the full mass, so the boundaries' work is summed G times);
    ``load_acceleration`` [m/s^2] the loads' largest (a_load)."""

    def __init__(self, options: Detection, scene, boundary_speed: float, v0: float, n_grids: int,
                 total_mass: float, load_acceleration: float = 0.0):
        self.options = options
        self.names = [b.name for b in scene.bodies]
        self.materials = [b.material for b in scene.bodies]
        g = float(np.linalg.norm(scene.gravity))
        fall = math.sqrt(v0 * v0 + 2.0 * (g + load_acceleration) * max(scene.domain))
        self.speed_base = boundary_speed + fall
        self.check_J = np.array([not getattr(m, "invertible", False) for m in self.materials])
        self.energy_on = not getattr(scene.solution, "has_body_force", False)
        c_min = min(m.wave_speed() for m in self.materials)
        dx = scene.dx
        self.floor = 0.5 * total_mass * (FLOOR_SPEED * c_min) ** 2 + total_mass * g * dx
        self.n_grids = n_grids
        self.E0: float | None = None
        self.work = 0.0  # W_in [J]
        self.scale = self.floor
        self.growth = -math.inf  # the largest (E - E0 - W_in) / scale seen
        self.fired: set[str] = set()  # criteria already reported (warn: once each)

    @property
    def active(self) -> bool:
        return self.options.action != "off"

    def speed_limit(self, b: int, J: float, stiffening: float) -> float:
        c = self.materials[b].wave_speed(min(max(J, 1e-3), 1.0)) * math.sqrt(max(stiffening, 1.0))
        return self.options.speed_factor * (c + self.speed_base)

    def step(self, report) -> list[Trip]:
        """Speed and inversion after a step (mpm.solver.StepReport); the
        boundaries' work of the step is added to W_in."""
        self.work += report.boundary_work / self.n_grids + report.load_work
        trips = []
        for b, name in enumerate(self.names):
            J = float(report.min_J[b]) if np.isfinite(report.min_J[b]) else 1.0
            stiff = float(report.stiffening[b]) if np.isfinite(report.stiffening[b]) else 1.0
            speed, limit = float(report.body_speed[b]), self.speed_limit(b, J, stiff)
            if not speed <= limit:
                trips.append(Trip("speed", name, speed, limit,
                                  f"particle speed {speed:.4g} m/s in body '{name}' above the limit "
                                  f"{limit:.4g} m/s (detect.speed_factor = {self.options.speed_factor:g})"))
            if self.check_J[b] and np.isfinite(report.min_J[b]) and report.min_J[b] <= self.options.min_J:
                trips.append(Trip("inversion", name, J, self.options.min_J,
                                  f"det F = {J:.4g} <= {self.options.min_J:g} in body '{name}', whose "
                                  f"model ({self.materials[b].name}) cannot invert"))
            s = report.min_F_stretch[b] if report.min_F_stretch is not None else math.inf
            if self.check_J[b] and np.isfinite(s) and s < self.options.min_stretch:
                trips.append(Trip("inversion", name, float(s), self.options.min_stretch,
                                  f"a singular value of F = {s:.4g} < {self.options.min_stretch:g} in body "
                                  f"'{name}' (degenerate), whose model ({self.materials[b].name}) cannot invert"))
        return self._new(trips)

    def initial(self, F: np.ndarray, body: np.ndarray) -> list[Trip]:
        """Inversion in the initial state (per-particle F and body index): a
        model that cannot invert must not start with det F <= min_J."""
        F = np.asarray(F, np.float64)
        J = np.linalg.det(F)
        s = np.linalg.svd(F, compute_uv=False).min(axis=1)
        trips = []
        for b, name in enumerate(self.names):
            if self.check_J[b] and (body == b).any():
                J_min, s_min = float(J[body == b].min()), float(s[body == b].min())
                if not J_min > self.options.min_J:
                    trips.append(Trip("inversion", name, J_min, self.options.min_J,
                                      f"initial det F = {J_min:.4g} <= {self.options.min_J:g} in body "
                                      f"'{name}', whose model ({self.materials[b].name}) cannot invert"))
                elif s_min < self.options.min_stretch:
                    trips.append(Trip("inversion", name, s_min, self.options.min_stretch,
                                      f"initial singular value of F = {s_min:.4g} < {self.options.min_stretch:g} "
                                      f"in body '{name}' (degenerate), whose model "
                                      f"({self.materials[b].name}) cannot invert"))
        return self._new(trips)

    def energy(self, kinetic: float, elastic: float, potential: float) -> list[Trip]:
        """The energy criterion for one state's energies [J]."""
        if not self.energy_on:
            return []
        E = kinetic + elastic + potential
        if self.E0 is None:
            self.E0 = E
        scale = self.scale  # of the states before this one
        growth = (E - self.E0 - self.work) / scale
        self.scale = max(self.scale, kinetic + max(elastic, 0.0))
        if not np.isfinite(growth):
            growth = math.inf
        self.growth = max(self.growth, growth)
        if growth > self.options.energy_growth:
            return self._new([Trip("energy", None, growth, self.options.energy_growth,
                                   f"total energy grew by {growth:.3g} x its scale {scale:.4g} J beyond the "
                                   f"boundaries' work {self.work:.4g} J (detect.energy_growth = "
                                   f"{self.options.energy_growth:g})")])
        return []

    def _new(self, trips: list[Trip]) -> list[Trip]:
        out = [t for t in trips if t.criterion not in self.fired]
        self.fired.update(t.criterion for t in out)
        return out

    def trip(self, record) -> Trip:
        """The trip of a device record (:func:`make_detection`), with the host's message."""
        code, body, value, limit, scale, work = (float(x) for x in record)
        code, b = int(code), int(body)
        o = self.options
        if code == 0:
            return Trip("energy", None, value, limit,
                        f"total energy grew by {value:.3g} x its scale {scale:.4g} J beyond the boundaries' work "
                        f"{work:.4g} J (detect.energy_growth = {o.energy_growth:g})")
        name, model = self.names[b], self.materials[b].name
        if code == 1:
            return Trip("speed", name, value, limit,
                        f"particle speed {value:.4g} m/s in body '{name}' above the limit {limit:.4g} m/s "
                        f"(detect.speed_factor = {o.speed_factor:g})")
        if code == 2:
            return Trip("inversion", name, value, limit,
                        f"det F = {value:.4g} <= {limit:g} in body '{name}', whose model ({model}) cannot invert")
        return Trip("inversion", name, value, limit,
                    f"a singular value of F = {value:.4g} < {limit:g} in body '{name}' (degenerate), whose model "
                    f"({model}) cannot invert")

    def sync(self, values: dict) -> None:
        """The running state from the device's control block (mpm.stepping.status values)."""
        self.E0 = float(values["e0"][0]) if values["e0_set"][0] else None
        self.work, self.scale = float(values["work"][0]), float(values["escale"][0])
        self.growth = float(values["growth"][0])
        fired = int(values["fired"][0])
        self.fired = {c for i, c in enumerate(CRITERIA) if fired & (1 << i)}

    def summary(self) -> dict:
        """metrics.json ``detect``."""
        return {"action": self.options.action, "energy_growth_max": self.growth if self.energy_on else None,
                "energy_scale": self.scale, "boundary_work": self.work, "fired": sorted(self.fired)}


# ---------------------------------------------------------------- on the device
CRITERION_BIT = {name: 1 << i for i, name in enumerate(CRITERIA)}


@wp.struct
class DetectParams:
    """The criteria's constants for one run (float64; the per-body arrays
    indexed by body)."""

    energy_growth: wp.float64
    speed_factor: wp.float64
    min_J: wp.float64
    min_stretch: wp.float64
    speed_base: wp.float64  # [m/s] the boundary's speed plus the free fall's
    n_grids: wp.float64
    check_J: wp.array(dtype=wp.float64)  # per body: 1 where the model cannot invert


def detect_params(detector: Detector, device) -> DetectParams:  # pyright: ignore[reportGeneralTypeIssues]  (a wp.struct)
    p = DetectParams()
    o = detector.options
    p.energy_growth, p.speed_factor, p.min_J, p.min_stretch = (o.energy_growth, o.speed_factor, o.min_J,
                                                                o.min_stretch)
    p.speed_base, p.n_grids = detector.speed_base, float(detector.n_grids)
    p.check_J = wp.array(detector.check_J.astype(np.float64), dtype=wp.float64, device=device)
    return p


@functools.cache
def make_record():
    """``record(status, control, criterion, body, value, limit, scale) ->
    recorded``: a trip into the step's status (:func:`make_detection`)."""
    f64 = wp.float64

    @wp.func
    def record(status: StepStatus, control: StepControl, criterion: int, body: f64, value: f64, limit: f64,
               scale: f64):
        """A trip, unless its criterion was reported before this call (``fired``)."""
        fired = int(control.fired[0])
        bit = 1 << wp.min(criterion, 2)  # (3: inversion by a singular value)
        if (fired & bit) != 0:
            return False
        n = int(status.trips[0])
        if n * TRIP_SIZE < status.trip.shape[0]:
            k = n * TRIP_SIZE
            status.trip[k] = f64(criterion)
            status.trip[k + 1] = body
            status.trip[k + 2] = value
            status.trip[k + 3] = limit
            status.trip[k + 4] = scale
            status.trip[k + 5] = control.work[0]
            status.trips[0] = f64(n + 1)
        return True

    return record


@functools.cache
def make_energy_check(energy_on: bool):
    """``energy(control, status, params) -> tripped``: :meth:`Detector.energy` on the device."""
    f64 = wp.float64
    inf = f64(math.inf)
    record = make_record()

    @wp.func
    def energy(control: StepControl, status: StepStatus, params: DetectParams):  # pyright: ignore[reportGeneralTypeIssues]
        """The energy criterion for the state the step started from (its kinetic
        and potential energy from the last G2P, its elastic energy from this
        step's P2G); the new state's energies are kept for the next step."""
        tripped = bool(False)
        if wp.static(energy_on):
            kinetic, potential = control.kinetic_last[0], control.potential_last[0]
            elastic = status.elastic[0]
            E = kinetic + elastic + potential
            if control.e0_set[0] == f64(0.0):
                control.e0[0] = E
                control.e0_set[0] = f64(1.0)
            scale = control.escale[0]
            growth = (E - control.e0[0] - control.work[0]) / scale
            control.escale[0] = pymax(scale, kinetic + pymax(elastic, f64(0.0)))
            if not wp.isfinite(growth):
                growth = inf
            control.growth[0] = pymax(control.growth[0], growth)
            if growth > params.energy_growth:
                tripped = record(status, control, 0, f64(-1.0), growth, params.energy_growth, scale)
                control.fired[0] = f64(int(control.fired[0]) | 1)
        control.kinetic_last[0] = status.kinetic[0]
        control.potential_last[0] = status.potential[0]
        return tripped

    return energy


@functools.cache
def make_step_check():
    """``step(control, status, laws, params, n_bodies) -> tripped``: :meth:`Detector.step` on the device."""
    f64 = wp.float64
    record = make_record()

    @wp.func
    def step(control: StepControl, status: StepStatus, laws: BodyLaws, params: DetectParams, n_bodies: int):  # pyright: ignore[reportGeneralTypeIssues]
        """Speed and inversion after the step; its boundaries' work is added."""
        control.work[0] = control.work[0] + status.boundary_work[0] / params.n_grids + status.load_work[0]
        tripped = bool(False)
        fired = int(0)
        for b in range(n_bodies):
            min_J = status.min_J[b]
            J = f64(1.0)
            if wp.isfinite(min_J):
                J = min_J
            stiff = f64(1.0)
            if wp.isfinite(status.stiffening[b]):
                stiff = status.stiffening[b]
            c = wave_speed(laws, b, pymin(pymax(J, f64(1.0e-3)), f64(1.0))) * wp.sqrt(pymax(stiff, f64(1.0)))
            limit = params.speed_factor * (c + params.speed_base)
            speed = wp.sqrt(status.max_speed2[b])
            if not (speed <= limit):
                if record(status, control, 1, f64(b), speed, limit, f64(0.0)):
                    tripped = True
                    fired = fired | 2
            check = params.check_J[b] != f64(0.0)
            if check and wp.isfinite(min_J) and min_J <= params.min_J:
                if record(status, control, 2, f64(b), J, params.min_J, f64(0.0)):
                    tripped = True
                    fired = fired | 4
            s = wp.sqrt(status.min_F_stretch2[b])
            if check and wp.isfinite(s) and s < params.min_stretch:
                if record(status, control, 3, f64(b), s, params.min_stretch, f64(0.0)):
                    tripped = True
                    fired = fired | 4
        control.fired[0] = f64(int(control.fired[0]) | fired)
        return tripped

    return step


@functools.cache
def make_detection(energy_on: bool):
    """``energy(control, status, params) -> tripped`` and ``step(control,
    status, laws, params, n_bodies) -> tripped``: :meth:`Detector.energy` and
    :meth:`Detector.step` on the device, the same float64 arithmetic, their
    running state in the control block (mpm.stepping.status) and every new trip
    recorded in the step's status (TRIP_SIZE values: the criterion's code -
    0 energy, 1 speed, 2 inversion by det F, 3 by a singular value - the
    body, the value, the limit, the energy scale, the boundaries' work) for
    the host's messages (:meth:`Detector.trip`)."""
    return make_energy_check(energy_on), make_step_check()
