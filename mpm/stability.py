"""Early detection of a blow-up, before any value is non-finite.

Three criteria, checked after every step (:class:`Detector`):

* energy: the total energy E = kinetic + elastic + potential (gravity's work
  is the potential's change) may not grow beyond what the boundaries put in,

      E(t) - E(0) - W_in(t) > energy_growth * scale,

  W_in the work of the boundary conditions on the grid, summed over the
  steps (per node and step the positive part of J . v_bc, J = m (v_bc -
  v_free) the boundary's impulse: an upper bound of the energy put in;
  static walls and colliders do none, mpm.grid), and
  ``scale`` the largest kinetic plus elastic energy of the earlier states, at least
  the floor 1/2 M (1e-3 c)^2 + M |g| dx (M the total mass, c the slowest
  wave speed): an oscillating or falling body moves energy between the
  terms, a blow-up creates it. Not applied with a body force (the
  manufactured solutions), whose work is not accounted;
* speed: a particle of body b faster than

      speed_factor * (c_b + u_boundary + sqrt(v0^2 + 2 |g| H)),

  c_b the body's wave speed at its most compressed particle (grown by a
  hardening material's factor), u_boundary the fastest collider or
  kinematic region, v0 the fastest initial particle and H the domain's
  largest extent (the speed a free fall through the domain adds);
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

import math
from dataclasses import dataclass

import numpy as np

from .params import param, violations

DETECTION_ACTIONS = ("stop", "warn", "off")
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
    the full mass, so the boundaries' work is summed G times)."""

    def __init__(self, options: Detection, scene, boundary_speed: float, v0: float, n_grids: int,
                 total_mass: float):
        self.options = options
        self.names = [b.name for b in scene.bodies]
        self.materials = [b.material for b in scene.bodies]
        g = float(np.linalg.norm(scene.gravity))
        fall = math.sqrt(v0 * v0 + 2.0 * g * max(scene.domain))
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
        self.work += report.boundary_work / self.n_grids
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

    def summary(self) -> dict:
        """metrics.json ``detect``."""
        return {"action": self.options.action, "energy_growth_max": self.growth if self.energy_on else None,
                "energy_scale": self.scale, "boundary_work": self.work, "fired": sorted(self.fired)}
