"""Von Mises (J2) plasticity on the Hencky strain with linear isotropic
hardening; St. Venant-Kirchhoff-Hencky elasticity (metals, clay-like solids).

Convention: ``yield_stress`` sigma_y is the uniaxial yield stress, i.e. the
von Mises equivalent stress sqrt(3/2) |dev tau| (Kirchhoff; equal to the
Cauchy stress for the nearly isochoric states of J2 flow) at yield. The yield
surface's radius in the Frobenius norm of dev tau is therefore
sqrt(2/3) sigma_y. (Public codes often call the radius itself sigma_y, which
is sqrt(3/2) = 1.22 times more than the uniaxial stress at yield.)

Radial return of the Hencky strain eps = ln sigma (principal), with the
equivalent plastic strain eps_p (history slot 1) and
sigma_y(eps_p) = sigma_y + H eps_p:
    delta = (2 mu |dev eps| - sqrt(2/3) sigma_y(eps_p)) / (2 mu + 2 H / 3);
    if delta > 0:  eps <- eps - delta dev(eps) / |dev eps|,
so that |dev tau| = sqrt(2/3) sigma_y(eps_p + sqrt(2/3) delta) after the step.
The volume is never changed by the flow. In 2D the deviator is the 2D one
(d = 2, as in the public 2D codes). CK-MPM fire hydrant: E = 1e9,
nu = 0.4, sigma_y = 3e6 (as the radius in that code).
"""

import functools
from dataclasses import dataclass

import warp as wp

from ..params import param
from ..types import Types
from .base import lame
from .plastic import SQRT_2_3, HenckyPlastic
from .return_map import make_deviator, make_hencky_strain, make_radial_return

TWO_THIRDS = 2.0 / 3.0  # a Python float: inside the Warp function 2.0 / 3.0 is a float32 quotient


@functools.cache
def _flow(t: Types):
    S = t.scalar
    hencky_strain = make_hencky_strain(t)
    deviator = make_deviator(t)
    radial_return = make_radial_return(t)

    @wp.func
    def flow(sigma: t.vec, params: t.params, history: t.history, dt: S):
        mu = params[0]
        H = params[3]
        eps, tr = hencky_strain(sigma)
        dev, norm = deviator(eps, tr)
        yield_stress = params[2] + H * history[1]
        delta = (S(2.0) * mu * norm - S(SQRT_2_3) * yield_stress) / (S(2.0) * mu + S(TWO_THIRDS) * H)
        return radial_return(eps, dev, norm, delta), history

    return flow


@dataclass
class VonMises(HenckyPlastic):
    """J2 plasticity with linear hardening on the Hencky strain."""

    name = "von_mises"
    flow = staticmethod(_flow)

    E: float = param(1.0e6, "Young's modulus [Pa]", gt=0.0)
    yield_stress: float = param(1.0e4, "uniaxial yield stress sigma_y [Pa]", ge=0.0)
    hardening: float = param(0.0, "linear hardening modulus H: sigma_y + H eps_p [Pa]", ge=0.0)

    def packed(self):
        mu, lam = lame(self.E, self.nu)
        return (mu, lam, self.yield_stress, self.hardening)

    def fields(self, history, J_E):
        out = super().fields(history, J_E)
        if self.hardening:
            out["yield_stress"] = self.yield_stress + self.hardening * history[:, 1]
        return out
