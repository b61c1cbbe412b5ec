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
    """``fixed_corotated(sigma, mu, lam) -> (P_hat, psi)`` (the module's docstring)."""
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
    """``hencky(sigma, mu, lam) -> (P_hat, psi)`` (the module's docstring)."""
    S, vec, dim = t.scalar, t.vec, t.dim

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
    """``split(sigma, mu, kappa) -> (P_hat, psi)`` (the module's docstring)."""
    S, vec, dim = t.scalar, t.vec, t.dim
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


# ------------------------------------------------------------------ Hessians
# ``*_hessian(sigma, a, b) -> H``: H_ij = d P_hat_i / d sigma_j = d^2 psi /
# d sigma_i d sigma_j of the law of the same name (the principal part of the
# stress differential, mpm.materials.differential).


@functools.cache
def make_cofactor_derivative(t: Types):
    """``cofactor_derivative(sigma) -> D`` with D_ij = d c_i / d sigma_j for
    c_i = J / sigma_i: zero on the diagonal, the product of the remaining
    singular values off it (1 in 2D)."""
    S = t.scalar
    mat = t.mat

    @wp.func
    def cofactor_derivative(sigma: t.vec):
        if wp.static(t.dim == 2):
            return mat(S(0.0), S(1.0), S(1.0), S(0.0))
        else:
            return mat(S(0.0), sigma[2], sigma[1],
                       sigma[2], S(0.0), sigma[0],
                       sigma[1], sigma[0], S(0.0))

    return cofactor_derivative


@functools.cache
def make_fixed_corotated_hessian(t: Types):
    """H_ij = 2 mu delta_ij + lam c_i c_j + lam (J - 1) dc_i/dsigma_j."""
    S = t.scalar
    cofactors = make_cofactors(t)
    dc = make_cofactor_derivative(t)
    dim = t.dim

    @wp.func
    def fixed_corotated_hessian(sigma: t.vec, mu: S, lam: S):
        J, c = cofactors(sigma)
        return (S(2.0) * mu * wp.identity(n=dim, dtype=S) + lam * wp.outer(c, c)
                + (lam * (J - S(1.0))) * dc(sigma))

    return fixed_corotated_hessian


@functools.cache
def make_hencky_hessian(t: Types):
    """H_ij = (2 mu delta_ij + lam) / (sigma_i sigma_j) - delta_ij tau_i / sigma_i^2,
    tau_i = 2 mu eps_i + lam tr eps."""
    S = t.scalar
    mat = t.mat
    dim = t.dim

    @wp.func
    def hencky_hessian(sigma: t.vec, mu: S, lam: S):
        tr = S(0.0)
        for i in range(wp.static(dim)):
            tr += wp.log(sigma[i])
        H = mat()
        for i in range(wp.static(dim)):
            for j in range(wp.static(dim)):
                H[i, j] = lam / (sigma[i] * sigma[j])
            tau = S(2.0) * mu * wp.log(sigma[i]) + lam * tr
            H[i, i] = H[i, i] + (S(2.0) * mu - tau) / (sigma[i] * sigma[i])
        return H

    return hencky_hessian


@functools.cache
def make_split_hessian(t: Types):
    """Of P_hat_i = mu q (sigma_i - s2 / (d sigma_i)) + kappa/2 (J^2 - 1) / sigma_i
    with q = J^(-2/d), s2 = sum sigma_k^2 (dq/dsigma_j = -2 q / (d sigma_j))."""
    S = t.scalar
    mat = t.mat
    dim = t.dim
    cofactors = make_cofactors(t)
    d = float(dim)
    MINUS_TWO_OVER_D = -2.0 / dim

    @wp.func
    def split_hessian(sigma: t.vec, mu: S, kappa: S):
        J, c = cofactors(sigma)
        q = wp.pow(J, S(MINUS_TWO_OVER_D))
        s2 = wp.dot(sigma, sigma)
        H = mat()
        for i in range(wp.static(dim)):
            dev_i = sigma[i] - s2 / (S(d) * sigma[i])
            for j in range(wp.static(dim)):
                h = mu * (S(-2.0) * q / (S(d) * sigma[j]) * dev_i
                          - q * S(2.0) * sigma[j] / (S(d) * sigma[i]))
                h += kappa * J * J / (sigma[i] * sigma[j])
                if i == j:
                    h += mu * q * (S(1.0) + s2 / (S(d) * sigma[i] * sigma[i]))
                    h -= S(0.5) * kappa * (J * J - S(1.0)) / (sigma[i] * sigma[i])
                H[i, j] = h
        return H

    return split_hessian


@functools.cache
def make_fixed_corotated_law(t: Types):
    """``fixed_corotated(sigma, mu, lam) -> (P_hat, psi, H)``: :func:`make_fixed_corotated`
    with its Hessian."""
    S = t.scalar
    law = make_fixed_corotated(t)
    hessian = make_fixed_corotated_hessian(t)

    @wp.func
    def fixed_corotated(sigma: t.vec, mu: S, lam: S):
        P, psi = law(sigma, mu, lam)
        return P, psi, hessian(sigma, mu, lam)

    return fixed_corotated


@functools.cache
def make_neo_hookean_law(t: Types):
    """``neo_hookean(sigma, mu, lam) -> (P_hat, psi, H)`` of
    psi = mu/2 (sum sigma_i^2 - d) - mu ln J + lam/2 (ln J)^2:
    P_hat_i = mu (sigma_i - 1/sigma_i) + lam ln J / sigma_i,
    H_ij = lam / (sigma_i sigma_j) + delta_ij (mu + (mu - lam ln J) / sigma_i^2)."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    dim = t.dim
    cofactors = make_cofactors(t)

    @wp.func
    def neo_hookean(sigma: t.vec, mu: S, lam: S):
        J, c = cofactors(sigma)
        lnJ = wp.log(J)
        P = vec()
        H = mat()
        for i in range(wp.static(dim)):
            P[i] = mu * (sigma[i] - S(1.0) / sigma[i]) + lam * lnJ / sigma[i]
            for j in range(wp.static(dim)):
                H[i, j] = lam / (sigma[i] * sigma[j])
            H[i, i] = H[i, i] + mu + (mu - lam * lnJ) / (sigma[i] * sigma[i])
        psi = S(0.5) * mu * (wp.dot(sigma, sigma) - S(dim)) - mu * lnJ + S(0.5) * lam * lnJ * lnJ
        return P, psi, H

    return neo_hookean


@functools.cache
def make_tait_law(t: Types):
    """``tait(sigma, K, gamma) -> (P_hat, psi, H)`` of the fluid energy
    psi(J) = K (J^(1-gamma) / (gamma - 1) + J - gamma / (gamma - 1)):
    P_hat_i = psi'(J) c_i, H_ij = psi''(J) c_i c_j + psi'(J) dc_i/dsigma_j,
    psi' = K (1 - J^-gamma) = -p, psi'' = K gamma J^(-gamma-1)."""
    S = t.scalar
    cofactors = make_cofactors(t)
    dc = make_cofactor_derivative(t)

    @wp.func
    def tait(sigma: t.vec, K: S, gamma: S):
        J, c = cofactors(sigma)
        d1 = K * (S(1.0) - wp.pow(J, -gamma))
        d2 = K * gamma * wp.pow(J, -gamma - S(1.0))
        psi = K * (wp.pow(J, S(1.0) - gamma) / (gamma - S(1.0)) + J - gamma / (gamma - S(1.0)))
        return d1 * c, psi, d2 * wp.outer(c, c) + d1 * dc(sigma)

    return tait


# ------------------------------------------------------------------ on params
# A material reads its moduli from the per-body vector ``params``: its
# ``principal(sigma, params, history)``, or a plastic model's ``elasticity``
# and ``elasticity_hessian``, is one of the laws above at two of them.


@functools.cache
def first_two(t: Types):
    """``moduli(params, history) -> (params[0], params[1])``."""

    @wp.func
    def moduli(params: t.params, history: t.history):
        return params[0], params[1]

    return moduli


def on_params(law, moduli=first_two):
    """The factory ``types -> f(sigma, params, history)`` that evaluates the
    principal-space ``law(types)(sigma, a, b)`` at the moduli
    (a, b) = ``moduli(types)(params, history)`` (by default params[0:2])."""

    @functools.cache
    def factory(t: Types):
        f = law(t)
        get = moduli(t)

        @wp.func
        def at_params(sigma: t.vec, params: t.params, history: t.history):
            a, b = get(params, history)
            return f(sigma, a, b)

        return at_params

    return factory

