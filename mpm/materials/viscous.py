"""Newtonian viscous fluid, weakly compressible: a J-based Tait pressure and
the viscous stress of the true velocity gradient.

p = K (J^-gamma - 1),  sigma = -p I + 2 eta sym(L),  P = J sigma F^-T,
psi(J) = K (J^(1-gamma) / (gamma - 1) + J - gamma / (gamma - 1))
(so that p = -dpsi/dJ and psi(1) = 0; viscosity stores no energy), with
eta the dynamic viscosity [Pa s] and L = C (F^sn)^-1 the velocity gradient in
current coordinates [1/s]: the viscous stress is a rate, not an elastic
stress of a one-step deformation, so its effect does not depend on dt (a
shear wave decays at the rate eta k^2 / rho: tested). The explicit step obeys
dt <= cfl dx^2 / (2 d eta / rho) (mpm.stepping.timestep).

The deformation gradient keeps only its volume change: on every update of the
reference configuration F <- J^(1/d) I, so shear never accumulates.
"""

import functools
import math
from dataclasses import dataclass

import warp as wp

from ..params import param
from ..types import Types
from .base import Material
from .elasticity import make_tait_law, on_params


@functools.cache
def _stress_energy(t: Types):
    S = t.scalar
    dim = t.dim

    @wp.func
    def stress_energy(F: t.mat, L: t.mat, params: t.params):
        K = params[0]
        gamma = params[1]
        viscosity = params[2]
        J = wp.determinant(F)
        p = K * (wp.pow(J, -gamma) - S(1.0))
        sigma = -p * wp.identity(n=dim, dtype=S)
        if viscosity > S(0.0):  # (an inviscid fluid never reads L, which may not be finite)
            sigma += viscosity * (L + wp.transpose(L))
        P = J * sigma * wp.transpose(wp.inverse(F))
        psi = K * (wp.pow(J, S(1.0) - gamma) / (gamma - S(1.0)) + J - gamma / (gamma - S(1.0)))
        return P, psi

    return stress_energy


@functools.cache
def _project(t: Types):
    """``project(F, params) -> J^(1/d) I``: only the volume change is kept."""
    S, dim = t.scalar, t.dim
    inv_dim = 1.0 / t.dim

    @wp.func
    def project(F: t.mat, params: t.params):
        J = wp.determinant(F)
        return wp.pow(J, S(inv_dim)) * wp.identity(n=dim, dtype=S)

    return project


@dataclass
class Viscous(Material):
    """Weakly compressible Newtonian viscous fluid."""

    name = "viscous"
    stress_energy = staticmethod(_stress_energy)
    project = staticmethod(_project)
    principal = staticmethod(on_params(make_tait_law))  # (K, gamma) = params[0:2]
    viscosity_param = 2  # params[2] is eta
    needs_velocity_gradient = True
    stiffens = True
    flows = True
    fluid = True

    K: float = param(1.0e5, "pressure stiffness K of p = K (J^-gamma - 1) [Pa]; the default's sound "
                            "speed sqrt(K gamma / rho) is 26 m/s", gt=0.0)
    gamma: float = param(7.0, "Tait exponent gamma [-]", gt=1.0)
    viscosity: float = param(1.0, "dynamic viscosity eta [Pa s]", ge=0.0)

    def packed(self):
        return (self.K, self.gamma, self.viscosity)

    def wave_speed(self, J: float = 1.0):
        # c^2 = dp/drho with rho = rho0 / J: K gamma J^(1 - gamma) / rho0, which
        # grows fast under compression (J^-6 for gamma = 7)
        return math.sqrt(self.K * self.gamma * J ** (1.0 - self.gamma) / self.rho)

    def wave_speed_law(self):
        return self.wave_speed(), self.K * self.gamma, 1.0 - self.gamma, self.rho

    def kinematic_viscosity(self):
        return self.viscosity / self.rho


@dataclass
class Fluid(Viscous):
    """The weakly compressible fluid without viscosity by default (``viscous``
    with eta = 0), kept under its own name."""

    name = "fluid"

    viscosity: float = param(0.0, "dynamic viscosity eta [Pa s]", ge=0.0)
