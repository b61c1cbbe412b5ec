"""Can a precision resolve a scene's motion? A pre-run estimate.

An explicit step advances the positions and the deformation gradient by
sums, ``x += dt v`` and ``F += dt grad_v`` (mpm.g2p; the Eulerian scheme
``F^0s <- (I + dt grad_v) F^0s``), each rounded to the precision's spacing
of the value it is added to: about ``2^-23 |x|`` for a position and
``2^-24`` for an entry of F near 1 in float32 (2^-52 and 2^-53 in float64).
An increment below that spacing is rounded away, or to one spacing, every
step, and the sum drifts: the small-deflection cantilever of
conf/scene/cantilever_stiff_2d.yaml (E = 1e8 Pa, deflection 1e-3 of its
length, a strain increment of about 1e-9 per step) deflects 1.03-1.34 times
as far in float32 as in float64, with a spurious stretching and an energy
gain.

:func:`resolution` estimates, from the scene alone, each body's per-step
increments: the stable step ``dt = cfl dx / (c + v)`` (the body's wave
speed at rest ``c``, its speed scale ``v``; or the step given), and per
source of motion a strain ``eps`` reached over a time ``T``:

==================  ========================  ===============  ===================
source              strain                    time T           speed
==================  ========================  ===============  ===================
initial velocity    v0 / c                    h / c            v0 (+ |omega| r)
gravity: the fall   sqrt(2 g H) / c           h / c            sqrt(2 g H)
gravity: weight     rho g h / M               h / c            eps h / T
traction t          |t| / M                   max(rise, h/c)   eps h / T
point load P        |P| h / (V M)             max(rise, h/c)   eps h / T
body force f        |f| h / M                 max(rise, h/c)   eps h / T
region, collider    u / c                     h / c            u
region's gradient   (rate |G|: dt |G| a step)                  |G| r
initial deformation |F0 - I|                  h / c            eps c
closed-form motion  v_a / c                   u_a / v_a        v_a
==================  ========================  ===============  ===================

with ``M = rho c^2`` the body's P-wave modulus, ``h`` the largest extent
of its bounding box, ``r`` half its diagonal, ``V`` its volume (the
bounding box's), ``H`` the height it can fall to the floor (the interior's
bound along gravity), ``u`` the region's or collider's speed and ``rise``
the time the load's profile takes to reach its largest factor; a scene's
closed-form solution (mpm.analytic) gives its amplitudes of displacement
``u_a`` and velocity ``v_a``. The body's
dominant strain source (the largest increment per step, ``d_eps = eps dt /
T``, or ``dt`` times a rate; earlier versions compared a source's total
strain with another's per step, and a slow ramp could outrank the body's
weight) sets its strain increment per step and its dominant speed its
position increment
``d_x = v dt``; their ratios to the precision's spacing,

    r_F = d_eps / 2^-24,      r_x = d_x / (2^-23 x_max)

(float64: 2^-53, 2^-52), ``x_max`` the domain's largest coordinate, say
how many spacings a step moves. Below :data:`THRESHOLD` (r_F < 1: under
one spacing) or :data:`POSITION_THRESHOLD` (r_x < 0.1) the precision
cannot resolve the motion. Measured on the stiff cantilever
(4 cells across, its load scaled; float32 against float64, TLMPM / EMPM):
the deflection 190 % too large at r_F = 0.0095, 36 / 28 % at 0.028,
4.8 / 7.2 % at 0.095, 0.4 / 1.9 % at 0.28, 0.1 / 0.1 % at 0.95, 0.00 /
0.05 % at 9.5; other sizes follow r_F: 0.07 / 1.9 % at 0.19 (2 cells),
4.6 / 7.7 % at 0.047 (8 cells), 31 / 35 % at 0.024 (16 cells). The small
cantilever of conf/scene/cantilever_2d.yaml (E = 1e6 Pa, r_F = 0.085) is
2.2 / 2.3 % too far, its large-deflection size (r_F = 2.8) and the dropped
balls and colliding spheres (r_F > 1000) agree with float64 to 2e-4.
A body that nothing moves or strains is resolved (r = inf).

The remedy, short of float64: compensated sums of x and F in G2P
(mpm.SolverOptions.compensate, mpm.g2p), on by default where this estimate
flags float32; they give the stiff cantilever float64's deflection to four
digits. The estimate assumes the step the run will take (:func:`for_policy`:
the step policy's fixed step, CFL number and cap, or the implicit
integrator's displacement limit); the command line and the library
(mpm.Driver fits the solver to its policy) decide by it alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .stepping.timestep import cfl_dt, displacement_dt

__all__ = ["THRESHOLD", "POSITION_THRESHOLD", "SPACING", "Source", "BodyResolution", "Resolution", "resolution",
           "for_policy", "compensates"]

THRESHOLD = 1.0
"""r_F below this: the precision cannot resolve a step's strain increment"""
POSITION_THRESHOLD = 0.1
"""r_x below this: nor a step's motion (the positions' rounding alone cost the
cantilever 0.2 % at r_x = 0.013 and 0.5 % at 0.0067: F's rounding dominates)"""

# (strain spacing near 1, relative spacing of a position): 2^-24 (just below 1) and 2^-23 in float32
SPACING = {"float32": (2.0 ** -24, 2.0 ** -23), "float64": (2.0 ** -53, 2.0 ** -52)}


@dataclass(frozen=True)
class Source:
    """One source of a body's motion: its strain ``strain`` reached over
    ``time`` [s] (or a strain rate ``rate`` [1/s]), and the speed [m/s] it gives."""

    name: str
    strain: float = 0.0
    time: float = math.inf
    speed: float = 0.0
    rate: float = 0.0

    def strain_step(self, dt: float) -> float:
        """The strain increment of a step of ``dt`` [s]."""
        if self.rate > 0.0:
            return self.rate * dt
        return self.strain * dt / self.time if self.time > 0.0 else self.strain


@dataclass
class BodyResolution:
    """One body's figures (see the module docstring)."""

    name: str
    wave_speed: float  # c [m/s]
    modulus: float  # M = rho c^2 [Pa]
    size: float  # h [m]
    sources: list[Source] = field(default_factory=list)
    strain_source: str = ""  # the dominant strain source's name ("" when none)
    strain_step: float = 0.0  # d_eps per step
    speed_source: str = ""
    position_step: float = 0.0  # d_x per step [m]
    r_F: float = math.inf
    r_x: float = math.inf


@dataclass
class Resolution:
    """What :func:`resolution` estimates for a scene in ``precision``."""

    precision: str
    dt: float  # [s] the step the estimate assumes (the given one, or the smallest of the bodies' limits)
    x_max: float  # [m] the largest coordinate in the domain
    strain_spacing: float  # 2^-24 (float32) or 2^-53
    position_spacing: float  # 2^-23 x_max (float32) or 2^-52 x_max [m]
    bodies: list[BodyResolution]
    threshold: float = THRESHOLD
    position_threshold: float = POSITION_THRESHOLD

    @property
    def r_F(self) -> float:
        return min((b.r_F for b in self.bodies), default=math.inf)

    @property
    def r_x(self) -> float:
        return min((b.r_x for b in self.bodies), default=math.inf)

    @property
    def resolved(self) -> bool:
        """Does every body strain by ``threshold`` spacings a step, and move by ``position_threshold``?"""
        return self.r_F >= self.threshold and self.r_x >= self.position_threshold

    def message(self) -> str:
        """One line: what is below the threshold, and the remedy ("" when resolved)."""
        if self.resolved:
            return ""
        worst = min(self.bodies, key=lambda b: min(b.r_F / self.threshold, b.r_x / self.position_threshold))
        parts = []
        if worst.r_F < self.threshold:
            parts.append(f"a step's strain increment ({worst.strain_source}) is about {worst.strain_step:.2g}, "
                         f"{worst.r_F:.2g} of {self.precision}'s spacing {self.strain_spacing:.2g} of F near I")
        if worst.r_x < self.position_threshold:
            parts.append(f"a step moves it about {worst.position_step:.2g} m ({worst.speed_source}), "
                         f"{worst.r_x:.2g} of {self.precision}'s spacing of positions {self.position_spacing:.2g} m")
        return (f"body '{worst.name}': " + "; ".join(parts)
                + f" (dt = {self.dt:.3g} s): {self.precision} rounds the motion away; "
                "run in float64 or keep compensated sums (SolverOptions.compensate)")


def _extent(shape) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = (np.asarray(v, float) for v in shape.bounds())
    return lo, hi


def _rise(load) -> float:
    """[s] the time a load's profile takes to reach its largest factor."""
    rows = load.rows()
    return float(rows[int(np.argmax(np.abs(rows[:, 1]))), 0])


def _fall(scene, lo: np.ndarray, hi: np.ndarray, g: np.ndarray) -> float:
    """[m] how far a body within lo/hi can fall along g to the interior's bound."""
    wall = scene.wall_cells * scene.dx
    gn = float(np.linalg.norm(g))
    if gn == 0.0:
        return 0.0
    u = g / gn
    H = math.inf
    for k, uk in enumerate(u):
        if uk < 0.0:
            H = min(H, max(lo[k] - wall, 0.0) / -uk)
        elif uk > 0.0:
            H = min(H, max(scene.domain[k] - wall - hi[k], 0.0) / uk)
    return 0.0 if not math.isfinite(H) else H


def _sources(scene, i: int, c: float, M: float, h: float, r: float, V: float, lo, hi) -> list[Source]:
    b = scene.bodies[i]
    rho = b.material.rho
    transit = h / c
    out = []
    v0 = float(np.linalg.norm(b.velocity)) if b.velocity is not None else 0.0
    if b.angular_velocity is not None:
        v0 += float(np.linalg.norm(np.atleast_1d(b.angular_velocity))) * r
    if v0 > 0.0:
        out.append(Source("initial velocity", v0 / c, transit, v0))
    g = np.asarray(scene.gravity, float)
    gn = float(np.linalg.norm(g))
    if gn > 0.0:
        H = _fall(scene, lo, hi, g)
        if H > 0.0:
            vf = math.sqrt(2.0 * gn * H)
            out.append(Source("gravity: the fall", vf / c, transit, vf))
        eps = rho * gn * h / M
        out.append(Source("gravity: its weight", eps, transit, eps * h / transit))
    for k, ld in enumerate(scene.loads):
        if ld.body is not None and ld.body != i:
            continue
        f = float(np.linalg.norm(ld.force))
        sigma = {"traction": f, "point": f * h / V, "body": f * h}.get(ld.kind, 0.0)
        if sigma <= 0.0:
            continue
        T = max(_rise(ld), transit)
        eps = sigma / M
        out.append(Source(f"load '{ld.name or f'load{k}'}' ({ld.kind})", eps, T, eps * h / T))
    for k, reg in enumerate(scene.regions):
        if reg.body != i:
            continue
        name = f"region '{reg.name or f'region{k}'}'"
        u = float(np.linalg.norm(reg.velocity)) if reg.velocity is not None else 0.0
        if reg.angular_velocity is not None:
            u += float(np.linalg.norm(np.atleast_1d(reg.angular_velocity))) * r
        if u > 0.0:
            out.append(Source(name, u / c, transit, u))
        if reg.velocity_gradient is not None:
            G = float(np.linalg.norm(np.asarray(reg.velocity_gradient, float), 2))
            if G > 0.0:
                out.append(Source(name + " (velocity gradient)", speed=G * r, rate=G))
    for k, col in enumerate(scene.colliders):
        u = float(np.linalg.norm(col.velocity)) if getattr(col, "velocity", None) is not None else 0.0
        if u > 0.0:
            out.append(Source(f"collider {k}", u / c, transit, u))
    solution = getattr(scene, "solution", None)
    if solution is not None and hasattr(solution, "scales"):
        u_amp, v_amp = (float(a) for a in solution.scales())
        if v_amp > 0.0:
            out.append(Source(f"solution '{solution.name}'", v_amp / c, u_amp / v_amp, v_amp))
    if b.deformation is not None:
        eps = float(np.linalg.norm(np.asarray(b.deformation, float) - np.eye(scene.dim), 2))
        if eps > 0.0:
            out.append(Source("initial deformation", eps, transit, eps * c))
    return out


def compensates(requested: bool | None, precision: str, r: Resolution) -> bool:
    """Whether a run keeps compensated sums (mpm.SolverOptions.compensate):
    as ``requested``, else (None) exactly where the precision is float32 and
    the estimate ``r`` finds the scene unresolved."""
    return requested if requested is not None else precision == "float32" and not r.resolved


def for_policy(scene, precision: str, policy=None, integrator=None) -> Resolution:
    """:func:`resolution` at the step a run will take: ``policy`` (an
    mpm.StepPolicy; None: its defaults) gives the fixed step or the CFL
    number and the cap, ``integrator`` (mpm.Implicit: its displacement
    limit instead of the CFL bound; None: explicit). The one rule the
    library (mpm.Solver, mpm.Driver) and the command line decide
    compensated sums by."""
    dt = getattr(policy, "dt", None)
    cfl = getattr(policy, "cfl", 0.4)
    dt_max = getattr(policy, "dt_max", 1.0e-3)
    displacement = getattr(integrator, "displacement", None) if getattr(integrator, "name", "") == "implicit" else None
    return resolution(scene, dt=dt, cfl=cfl, dt_max=dt_max, precision=precision, displacement=displacement)


def resolution(scene, dt: float | None = None, cfl: float = 0.4, dt_max: float = 1.0e-3,
               precision: str = "float32", threshold: float = THRESHOLD,
               position_threshold: float = POSITION_THRESHOLD, displacement: float | None = None) -> Resolution:
    """The per-step increments of ``scene``'s bodies against ``precision``'s
    spacings (module docstring): with the step ``dt`` [s] when given, else
    the smallest of the bodies' ``cfl dx / (c + v)`` (under the implicit
    integrator, ``displacement``: its ``displacement dx / v``), capped by
    ``dt_max`` [s] (mpm.stepping.timestep)."""
    if precision not in SPACING:
        raise ValueError(f"precision {precision!r}; accepted: {', '.join(SPACING)}")
    s_F, s_x = SPACING[precision]
    x_max = float(max(scene.domain))
    found = []
    for i, b in enumerate(scene.bodies):
        lo, hi = _extent(b.shape)
        ext = np.maximum(hi - lo, 0.0)
        h = float(ext.max())
        r = 0.5 * float(np.linalg.norm(ext))
        V = float(np.prod(np.maximum(ext, scene.dx)))
        c = float(b.material.wave_speed())
        M = b.material.rho * c * c
        sources = _sources(scene, i, c, M, h, r, V, lo, hi)
        speed = max((s.speed for s in sources), default=0.0)
        if displacement is not None:
            limit = displacement_dt(scene.dx, speed, displacement)
        else:
            limit = cfl_dt(scene.dx, c, speed, cfl, b.material.kinematic_viscosity(), scene.dim)
        found.append((BodyResolution(b.name or f"body{i}", c, M, h, sources), limit))
    step = dt if dt is not None else min([dt_max] + [limit for _, limit in found])
    bodies = []
    for br, _ in found:
        strained = [s for s in br.sources if s.strain > 0.0 or s.rate > 0.0]
        if strained:
            top = max(strained, key=lambda s: s.strain_step(step))  # per step, every source alike
            br.strain_source, br.strain_step = top.name, top.strain_step(step)
            br.r_F = br.strain_step / s_F
        moving = [s for s in br.sources if s.speed > 0.0]
        if moving:
            top = max(moving, key=lambda s: s.speed)
            br.speed_source, br.position_step = top.name, top.speed * step
            br.r_x = br.position_step / (s_x * x_max)
        bodies.append(br)
    return Resolution(precision, step, x_max, s_F, s_x * x_max, bodies, threshold, position_threshold)
