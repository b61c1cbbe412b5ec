"""Compressible neo-Hookean elasticity.

P = mu (F - F^-T) + lambda ln(J) F^-T,
psi = mu/2 (tr(F^T F) - d) - mu ln J + lambda/2 (ln J)^2.
"""

import functools
from dataclasses import dataclass

import warp as wp

from ..params import param
from ..types import Types
from .elasticity import make_neo_hookean_law, on_params
from .base import Material, elastic_wave_speed, lame


@functools.cache
def _stress_energy(t: Types):
    S = t.scalar
    d = float(t.dim)

    @wp.func
    def stress_energy(F: t.mat, L: t.mat, params: t.params):
        mu = params[0]
        lam = params[1]
        FinvT = wp.transpose(wp.inverse(F))
        lnJ = wp.log(wp.determinant(F))
        P = mu * (F - FinvT) + lam * lnJ * FinvT
        psi = S(0.5) * mu * (wp.ddot(F, F) - S(d)) - mu * lnJ + S(0.5) * lam * lnJ * lnJ
        return P, psi

    return stress_energy


@dataclass
class NeoHookean(Material):
    """Compressible neo-Hookean hyperelastic solid."""

    name = "neo_hookean"
    stress_energy = staticmethod(_stress_energy)
    principal = staticmethod(on_params(make_neo_hookean_law))

    E: float = param(1.0e5, "Young's modulus [Pa]", gt=0.0)
    nu: float = param(0.3, "Poisson's ratio [-]", gt=-1.0, lt=0.5)

    def packed(self):
        return lame(self.E, self.nu)

    def wave_speed(self, J: float = 1.0):
        return elastic_wave_speed(self.E, self.nu, self.rho)
