"""Non-associative Cam-Clay (NACC, Wolper et al. 2019): clay, soil, crumbly
solids; the return mapping of the CK-MPM / claymore codes.

Elasticity: the split energy of mpm.materials.elasticity with the shear
modulus mu and the bulk modulus kappa = lam + 2 mu / 3 (in 2D too: a
property of the material, not of the simulation), so that the trial
pressure and deviatoric Kirchhoff stress are
    p = -kappa/2 (J^2 - 1),    s = mu J^(-2/d) dev(b),  b_i = sigma_i^2.
Yield surface, an ellipse in (p, q = sqrt(3/2) |s|):
    y = (1 + 2 beta) q^2 + M^2 (p + beta p0)(p - p0) <= 0,
    p0 = kappa (1e-5 + sinh(xi max(-alpha, 0))),
with alpha = ln J_P (history slot 0, initially ``alpha0``): compaction
(alpha < 0) hardens the material. Return mapping:
  1. p outside [-beta p0, p0]: project to the nearest tip, J_E = sqrt(1 - 2p/kappa),
     b isotropic (no shear stress); alpha += ln(J / J_E) (with hardening);
  2. y > 0: scale s radially at fixed p onto the ellipse (volume kept); with
     hardening, alpha += ln(J / J_x) with J_x the volume at the point where the
     line from the ellipse's centre ((1 - beta) p0 / 2, 0) to the trial state
     meets the ellipse - once per step (one public code applies it nine times).
Under steady loading with hardening, plastic and elastic steps alternate
(each plastic step grows the ellipse past the next trial state), so which
steps yield is decided by round-off: a 1e-13 change of a material point's
deformation path reaches 1e-3 in F_E within 70 steps, and two runs that
differ by round-off (another scheme, another summation order) part ways.
M relates to a friction angle by M = 6 sin phi / (3 - sin phi) (M = 2.36 is
about 58 deg); ``friction_angle`` may be given instead of M. CK-MPM scenes
(E, nu, alpha0, beta, xi, M): pumpkin 2000, 0.39, -0.04, 2, 3, 2.36; oreo
2e4, 0.4, -0.01, 0.5, 0.8, 2.36; sandcastle 1e4, 0.3, -0.006, 0.3, 0.5, 1.85.
Those scenes pass (lambda, mu) where the constructor takes (mu, lambda):
derive both from (E, nu) here.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..params import param
from ..types import Types
from .base import lame
from .plastic import SplitPlastic
from .return_map import make_isochoric_b, make_stretches_of_b

JE2_FLOOR = 1.0e-4  # smallest J_E^2 a tip projection may produce


def friction_to_M(phi_deg: float) -> float:
    """Slope M of the critical state line for a friction angle [deg]."""
    s = math.sin(math.radians(phi_deg))
    return 6.0 * s / (3.0 - s)


@functools.cache
def _flow(t: Types):
    S = t.scalar
    vec = t.vec
    isochoric_b = make_isochoric_b(t)
    stretches_of_b = make_stretches_of_b(t)

    @wp.func
    def flow(sigma: t.vec, params: t.params, history: t.history, dt: S):
        mu = params[0]
        kappa = params[1]
        beta = params[2]
        xi = params[3]
        M2 = params[4] * params[4]
        hardening = params[5] > S(0.5)
        h = history
        p0 = kappa * (S(1.0e-5) + wp.sinh(xi * wp.max(-h[0], S(0.0))))
        p_min = -beta * p0
        stretches, J, mean, dev = isochoric_b(sigma)
        s = mu * dev
        p = -S(0.5) * kappa * (J * J - S(1.0))
        if p > p0 or p < p_min:  # beyond a tip: isotropic (no deviator), on the tip
            p = wp.clamp(p, p_min, p0)
            JE = wp.sqrt(wp.max(S(1.0) - S(2.0) * p / kappa, S(JE2_FLOOR)))  # pyright: ignore[reportArgumentType]
            if hardening:
                h[0] = h[0] + wp.log(J / JE)
            return stretches_of_b(mean, vec(), JE), h
        s2 = wp.dot(s, s)
        a_q = S(1.5) * (S(1.0) + S(2.0) * beta)
        y_p = M2 * (p - p_min) * (p - p0)  # <= 0 between the tips
        if a_q * s2 + y_p <= S(0.0) or s2 <= S(0.0):  # inside: elastic
            return stretches, h
        # scale s onto the ellipse at fixed p (J kept exactly)
        c = wp.sqrt(-y_p / a_q / s2)
        out = stretches_of_b(mean, c * dev, J)
        if hardening and p0 > S(1.0e-12) * kappa:
            # where the line from the centre to the trial state meets the ellipse
            pc = S(0.5) * (S(1.0) - beta) * p0
            q = wp.sqrt(S(1.5) * s2)
            d0 = pc - p
            d1 = -q
            n = wp.sqrt(d0 * d0 + d1 * d1)
            d0 = d0 / n
            d1 = d1 / n
            A = M2 * d0 * d0 + (S(1.0) + S(2.0) * beta) * d1 * d1
            B = M2 * d0 * (S(2.0) * pc - p0 - p_min)
            C = M2 * (pc - p_min) * (pc - p0)
            root = wp.sqrt(wp.max(B * B - S(4.0) * A * C, S(0.0)))  # pyright: ignore[reportArgumentType]
            p1 = pc + d0 * (-B + root) / (S(2.0) * A)
            p2 = pc + d0 * (-B - root) / (S(2.0) * A)
            px = p2
            if (p - pc) * (p1 - pc) > S(0.0):
                px = p1
            Jx2 = wp.abs(S(1.0) - S(2.0) * px / kappa)
            if Jx2 > S(JE2_FLOOR):
                h[0] = h[0] + wp.log(J / wp.sqrt(Jx2))  # pyright: ignore[reportArgumentType]
        return out, h

    return flow


@dataclass
class NACC(SplitPlastic):
    """Non-associative Cam-Clay with hardening on log J_P."""

    name = "nacc"
    flow = staticmethod(_flow)
    history_names = ("alpha", "plastic_strain")
    log_Jp = True

    E: float = param(2.0e4, "Young's modulus [Pa]", gt=0.0)
    nu: float = param(0.4, "Poisson's ratio [-]", gt=-1.0, lt=0.5)
    alpha0: float = param(-0.01, "initial alpha = ln J_P (< 0: compacted, p0 > 0) [-]", le=0.0)
    beta: float = param(0.5, "tension/compression ratio of the ellipse: tips at -beta p0, p0 [-]",
                        ge=0.0)
    xi: float = param(0.8, "hardening: p0 = kappa (1e-5 + sinh(xi max(-alpha, 0))) [-]", ge=0.0)
    M: float | None = param(2.36, "slope of the critical state line (null: from friction_angle) [-]",
                            gt=0.0)
    friction_angle: float | None = param(None, "friction angle [deg], instead of M: "
                                               "M = 6 sin phi / (3 - sin phi)", gt=0.0, lt=90.0)
    hardening: bool = param(True, "alpha follows the plastic volume change (false: the ellipse never "
                                  "changes)")

    def slope(self) -> float:
        if self.friction_angle is not None:
            return friction_to_M(self.friction_angle)
        assert self.M is not None, "checked by problems(): M or friction_angle"
        return self.M

    def problems(self):
        if self.M is not None and self.friction_angle is not None:
            return [("friction_angle", f"{self.friction_angle} given with M = {self.M}; accepted: "
                                       "one of them (set M: null to use friction_angle)")]
        if self.M is None and self.friction_angle is None:
            return [("M", "null without a friction_angle; accepted: M > 0 or friction_angle")]
        return []

    def kappa(self) -> float:
        mu, lam = lame(self.E, self.nu)
        return lam + 2.0 * mu / 3.0

    def packed(self):
        mu, lam = lame(self.E, self.nu)
        return (mu, self.kappa(), self.beta, self.xi, self.slope(),
                1.0 if self.hardening else 0.0)

    def initial_history(self):
        return (self.alpha0, 0.0)

    def fields(self, history, J_E):
        out = super().fields(history, J_E)
        out["p0"] = self.kappa() * (1e-5 + np.sinh(self.xi * np.maximum(-history[:, 0], 0.0)))
        return out
