"""Dry sand: Drucker-Prager plasticity on the Hencky strain (Klar et al.
2016), St. Venant-Kirchhoff-Hencky elasticity, no tension.

Yield surface (Kirchhoff stress tau = 2 mu eps + lam tr(eps) 1 in principal
strains eps = ln sigma, pressure p = -tr(tau)/d):
    |dev tau| <= alpha d (p + c cot phi),
    3D: alpha = sqrt(2/3) 2 sin phi / (3 - sin phi), the cone through the
        compression meridian of Mohr-Coulomb (Klar et al.): in triaxial
        compression (sigma_2 = sigma_3) yield is exactly
        sigma_1 - sigma_3 = (sigma_1 + sigma_3) sin phi (compression positive),
        the Mohr circle touching tau = c + sigma_n tan phi;
    2D: alpha = sin phi / sqrt(2): with two principal stresses the cone is
        the Mohr-Coulomb criterion itself, so phi is the friction angle of the
        simulated plane. (Public 2D codes put d = 2 into the 3D alpha, which
        makes phi = 30 deg act as 27.5 deg.)
Cohesion c shifts the apex to the tension p = -c cot phi, where tr(eps)
reaches tr_apex = d c cot phi / (d lam + 2 mu). Return mapping of a trial strain,
corrected by the volume correction v (history slot 0, below):
    eps_c = eps + v/d 1
  1. tr eps_c >= tr_apex (tension beyond the apex): eps_E = tr_apex/d 1 (no
     shear stress, no stress at all without cohesion), v <- tr eps_c - tr_apex;
  2. otherwise v <- 0 and, with dg = |dev eps_c| + alpha (d lam + 2 mu)/(2 mu)
     (tr eps_c - tr_apex): if dg > 0, eps_E = eps_c - dg dev(eps_c)/|dev eps_c|
     (back onto the cone along the deviator; the volume is kept), else eps_E = eps_c.
Volume correction (Klar et al. 2016, Sec. 6.3): sand pulled apart in tension
loses contact; its dilation v = ln(J/J_E) is remembered, and when compressed
again the grains first close that gap before they push back. Without it,
dilated sand becomes artificially cohesive. Public codes differ here: one has
it commented out, others reset v but return the uncorrected strain; here the
remembered dilation is absorbed into F_E as soon as the sand is in
compression (as in Tampubolon et al. 2017).
Hardening (Klar et al. 2016, Table 3): phi(q) = phi0 + (h1 q - h3) exp(-h2 q),
q = sqrt(3/2) eps_p the accumulated plastic strain |delta eps_p| (history slot
1); h1 = h3 = 0 (the default) is a constant friction angle.
Paper parameters: E = 3.537e5 Pa, nu = 0.3, rho = 2200, phi0 = 35 deg,
h1 = 9 deg, h2 = 0.2, h3 = 10 deg. CK-MPM sand: E = 1e4, nu = 0.4, phi = 30.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..params import param
from ..types import Types
from .base import lame
from .plastic import SQRT_2_3, HenckyPlastic
from .return_map import make_deviator, make_exp_strain, make_hencky_strain, make_radial_return

DEG = math.pi / 180.0
INV_SQRT2 = 1.0 / math.sqrt(2.0)


@functools.cache
def _friction(t: Types):
    """``friction(params, eps_p) -> (alpha, apex)``: the cone's slope alpha and
    the trace tr_apex of the Hencky strain at its apex."""
    S = t.scalar
    d = float(t.dim)

    @wp.func
    def friction(params: t.params, eps_p: S):
        mu = params[0]
        lam = params[1]
        q = eps_p / S(SQRT_2_3)
        phi = params[2] + (params[3] * q - params[5]) * wp.exp(-params[4] * q)
        phi = wp.clamp(phi, S(1.0e-6), S(0.5 * math.pi - 1.0e-6))
        s = wp.sin(phi)
        alpha = S(0.0)
        if wp.static(t.dim == 2):
            alpha = s * S(INV_SQRT2)
        else:
            alpha = S(SQRT_2_3) * S(2.0) * s / (S(3.0) - s)
        apex = S(d) * params[6] * wp.cos(phi) / s / (S(d) * lam + S(2.0) * mu)
        return alpha, apex

    return friction


@functools.cache
def _flow(t: Types):
    S = t.scalar
    d = float(t.dim)
    friction = _friction(t)
    hencky_strain = make_hencky_strain(t)
    deviator = make_deviator(t)
    radial_return = make_radial_return(t)
    exp_strain = make_exp_strain(t)
    ones = t.vec(*([1.0] * t.dim))

    @wp.func
    def flow(sigma: t.vec, params: t.params, history: t.history, dt: S):
        mu = params[0]
        lam = params[1]
        alpha, apex = friction(params, history[1])
        eps, tr = hencky_strain(sigma)
        h = history
        # the remembered dilation, then the trace of the corrected strain
        eps = eps + (h[0] / S(d)) * ones
        tr = tr + h[0]
        if tr >= apex:  # tension beyond the apex: no shear stress
            h[0] = tr - apex
            return exp_strain((apex / S(d)) * ones), h
        h[0] = S(0.0)
        dev, norm = deviator(eps, tr)
        dg = norm + (S(d) * lam + S(2.0) * mu) / (S(2.0) * mu) * (tr - apex) * alpha
        return radial_return(eps, dev, norm, dg), h

    return flow


@dataclass
class Sand(HenckyPlastic):
    """Drucker-Prager sand on the Hencky strain, with volume correction."""

    name = "sand"
    flow = staticmethod(_flow)
    history_names = ("volume_correction", "plastic_strain")
    log_Jp = None  # the volume correction is the unrecovered dilation, not ln J_P

    rho: float = param(2200.0, "rest density [kg/m^3]", gt=0.0)
    E: float = param(3.537e5, "Young's modulus [Pa]", gt=0.0)
    friction_angle: float = param(30.0, "friction angle phi0 [deg]", gt=0.0, lt=90.0)
    cohesion: float = param(0.0, "cohesion c [Pa]: the cone's apex at the tension c cot phi", ge=0.0)
    h1: float = param(0.0, "hardening: phi(q) = phi0 + (h1 q - h3) exp(-h2 q) [deg]", ge=0.0)
    h2: float = param(0.0, "hardening decay h2 [-]", ge=0.0)
    h3: float = param(0.0, "hardening: initial softening h3 [deg]", ge=0.0, lt=90.0)

    def packed(self):
        mu, lam = lame(self.E, self.nu)
        return (mu, lam, self.friction_angle * DEG, self.h1 * DEG, self.h2, self.h3 * DEG,
                self.cohesion)

    def problems(self):
        if self.friction_angle - self.h3 <= 0.0:
            return [("h3", f"{self.h3} leaves no friction at q = 0 (friction_angle - h3 = "
                           f"{self.friction_angle - self.h3:g}); accepted: h3 < friction_angle")]
        return []

    def friction_angle_at(self, plastic_strain: np.ndarray) -> np.ndarray:
        """phi(q) [deg] at the accumulated plastic strain."""
        q = np.asarray(plastic_strain) / SQRT_2_3
        return self.friction_angle + (self.h1 * q - self.h3) * np.exp(-self.h2 * q)

    def fields(self, history, J_E):
        out = super().fields(history, J_E)
        if self.h1 or self.h3:
            out["friction_angle"] = self.friction_angle_at(history[:, 1])
        return out
