"""Viscoplastic fluid: Herschel-Bulkley (Bingham for flow_index = 1) on the
elastic left Cauchy-Green strain, after Yue et al. 2015.

Elasticity: the split energy of mpm.materials.elasticity (shear modulus mu,
bulk modulus kappa = lam + 2 mu / 3), deviatoric Kirchhoff stress
s = mu dev(b_bar), b_bar = J^(-2/d) b_E. Above the yield surface the trial
deviator relaxes at fixed direction and volume,
    |s_tr| - |s| = 2 mu_hat dt |D_p|,    mu_hat = mu tr(b_bar)/d,
with the plastic rate of deformation |D_p| given by the flow curve
    |s| = sqrt(2) tau_Y + sqrt(2) K (sqrt(2) |D_p|)^n      (|s| > sqrt(2) tau_Y),
i.e., in steady simple shear at rate gamma_dot (|D| = gamma_dot / sqrt(2)),
the Herschel-Bulkley law  tau_xy = tau_Y + K gamma_dot^n  once the elastic
strain has settled (tested at a material point). Here ``yield_stress`` is the
yield stress in simple shear tau_Y (the uniaxial, von Mises one is
sqrt(3) tau_Y: Yue et al.'s sqrt(2/3) sigma_Y = sqrt(2) tau_Y) and
``viscosity`` the consistency K [Pa s^n] (n = 1: the plastic viscosity
above yield; Yue et al.'s eta = 2^((n+1)/2) K). The scalar equation for |s| is
solved in closed form for n = 1 and by a bracketed Newton iteration
otherwise. dt = 0 (a stress evaluation outside a step) relaxes nothing.
The time scale K / mu of the relaxation is resolved implicitly: any dt works.
"""

import functools
import math
from dataclasses import dataclass

import warp as wp

from ..params import param
from ..types import Types
from .base import lame
from .plastic import SplitPlastic
from .return_map import make_isochoric_b, make_stretches_of_b

NEWTON_ITERATIONS = 40
SQRT2 = math.sqrt(2.0)


@functools.cache
def _flow(t: Types):
    S = t.scalar
    isochoric_b = make_isochoric_b(t)
    stretches_of_b = make_stretches_of_b(t)

    @wp.func
    def flow(sigma: t.vec, params: t.params, history: t.history, dt: S):
        mu = params[0]
        tau_Y = params[2]
        K = params[3]
        n = params[4]
        stretches, J, mean, dev = isochoric_b(sigma)
        s_tr = mu * wp.length(dev)
        excess = s_tr - S(SQRT2) * tau_Y
        if excess <= S(0.0) or dt <= S(0.0):
            return stretches, history
        # x = |s| - sqrt(2) tau_Y solves x + c x^(1/n) = excess,
        # c = 2 mu_hat dt / sqrt(2) (sqrt(2) K)^(-1/n)
        c = S(SQRT2) * mu * mean * dt * wp.pow(S(SQRT2) * K, -S(1.0) / n)
        x = excess / (S(1.0) + c)  # n = 1
        if n != S(1.0):
            lo = S(0.0)
            hi = excess
            x = S(0.5) * excess
            for _ in range(NEWTON_ITERATIONS):
                xn = wp.pow(x, S(1.0) / n)
                g = x + c * xn - excess
                if g > S(0.0):
                    hi = x
                else:
                    lo = x
                step = g / (S(1.0) + c * xn / (n * x))
                nx = x - step
                if nx <= lo or nx >= hi:
                    nx = S(0.5) * (lo + hi)
                x = nx
        return stretches_of_b(mean, ((S(SQRT2) * tau_Y + x) / s_tr) * dev, J), history

    return flow


@dataclass
class Viscoplastic(SplitPlastic):
    """Herschel-Bulkley / Bingham viscoplastic fluid (Yue et al. 2015)."""

    name = "viscoplastic"
    flow = staticmethod(_flow)

    E: float = param(1.0e5, "Young's modulus of the elastic response [Pa]", gt=0.0)
    yield_stress: float = param(50.0, "yield stress in simple shear tau_Y [Pa]", ge=0.0)
    viscosity: float = param(10.0, "consistency K of tau = tau_Y + K gamma_dot^n [Pa s^n]", gt=0.0)
    flow_index: float = param(1.0, "n: 1 Bingham, < 1 shear-thinning, > 1 shear-thickening [-]",
                              gt=0.0)

    def packed(self):
        mu, lam = lame(self.E, self.nu)
        return (mu, lam + 2.0 * mu / 3.0, self.yield_stress, self.viscosity, self.flow_index)
