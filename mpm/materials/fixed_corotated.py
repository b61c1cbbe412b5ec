"""Fixed corotated elasticity (Stomakhin et al. 2012).

P = 2 mu (F - R) + lambda (J - 1) J F^-T,
psi = mu |F - R|^2 + lambda/2 (J - 1)^2, with R the rotation of F = R S.
"""

import functools
from dataclasses import dataclass

import warp as wp

from ..types import Types
from .base import Isotropic
from .decompositions import make_rotation
from .elasticity import make_fixed_corotated_law, on_params


@functools.cache
def _stress_energy(t: Types):
    rotation = make_rotation(t)
    S = t.scalar

    @wp.func
    def stress_energy(F: t.mat, L: t.mat, params: t.params):
        mu = params[0]
        lam = params[1]
        R = rotation(F)
        J = wp.determinant(F)
        D = F - R
        P = S(2.0) * mu * D + lam * (J - S(1.0)) * J * wp.transpose(wp.inverse(F))
        psi = mu * wp.ddot(D, D) + S(0.5) * lam * (J - S(1.0)) * (J - S(1.0))
        return P, psi

    return stress_energy


@dataclass
class FixedCorotated(Isotropic):
    """Fixed corotated hyperelastic solid."""

    name = "fixed_corotated"
    invertible = True  # |F - R|^2 and (J - 1)^2 hold for any F
    stress_energy = staticmethod(_stress_energy)
    principal = staticmethod(on_params(make_fixed_corotated_law))
