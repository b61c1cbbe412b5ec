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

from __future__ import annotations

import math
from dataclasses import dataclass

STRAIN_STEP = 0.25  # dt |L| <= STRAIN_STEP * cfl: the strain increment of one step
TERMS = ("wave", "viscous", "strain_rate")


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
