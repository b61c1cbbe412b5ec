"""Snow (Stomakhin et al. 2013): fixed corotated elasticity on F_E with
hardening, plasticity by clamping the principal stretches.

Return mapping (principal stretches sigma of the trial F_E):
    sigma_E = clamp(sigma, 1 - theta_c, 1 + theta_s),
    J_P <- J_P prod(sigma) / prod(sigma_E)      (F = F_E F_P, J fixed),
stress: fixed corotated with mu, lambda scaled by the hardening factor
    h = exp(xi (1 - J_P))      (mpm.materials.elasticity.fixed_corotated).
History: slot 0 log J_P, slot 1 the equivalent plastic strain.
Defaults are the paper's (E0 = 1.4e5 Pa, nu = 0.2, rho = 400, theta_c =
2.5e-2, theta_s = 7.5e-3, xi = 10). Several public codes use theta_s =
4.5e-3 and clamp h to [0.1, 5]; here h is not clamped, and the time step
follows the stiffest particle (the wave speed grows as sqrt(h)).
"""

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..params import param
from ..types import Types
from .base import lame
from .elasticity import make_fixed_corotated, make_fixed_corotated_hessian, on_params
from .plastic import STRETCH_FLOOR, Plastic


@functools.cache
def _flow(t: Types):
    S = t.scalar
    vec = t.vec

    @wp.func
    def flow(sigma: t.vec, params: t.params, history: t.history, dt: S):
        lo = S(1.0) - params[2]
        hi = S(1.0) + params[3]
        sig_E = vec()
        dlogJ = S(0.0)
        for i in range(wp.static(t.dim)):
            sig_E[i] = wp.clamp(sigma[i], lo, hi)
            dlogJ += wp.log(wp.max(wp.abs(sigma[i]), S(STRETCH_FLOOR))) - wp.log(sig_E[i])  # pyright: ignore[reportArgumentType]
        h = history
        h[0] = h[0] + dlogJ
        return sig_E, h

    return flow


@functools.cache
def _stiffening(t: Types):
    """The hardening factor exp(xi (1 - J_P)) that scales the moduli (and the
    squared wave speed)."""
    S = t.scalar

    @wp.func
    def stiffening(params: t.params, history: t.history):
        return wp.exp(params[4] * (S(1.0) - wp.exp(history[0])))

    return stiffening


@functools.cache
def _hardened(t: Types):
    """``moduli(params, history) -> (h mu, h lam)``, h the hardening factor."""
    stiffening = _stiffening(t)

    @wp.func
    def hardened(params: t.params, history: t.history):
        harden = stiffening(params, history)
        return harden * params[0], harden * params[1]

    return hardened


@dataclass
class Snow(Plastic):
    """Elastoplastic snow with hardening."""

    name = "snow"
    invertible = True  # fixed corotated elasticity (its hardening reads the plastic J only)
    flow = staticmethod(_flow)
    elasticity = staticmethod(on_params(make_fixed_corotated, _hardened))
    elasticity_hessian = staticmethod(on_params(make_fixed_corotated_hessian, _hardened))
    stiffening = staticmethod(_stiffening)
    history_names = ("log_Jp", "plastic_strain")
    log_Jp = True

    rho: float = param(400.0, "rest density [kg/m^3]", gt=0.0)
    E: float = param(1.4e5, "Young's modulus E0 of the uncompacted snow [Pa]", gt=0.0)
    nu: float = param(0.2, "Poisson's ratio [-]", gt=-1.0, lt=0.5)
    theta_c: float = param(2.5e-2, "critical compression: sigma >= 1 - theta_c [-]", ge=0.0, lt=1.0)
    theta_s: float = param(7.5e-3, "critical stretch: sigma <= 1 + theta_s [-]", ge=0.0)
    xi: float = param(10.0, "hardening coefficient: moduli scale by exp(xi (1 - J_P)) [-]", ge=0.0)

    def packed(self):
        mu, lam = lame(self.E, self.nu)
        return (mu, lam, self.theta_c, self.theta_s, self.xi)

    def fields(self, history, J_E):
        out = super().fields(history, J_E)
        J_P = np.exp(out.pop("log_Jp"))
        return {"J_P": J_P, "hardening": np.exp(self.xi * (1.0 - J_P)), **out}
