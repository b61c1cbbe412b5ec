"""Stable explicit time step, term by term.

Per body, with s = sigma_min(F^sn) the smallest stretch of its reference
configuration (a reference cell of width dx is s dx wide now; s = 1 in EMPM
and right after a configuration update):

    wave         dt <= cfl s dx / (c + max|v|)       acoustic CFL, c the wave speed
    viscous      dt <= cfl (s dx)^2 / (2 d nu)        viscous diffusion, nu kinematic viscosity
    strain_rate  dt <= STRAIN_STEP cfl / |L|          the strain increment of one step

The step is the smallest term. The implicit integrator is not bound by
these: its step is a displacement limit (:func:`displacement_dt`). ``fresh`` is the same bound with s = 1: the
step the body would be allowed right after a configuration update, so
``dt / fresh`` is what the Lagrangian reference costs in step size (the
quantity A-ULMPM's step-driven criterion watches, mpm.schemes).
"""


import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

STRAIN_STEP = 0.25  # dt |L| <= STRAIN_STEP * cfl: the strain increment of one step
TERMS = ("wave", "viscous", "strain_rate")
CRUSHED = 0.05  # a step collapse with a reference cell narrower than this (s_min of F^sn) blames the reference


def cfl_dt(dx: float, wave_speed: float, max_speed: float, cfl: float,
           kinematic_viscosity: float = 0.0, dim: int = 2) -> float:
    """dt = cfl dx / (c + max|v|), and the viscous bound when nu > 0 [s]: the
    limit of an undeformed reference with no strain rate."""
    return step_limits(dx, 1.0, wave_speed, max_speed, cfl, kinematic_viscosity, dim, 0.0).dt


def displacement_dt(dx: float, max_speed: float, fraction: float) -> float:
    """The implicit integrator's step [s]: dt = fraction dx / max|v|, no
    particle moves more than ``fraction`` of a cell (inf at rest)."""
    return fraction * dx / max_speed if max_speed > 0 else math.inf


@dataclass(frozen=True)
class StepLimits:
    """The terms of one body's step limit [s] (see the module docstring)."""

    wave: float
    viscous: float
    strain_rate: float
    fresh: float  # the limit with s = 1

    @property
    def dt(self) -> float:
        return min(self.wave, self.viscous, self.strain_rate)

    @property
    def binding(self) -> str:
        """The name of the smallest term."""
        return min(TERMS, key=lambda n: getattr(self, n))

    @property
    def reference_factor(self) -> float:
        """dt / fresh in (0, 1]: 1 when the reference's narrowest cell does not bind."""
        return self.dt / self.fresh if self.fresh > 0 else 1.0


def step_limits(dx: float, stretch: float, wave_speed: float, max_speed: float, cfl: float,
                kinematic_viscosity: float, dim: int, rate: float) -> StepLimits:
    """The terms for one body: ``stretch`` s, ``wave_speed`` c [m/s], ``max_speed``
    [m/s], ``kinematic_viscosity`` nu [m^2/s], ``rate`` |L| [1/s] (0: none)."""

    def wave(s):
        return cfl * s * dx / (wave_speed + max_speed)

    def viscous(s):
        return cfl * (s * dx) ** 2 / (2.0 * dim * kinematic_viscosity) if kinematic_viscosity > 0 else math.inf

    strain = STRAIN_STEP * cfl / rate if rate > 0 else math.inf
    return StepLimits(wave=wave(stretch), viscous=viscous(stretch), strain_rate=strain,
                      fresh=min(wave(1.0), viscous(1.0), strain))


class StepRule:
    """The step limits of one model's bodies after a step (the terms above,
    from a step's figures, mpm.stepping.status.StepReport); ``collider_speed`` [m/s]
    the fastest collider, which every particle may have to follow."""

    def __init__(self, model, collider_speed: float):
        self.model, self.collider_speed = model, collider_speed

    def limits(self, cfl: float, report=None, max_speed: float = 0.0) -> list[StepLimits]:
        """Per body, the terms of the step limit: the wave speed c(J_min) at
        the most compressed particle (grown by a stiffening material's
        factor), the narrowest reference cell s_min dx, viscous diffusion and
        the strain rate; at rest (J = s = 1, no rate) without ``report``,
        the particles at ``max_speed`` [m/s]."""
        m = self.model
        out = []
        for b, body in enumerate(m.scene.bodies):
            J, s, stiffening, rate = 1.0, 1.0, 1.0, 0.0
            if report is not None:
                J = float(report.min_J[b]) if math.isfinite(report.min_J[b]) else 1.0
                s = float(report.min_stretch[b]) if math.isfinite(report.min_stretch[b]) else 1.0
                if report.stiffening[b] > 0 and math.isfinite(report.stiffening[b]):
                    stiffening = float(report.stiffening[b])
                rate = float(report.max_rate[b])
            speed = report.max_speed if report is not None else max_speed
            speed = max(speed, self.collider_speed)
            c = body.material.wave_speed(min(max(J, 1e-3), 1.0)) * math.sqrt(stiffening)
            out.append(step_limits(m.dx, min(max(s, 1e-3), 1.0), c, speed, cfl,
                                   body.material.kinematic_viscosity(), m.dim, rate))
        return out

    def stable_dt(self, cfl: float, report=None, max_speed: float = 0.0) -> float:
        """The explicit step limit [s]: the smallest of :meth:`limits`."""
        return min(lim.dt for lim in self.limits(cfl, report, max_speed))

    def displacement_dt(self, fraction: float, report=None, max_speed: float = 0.0) -> float:
        """The implicit integrator's step limit [s]: a particle moves at most
        ``fraction`` of a cell per step at the speed of the last step (or
        ``max_speed`` before the first), the colliders' included."""
        speed = report.max_speed if report is not None else max_speed
        return displacement_dt(self.model.dx, max(speed, self.collider_speed), fraction)


# ---------------------------------------------------------------- on the device
BINDINGS = TERMS + ("dt_max", "fixed", "displacement")  # what bound a step: mpm.stepping.status ``binding``


@wp.struct
class BodyLaws:
    """Per body, what the step rule needs of its material (mpm.materials
    ``wave_speed_law``, ``kinematic_viscosity``), float64."""

    c0: wp.array(dtype=wp.float64)  # [m/s] the wave speed at rest
    a: wp.array(dtype=wp.float64)  # c(J) = sqrt(a J^b / rho) when b != 0
    b: wp.array(dtype=wp.float64)
    rho: wp.array(dtype=wp.float64)  # [kg/m^3]
    nu: wp.array(dtype=wp.float64)  # [m^2/s] kinematic viscosity


def body_laws(materials, device) -> BodyLaws:  # pyright: ignore[reportGeneralTypeIssues]  (a wp.struct)
    laws = BodyLaws()
    rows = np.array([m.wave_speed_law() for m in materials], dtype=np.float64).reshape(-1, 4)
    with wp.ScopedDevice(device):
        laws.c0, laws.a, laws.b, laws.rho = (wp.array(rows[:, k].copy(), dtype=wp.float64) for k in range(4))
        laws.nu = wp.array([m.kinematic_viscosity() for m in materials], dtype=wp.float64)
    return laws


@wp.func
def pymin(a: wp.float64, b: wp.float64):
    """Python's min(a, b): b only if b < a (NaN never wins)."""
    if b < a:
        return b
    return a


@wp.func
def pymax(a: wp.float64, b: wp.float64):
    """Python's max(a, b): b only if b > a."""
    if b > a:
        return b
    return a


@wp.func
def wave_speed(laws: BodyLaws, i: int, J: wp.float64):  # pyright: ignore[reportGeneralTypeIssues]
    """Body i's wave speed at volume ratio J [m/s]."""
    if laws.b[i] == wp.float64(0.0):
        return laws.c0[i]
    return wp.sqrt(laws.a[i] * wp.pow(J, laws.b[i]) / laws.rho[i])


@functools.cache
def make_step_rule(dim: int):
    """``limits(dx, s, c, speed, cfl, nu, rate) -> (wave, viscous, strain_rate,
    fresh)``: :func:`step_limits` on the device, the same float64 arithmetic."""
    f64 = wp.float64
    inf = f64(math.inf)
    two_dim = 2.0 * dim

    @wp.func
    def terms(dx: f64, s: f64, c: f64, speed: f64, cfl: f64, nu: f64):
        wave = cfl * s * dx / (c + speed)
        viscous = inf
        if nu > f64(0.0):  # (s dx)^2 by pow, as the host's ** does
            viscous = cfl * wp.pow(s * dx, f64(2.0)) / (f64(two_dim) * nu)
        return wave, viscous

    @wp.func
    def limits(dx: f64, s: f64, c: f64, speed: f64, cfl: f64, nu: f64, rate: f64):
        wave, viscous = terms(dx, s, c, speed, cfl, nu)
        strain = inf
        if rate > f64(0.0):
            strain = f64(STRAIN_STEP) * cfl / rate
        wave1, viscous1 = terms(dx, f64(1.0), c, speed, cfl, nu)
        fresh = pymin(pymin(wave1, viscous1), strain)
        return wave, viscous, strain, fresh

    return limits


def collapse_reason(driver, v: dict) -> str:
    """Why ``driver`` (an mpm.Driver) cannot take its next step, from the step buffer's values ``v``."""
    p, dt0, limit = driver.policy, driver.dt_first, float(v["dt_limit"][0])
    if p.dt is None and dt0 is not None and not (limit >= p.dt_collapse * dt0):
        said = f"time step collapsed to {limit:.3g} s, below {p.dt_collapse:g} of the first step ({dt0:.3g} s)"
        s_min = math.sqrt(float(np.min(v["min_stretch2"])))  # the narrowest reference cell (inf: Eulerian)
        if not s_min < CRUSHED:
            return f"{said}: a particle's strain rate or compression is running away"
        cause = f"{said}: a reference cell is crushed to {s_min:.2g} of its width"
        scheme = driver.solver.scheme.name
        if scheme == "tlmpm":
            return (f"{cause}; TLMPM never updates its reference, so this is the method's limit "
                    f"(scheme=empm or aulmpm update it)")
        if scheme == "aulmpm":
            return f"{cause}; A-ULMPM's criterion did not update it in time (scheme.stretch_min bounds it)"
        return cause
    speed = math.sqrt(v["max_v2"][0]) if driver.step else driver.v0
    return f"the time step is {driver.dt:.3g} s (fastest particle {speed:.3g} m/s): the run cannot advance"
