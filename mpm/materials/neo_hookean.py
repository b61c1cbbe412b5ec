"""Compressible neo-Hookean elasticity.

P = mu (F - F^-T) + lambda ln(J) F^-T,
psi = mu/2 (tr(F^T F) - d) - mu ln J + lambda/2 (ln J)^2.
"""

import functools
from dataclasses import dataclass

import warp as wp

from ..types import Types
from .elasticity import make_neo_hookean_law, on_params
from .base import Isotropic


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
class NeoHookean(Isotropic):
    """Compressible neo-Hookean hyperelastic solid."""

    name = "neo_hookean"
    stress_energy = staticmethod(_stress_energy)
    principal = staticmethod(on_params(make_neo_hookean_law))
