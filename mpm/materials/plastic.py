"""Elastoplastic models in one formulation for every scheme.

The plastic state and the reference configuration
-------------------------------------------------
The deformation gradient splits multiplicatively, F = F_E F_P. The schemes
(mpm.schemes) carry per particle F^sn, the deformation since the body's last
configuration update, which is kinematic: it follows the grid velocities
(F^sn += dt C) and its reference is where the stencil weights were cached, so
plasticity must never touch it. Everything plastic lives in F^0s and in two
per-particle history variables:

    F_E = F^sn F^0s      at all times, i.e.  F^0s = F^0s_total F_P^-1,

F^0s is the part of the deformation at the last update that is still
elastic, given the plastic flow so far. Every step, in every scheme, P2G
takes the trial state F_E^tr = F^sn F^0s (F^sn already advanced by the last
G2P: F_E^tr = (F^sn_new (F^sn_old)^-1) F_E, the classic
F_E^tr = (I + dt grad v) F_E when F^sn_old = I), returns it to the yield
surface in principal stretches, and writes back

    F^0s <- (F^sn)^-1 F_E,    history <- updated history,

then evaluates the stress of F_E. Its pull-back to the reference grid is the
usual P(F^sn F^0s) F^0s^T = tau (F^sn)^-T, with tau = P F_E^T the Kirchhoff
stress: the force of the A-ULMPM paper (eq. 20) with F_E in place of F.

* EMPM (s = n): F^sn = I at every P2G, so F^0s = F_E: classic MLS-MPM
  plasticity (F_E stored, F_E^tr = (I + dt C) F_E), exactly.
* TLMPM (s = 0): F^sn = F is the total deformation and F^0s = F_P^-1.
* A configuration update (F^0s <- F^sn F^0s, F^sn <- I) maps F_E to itself and
  leaves the history alone: it changes where the stencil is cached, not the
  material state, so the return mapping sees the same trial state whether or
  not the body updated. The same homogeneous deformation history therefore
  gives the same stress in all three schemes (tested).
* The A-ULMPM criterion dJ = |det F^sn - 1| stays kinematic: for a plastic
  body it measures the total volume change of the reference cells since the
  update, elastic and plastic alike. It does not see isochoric plastic flow
  (von Mises, the deviatoric part of sand or snow flow), which shears the
  reference cells without changing their volume.

History variables (per particle, ``Types.history``): slot 0 is the model's
volumetric variable (log J_P for snow and NACC, the volume correction for
sand, unused otherwise), slot 1 the accumulated equivalent plastic strain
    eps_p = sum over steps sqrt(2/3) |ln sigma^tr - ln sigma_E|
(Hencky strains of the trial and returned principal stretches), which this
module updates for every model after its return mapping.

A model provides, in principal stretches sigma (singular values of F_E with
the sign convention of mpm.materials.decompositions):
* ``flow(sigma_tr, params, history, dt) -> (sigma_E, history)``: the return
  mapping (rate-dependent models use dt; dt = 0 must leave the state as a
  rate-independent projection would, so that a stress evaluation outside a
  step changes nothing);
* ``elasticity(sigma, params, history) -> (P_hat, psi)``: the principal first
  Piola-Kirchhoff stress and the energy per rest volume (mpm.materials.elasticity),
  and ``elasticity_hessian(sigma, params, history) -> H`` its principal
  Hessian (the implicit integrator's elastic predictor);
* optionally ``stiffening(params, history) -> factor``: how much the squared
  wave speed has grown from the rest value (snow hardening), for the time step.

:class:`HenckyPlastic` and :class:`SplitPlastic` give ``elasticity`` and
``elasticity_hessian`` for the Hencky and the split energies;
mpm.materials.return_map has the pieces the return mappings are built from.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np
import warp as wp

from ..types import Types
from .base import Isotropic, Material
from .decompositions import make_svd
from .elasticity import make_hencky, make_hencky_hessian, make_split, make_split_hessian, on_params

STRETCH_FLOOR = 1.0e-6  # |sigma| below this counts as this in logarithms
SQRT_2_3 = math.sqrt(2.0 / 3.0)


@dataclass
class Plastic(Isotropic):
    """Base of the elastoplastic models: the elastic parameters E, nu of
    :class:`Isotropic` (a model restates the defaults it changes) and the
    wave speed they give; each model packs its own parameters."""

    plastic: ClassVar[bool] = True
    flows: ClassVar[bool] = True
    flow: ClassVar[Callable[[Types], Callable]]
    elasticity: ClassVar[Callable[[Types], Callable]]
    elasticity_hessian: ClassVar[Callable[[Types], Callable]]
    stiffening: ClassVar[Callable[[Types], Callable] | None] = None
    history_names: ClassVar[tuple[str, str]] = ("", "plastic_strain")
    """names of the two history variables ("" for an unused slot)"""
    log_Jp: ClassVar[bool | None] = False
    """history slot 0 is ln J_P (True), the flow keeps the volume (False), or
    the plastic volume change is not tracked (None)"""

    packed = Material.packed  # not Isotropic's (mu, lambda) alone

    def initial_history(self) -> tuple[float, float]:
        return (0.0, 0.0)

    def fields(self, history: np.ndarray, J_E: np.ndarray) -> dict[str, np.ndarray]:
        """Per-particle fields to log, from the history variables (n, 2) and
        J_E = det(F^sn F^0s): the named history variables and, where the
        plastic volume is known, the density against the initial one,
        rho / rho0 = 1 / (J_E J_P / J_P0) (after a step J_E is the trial
        state's and the history the last return's, so their product is the
        current volume ratio)."""
        out = {name: history[:, i] for i, name in enumerate(self.history_names) if name}
        if self.log_Jp is not None:
            J_P = np.exp(history[:, 0] - self.initial_history()[0]) if self.log_Jp else 1.0
            out["density_ratio"] = 1.0 / (J_E * J_P)
        return out


@dataclass
class HenckyPlastic(Plastic):
    """A plastic model with St. Venant-Kirchhoff-Hencky elasticity,
    (mu, lam) = params[0:2] (mpm.materials.elasticity)."""

    elasticity = staticmethod(on_params(make_hencky))
    elasticity_hessian = staticmethod(on_params(make_hencky_hessian))


@dataclass
class SplitPlastic(Plastic):
    """A plastic model with the deviatoric / volumetric split energy,
    (mu, kappa) = params[0:2] (mpm.materials.elasticity)."""

    elasticity = staticmethod(on_params(make_split))
    elasticity_hessian = staticmethod(on_params(make_split_hessian))


@functools.cache
def make_plastic_update(t: Types, cls: type[Plastic]):
    """``plastic_update(F_tr, params, history, dt) -> (F_E, P, psi, history)``:
    the return mapping of ``cls`` on the trial elastic deformation F_tr, the
    plastic-strain bookkeeping, and the stress P [Pa] and energy psi [J/m^3]
    of the returned F_E, with one SVD."""
    S = t.scalar
    vec = t.vec
    svd = make_svd(t)
    flow = cls.flow(t)
    elasticity = cls.elasticity(t)

    @wp.func
    def plastic_update(F: t.mat, params: t.params, history: t.history, dt: S):
        U, sig, V = svd(F)
        sig_E, h = flow(sig, params, history, dt)
        de = vec()
        for i in range(wp.static(t.dim)):
            de[i] = (wp.log(wp.max(wp.abs(sig[i]), S(STRETCH_FLOOR)))  # pyright: ignore[reportArgumentType]
                     - wp.log(wp.max(sig_E[i], S(STRETCH_FLOOR))))  # pyright: ignore[reportArgumentType]
        h[1] = h[1] + S(SQRT_2_3) * wp.length(de)
        P_hat, psi = elasticity(sig_E, params, h)
        Vt = wp.transpose(V)
        return U * wp.diag(sig_E) * Vt, U * wp.diag(P_hat) * Vt, psi, h

    return plastic_update
