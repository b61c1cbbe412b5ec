"""Stable explicit time step.

dt = cfl * dx / (c + max|v|)           (acoustic CFL: c the fastest wave speed)
dt <= cfl * dx^2 / (2 d nu)            (viscous diffusion, nu kinematic viscosity)
"""

from __future__ import annotations


def cfl_dt(dx: float, wave_speed: float, max_speed: float, cfl: float,
           kinematic_viscosity: float = 0.0, dim: int = 2) -> float:
    dt = cfl * dx / (wave_speed + max_speed)
    if kinematic_viscosity > 0.0:
        dt = min(dt, cfl * dx * dx / (2.0 * dim * kinematic_viscosity))
    return dt
