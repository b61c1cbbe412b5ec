"""The stress differential dP = dP/dF : dF of the isotropic elastic energies,
from principal stretches (for the implicit integrator, mpm.implicit).

With F = U diag(sigma) V^T (mpm.materials.decompositions), the principal
stress P_hat_i = d psi / d sigma_i and Hessian H_ij = d^2 psi / d sigma_i
d sigma_j of a material (``principal``, or ``elasticity`` with
``elasticity_hessian`` for a plastic model's elastic predictor), and
M = U^T dF V (Teran et al. 2005; Stomakhin et al. 2012, the "B blocks"):

    dP_hat_ii = sum_k H_ik M_kk
    for each pair i < j, with s = (M_ij + M_ji) / 2 and a = (M_ij - M_ji) / 2:
        dP_hat_ij = lam_s s + lam_a a,    dP_hat_ji = lam_s s - lam_a a,
        lam_s = (P_hat_i - P_hat_j) / (sigma_i - sigma_j)   (H_ii - H_ij as sigma_j -> sigma_i),
        lam_a = (P_hat_i + P_hat_j) / (sigma_i + sigma_j)
    dP = U dP_hat V^T.

The tangent dP/dF is symmetric with eigenvalues those of H and every pair's
(lam_s, lam_a). ``psd=True`` clamps each of them at zero: the per-particle
definiteness fix of the implicit integrator (Teran et al. 2005), which
leaves the tangent of a material in its convex region unchanged.
Pairs are (0, 1) in 2D; (0, 1), (0, 2), (1, 2) in 3D (slot k of ``lam_s``).
"""

import functools

import warp as wp

from ..types import Types
from .decompositions import make_svd

# |sigma_i -+ sigma_j| below this (relative to the larger stretch) takes the limit form
COINCIDENT = 1.0e-6


@functools.cache
def make_tangent_type(t: Types):
    """Per-particle tangent dP/dF, stored between the differential's uses."""

    @wp.struct
    class Tangent:
        U: t.mat
        V: t.mat
        H: t.mat  # principal Hessian (projected when psd)
        lam_s: t.vec  # per pair (i, j): (P_hat_i - P_hat_j) / (sigma_i - sigma_j)
        lam_a: t.vec  # per pair: (P_hat_i + P_hat_j) / (sigma_i + sigma_j)

    return Tangent


def principal_law(t: Types, cls):
    """``law(sigma, params, history) -> (P_hat, psi, H)`` of the material
    class ``cls`` (for a plastic model, the elastic predictor's)."""
    if getattr(cls, "plastic", False):
        return _plastic_law(t, cls)
    return cls.principal(t)


@functools.cache
def _plastic_law(t: Types, cls):
    elasticity = cls.elasticity(t)
    hessian = cls.elasticity_hessian(t)

    @wp.func
    def law(sigma: t.vec, params: t.params, history: t.history):
        P, psi = elasticity(sigma, params, history)
        return P, psi, hessian(sigma, params, history)

    return law


@functools.cache
def make_psd(t: Types):
    """``psd(H) -> H``: the symmetric matrix with negative eigenvalues set to 0."""
    S = t.scalar
    mat, vec = t.mat, t.vec

    @wp.func
    def psd(H: t.mat):
        A = S(0.5) * (H + wp.transpose(H))
        if wp.static(t.dim == 2):
            a = A[0, 0]
            b = A[0, 1]
            c = A[1, 1]
            mean = S(0.5) * (a + c)
            r = wp.sqrt(S(0.25) * (a - c) * (a - c) + b * b)
            if mean - r >= S(0.0):
                return A
            phi = S(0.5) * wp.atan2(S(2.0) * b, a - c)
            e = vec(wp.cos(phi), wp.sin(phi))  # eigenvector of mean + r
            return wp.max(mean + r, S(0.0)) * wp.outer(e, e)  # pyright: ignore[reportOperatorIssue]
        else:
            Q = mat()
            d = vec()
            wp.eig3(A, Q, d)
            if d[0] >= S(0.0) and d[1] >= S(0.0) and d[2] >= S(0.0):
                return A
            for k in range(3):
                d[k] = wp.max(d[k], S(0.0))
            return Q * wp.diag(d) * wp.transpose(Q)

    return psd


@functools.cache
def make_tangent(t: Types, psd: bool):
    """``tangent(U, sigma, V, P_hat, H) -> Tangent`` (see the module docstring)."""
    S = t.scalar
    vec = t.vec
    Tangent = make_tangent_type(t)
    project = make_psd(t)
    n_pairs = 1 if t.dim == 2 else 3

    @wp.func
    def ratio(num: S, den: S, limit: S, scale: S):
        if wp.abs(den) > S(COINCIDENT) * scale:
            return num / den
        return limit

    @wp.func
    def tangent(U: t.mat, sigma: t.vec, V: t.mat, P: t.vec, H: t.mat):
        T = Tangent()
        T.U = U
        T.V = V
        scale = wp.max(wp.max(wp.abs(sigma[0]), wp.abs(sigma[1])), S(1.0e-30))
        if wp.static(t.dim == 3):
            scale = wp.max(scale, wp.abs(sigma[2]))
        ls = vec()
        la = vec()
        for k in range(wp.static(n_pairs)):
            i = k // 2  # pairs (0, 1), (0, 2), (1, 2)
            j = (k + 3) // 2
            ls[k] = ratio(P[i] - P[j], sigma[i] - sigma[j], H[i, i] - H[i, j], scale)
            la[k] = ratio(P[i] + P[j], sigma[i] + sigma[j], H[i, i] + H[i, j], scale)
            if wp.static(psd):
                ls[k] = wp.max(ls[k], S(0.0))
                la[k] = wp.max(la[k], S(0.0))
        T.lam_s = ls
        T.lam_a = la
        if wp.static(psd):
            T.H = project(H)
        else:
            T.H = H
        return T

    return tangent


@functools.cache
def make_tangent_action(t: Types):
    """``tangent_action(T, dF) -> dP``."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    n_pairs = 1 if t.dim == 2 else 3

    @wp.func
    def tangent_action(T: make_tangent_type(t), dF: t.mat):
        M = wp.transpose(T.U) * dF * T.V
        diag = vec()
        for i in range(wp.static(t.dim)):
            diag[i] = M[i, i]
        hd = T.H * diag
        dP = mat()
        for i in range(wp.static(t.dim)):
            dP[i, i] = hd[i]
        for k in range(wp.static(n_pairs)):
            i = k // 2  # pairs (0, 1), (0, 2), (1, 2)
            j = (k + 3) // 2
            s = S(0.5) * (M[i, j] + M[j, i])
            a = S(0.5) * (M[i, j] - M[j, i])
            dP[i, j] = T.lam_s[k] * s + T.lam_a[k] * a
            dP[j, i] = T.lam_s[k] * s - T.lam_a[k] * a
        return T.U * dP * wp.transpose(T.V)

    return tangent_action


@functools.cache
def make_principal_stress(t: Types, cls, psd: bool):
    """``principal_stress(F, params, history) -> (P, psi, Tangent)``: the
    stress [Pa], energy [J/m^3] and tangent of material class ``cls`` at F,
    with one SVD."""
    svd = make_svd(t)
    law = principal_law(t, cls)
    tangent = make_tangent(t, psd)

    @wp.func
    def principal_stress(F: t.mat, params: t.params, history: t.history):
        U, sigma, V = svd(F)
        P_hat, psi, H = law(sigma, params, history)
        return U * wp.diag(P_hat) * wp.transpose(V), psi, tangent(U, sigma, V, P_hat, H)

    return principal_stress


@functools.cache
def make_tangent_quadratic(t: Types):
    """``tangent_quadratic(T, u, z) -> (a b^T) : dP(a b^T)`` for u = U^T a and
    z = V^T b (the rank-one direction in the principal frames): with
    c = u * z (per component), s and w the pairs' (u_i z_j +- u_j z_i) / 2,
    it is c^T H c + 2 sum_pairs (lam_s s^2 + lam_a w^2) - the diagonal of
    the implicit system without a full :func:`make_tangent_action`."""
    S = t.scalar
    n_pairs = 1 if t.dim == 2 else 3

    @wp.func
    def tangent_quadratic(T: make_tangent_type(t), u: t.vec, z: t.vec):
        c = wp.cw_mul(u, z)
        q = wp.dot(c, T.H * c)
        for k in range(wp.static(n_pairs)):
            i = k // 2  # pairs (0, 1), (0, 2), (1, 2)
            j = (k + 3) // 2
            s = S(0.5) * (u[i] * z[j] + u[j] * z[i])
            w = S(0.5) * (u[i] * z[j] - u[j] * z[i])
            q += S(2.0) * (T.lam_s[k] * s * s + T.lam_a[k] * w * w)
        return q

    return tangent_quadratic
