"""Isotropic elastic energies in principal stretches, for the plastic models.

Each ``law(sigma, a, b) -> (P_hat, psi)`` takes the singular values sigma of
the elastic deformation gradient F_E = U diag(sigma) V^T and two moduli, and
returns the principal first Piola-Kirchhoff stress P_hat_i = d psi / d sigma_i
[Pa] (so P = U diag(P_hat) V^T, and the Kirchhoff stress
tau = P F_E^T = U diag(P_hat_i sigma_i) U^T) and the energy psi per unit
rest volume [J/m^3]. J = prod sigma_i.

* ``fixed_corotated(sigma, mu, lam)`` (Stomakhin et al. 2012):
  psi = mu sum (sigma_i - 1)^2 + lam/2 (J - 1)^2,
  P_hat_i = 2 mu (sigma_i - 1) + lam (J - 1) J / sigma_i.
* ``hencky(sigma, mu, lam)`` (St. Venant-Kirchhoff on the Hencky strain
  eps_i = ln sigma_i, Klar et al. 2016): psi = mu |eps|^2 + lam/2 (tr eps)^2,
  tau_i = 2 mu eps_i + lam tr eps.
* ``split(sigma, mu, kappa)`` (deviatoric / volumetric split of Wolper et al.
  2019 and Yue et al. 2015), with b_bar_i = J^(-2/d) sigma_i^2:
  psi = mu/2 (sum b_bar_i - d) + kappa/2 ((J^2 - 1)/2 - ln J),
  tau_i = mu (b_bar_i - mean b_bar) + kappa/2 (J^2 - 1).

The Hencky and split laws need sigma_i > 0: the return mappings that use
them leave positive singular values.
"""

import functools

import warp as wp

from ..types import Types


@functools.cache
def make_cofactors(t: Types):
    """``cofactors(sigma) -> (J, c)`` with c_i = J / sigma_i computed as the
    product of the other singular values (finite when one vanishes)."""
    vec = t.vec

    @wp.func
    def cofactors(sigma: t.vec):
        if wp.static(t.dim == 2):
            return sigma[0] * sigma[1], vec(sigma[1], sigma[0])
        else:
            return sigma[0] * sigma[1] * sigma[2], vec(sigma[1] * sigma[2], sigma[0] * sigma[2],
                                                       sigma[0] * sigma[1])

    return cofactors


@functools.cache
def make_fixed_corotated(t: Types):
    S = t.scalar
    cofactors = make_cofactors(t)
    ones = t.vec(*([1.0] * t.dim))

    @wp.func
    def fixed_corotated(sigma: t.vec, mu: S, lam: S):
        J, c = cofactors(sigma)
        d = sigma - ones
        P = S(2.0) * mu * d + (lam * (J - S(1.0))) * c
        psi = mu * wp.dot(d, d) + S(0.5) * lam * (J - S(1.0)) * (J - S(1.0))
        return P, psi

    return fixed_corotated


@functools.cache
def make_hencky(t: Types):
    S = t.scalar
    vec = t.vec
    dim = t.dim

    @wp.func
    def hencky(sigma: t.vec, mu: S, lam: S):
        eps = vec()
        for i in range(wp.static(dim)):
            eps[i] = wp.log(sigma[i])
        tr = S(0.0)
        for i in range(wp.static(dim)):
            tr += eps[i]
        P = vec()
        for i in range(wp.static(dim)):
            P[i] = (S(2.0) * mu * eps[i] + lam * tr) / sigma[i]
        psi = mu * wp.dot(eps, eps) + S(0.5) * lam * tr * tr
        return P, psi

    return hencky


@functools.cache
def make_split(t: Types):
    S = t.scalar
    vec = t.vec
    dim = t.dim
    cofactors = make_cofactors(t)
    MINUS_TWO_OVER_D = -2.0 / t.dim

    @wp.func
    def split(sigma: t.vec, mu: S, kappa: S):
        J, c = cofactors(sigma)
        scale = wp.pow(J, S(MINUS_TWO_OVER_D))
        b = vec()
        mean = S(0.0)
        for i in range(wp.static(dim)):
            b[i] = scale * sigma[i] * sigma[i]
            mean += b[i] / S(dim)
        vol = S(0.5) * kappa * (J * J - S(1.0))
        P = vec()
        for i in range(wp.static(dim)):
            P[i] = (mu * (b[i] - mean) + vol) / sigma[i]
        psi = (S(0.5) * mu * (S(dim) * mean - S(dim))
               + S(0.5) * kappa * (S(0.5) * (J * J - S(1.0)) - wp.log(J)))
        return P, psi

    return split


@functools.cache
def hencky_elasticity(t: Types):
    """``elasticity(sigma, params, history)`` of a plastic model whose moduli
    are (mu, lam) = params[0:2] (mpm.materials.plastic)."""
    hencky = make_hencky(t)

    @wp.func
    def elasticity(sigma: t.vec, params: t.params, history: t.history):
        return hencky(sigma, params[0], params[1])

    return elasticity


@functools.cache
def split_elasticity(t: Types):
    """``elasticity(sigma, params, history)`` with (mu, kappa) = params[0:2]."""
    split = make_split(t)

    @wp.func
    def elasticity(sigma: t.vec, params: t.params, history: t.history):
        return split(sigma, params[0], params[1])

    return elasticity
