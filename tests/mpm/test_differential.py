"""The stress differential of every material (mpm.materials.differential):
dP = dP/dF : dF against centred differences of the material's own stress,
and the definiteness fix."""

import functools

import numpy as np
import pytest
import warp as wp

from mpm.launch import warp_kernel
from mpm.materials import MATERIALS
from mpm.materials.differential import (make_principal_stress, make_tangent_action,
                                        make_tangent_quadratic, make_tangent_type)
from mpm.types import make_types


@functools.cache
def evaluator(t, cls, psd):
    principal = make_principal_stress(t, cls, psd)
    action = make_tangent_action(t)
    stress_energy = None if cls.plastic else cls.stress_energy(t)

    @warp_kernel
    def evaluate(F: wp.array(dtype=t.mat), dF: wp.array(dtype=t.mat), prm: t.params,
                 history: t.history, P: wp.array(dtype=t.mat), P_matrix: wp.array(dtype=t.mat),
                 dP: wp.array(dtype=t.mat), T: wp.array(dtype=make_tangent_type(t))):
        i = wp.tid()
        Pi, psi, Ti = principal(F[i], prm, history)
        P[i] = Pi
        if wp.static(stress_energy is not None):
            Pm, psim = stress_energy(F[i], t.mat(), prm)
            P_matrix[i] = Pm
        dP[i] = action(Ti, dF[i])
        T[i] = Ti

    return evaluate


def run(material, F, dF, psd=False):
    """(P from the principal law, P from stress_energy (non-plastic), dP)."""
    dim = F.shape[-1]
    t = make_types(dim, "float64")
    n = len(F)
    P, Pm, dP = (wp.zeros(n, dtype=t.mat) for _ in range(3))
    T = wp.zeros(n, dtype=make_tangent_type(t))
    history = t.history(*material.initial_history()) if material.plastic else t.history()
    wp.launch(evaluator(t, type(material), psd), n,
              inputs=[wp.array(F, dtype=t.mat), wp.array(dF, dtype=t.mat),
                      t.params(*material.packed_padded()), history, P, Pm, dP, T])
    return P.numpy(), Pm.numpy(), dP.numpy()


def random_F(dim, n, rng, spread=0.25):
    F = np.eye(dim) + spread * rng.standard_normal((n, dim, dim))
    return F[np.linalg.det(F) > 0.4]


EPS = np.finfo(np.float64).eps
MODELS = sorted(MATERIALS)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", MODELS)
def test_differential_matches_central_differences(model, dim):
    """dP(F; dF) = (P(F + h dF) - P(F - h dF)) / 2h + O(h^2) (float64,
    h = 1e-6), with P the stress of the principal law, which for the elastic
    and fluid models must equal the model's own matrix-form stress to
    round-off, 64 eps of the modulus (the plastic models' P is their elastic
    predictor's, U diag(P_hat) V^T). The difference's error: its truncation,
    estimated from the same difference at 2h (Richardson: the O(h^2) error
    e(2h) = 4 e(h), so e(h) = (fd(2h) - fd(h)) / 3; the stiff fluid's J^-gamma
    makes it the larger part there, 5e-8 of the modulus), allowed twice, plus
    its round-off eps |P| / h, allowed 16 times (2e-10 of the modulus each:
    the solids measure 1.3e-9)."""
    material = MATERIALS[model]()
    rng = np.random.default_rng(3)
    F = random_F(dim, 24, rng)
    dF = rng.standard_normal(F.shape)
    P, Pm, dP = run(material, F, dF)
    scale = np.abs(P).max() + material.wave_speed() ** 2 * material.rho  # ~ modulus [Pa]
    if not material.plastic:
        np.testing.assert_allclose(P, Pm, rtol=0, atol=64 * EPS * scale)
    h = 1e-6

    def fd(h):
        return (run(material, F + h * dF, dF)[0] - run(material, F - h * dF, dF)[0]) / (2 * h)

    fd_h, fd_2h = fd(h), fd(2 * h)
    truncation = np.abs(fd_2h - fd_h).max() / 3
    err = np.abs(dP - fd_h).max()
    assert err <= 2 * truncation + 16 * EPS * scale / h, \
        f"{model} {dim}D: |dP - fd| = {err / scale:.2e} of the modulus, truncation {truncation / scale:.2e}"
    assert np.abs(dP).max() > 1e-3 * scale  # not trivially zero


def tangent_matrix(material, F, psd):
    """The d^2 x d^2 matrix of dF -> dP at each F (columns: dF = unit basis)."""
    dim = F.shape[-1]
    n = len(F)
    cols = []
    for k in range(dim * dim):
        e = np.zeros((n, dim, dim))
        e[:, k // dim, k % dim] = 1.0
        cols.append(run(material, F, e, psd)[2].reshape(n, -1))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("model", ["fixed_corotated", "neo_hookean", "fluid", "snow"])
def test_projected_tangent_is_symmetric_semidefinite(model, dim):
    """The tangent is symmetric (it is a Hessian) and, with psd=True, has no
    negative eigenvalue, even under strong compression, where the raw
    tangent of these models is indefinite; the fix changes nothing where the
    raw tangent is already semi-definite."""
    material = MATERIALS[model]()
    rng = np.random.default_rng(5)
    F = random_F(dim, 12, rng, spread=0.6)
    raw = tangent_matrix(material, F, psd=False)
    fixed = tangent_matrix(material, F, psd=True)
    scale = np.abs(raw).max()
    for A in (raw, fixed):
        np.testing.assert_allclose(A, np.swapaxes(A, 1, 2), rtol=0, atol=16 * EPS * scale)  # measured 2.5 eps
    raw_min = np.linalg.eigvalsh(raw).min(axis=1)
    fixed_min = np.linalg.eigvalsh(fixed).min(axis=1)
    assert (raw_min < -1e-6 * scale).any(), "no indefinite case drawn: the test would prove nothing"
    assert (fixed_min > -1e-9 * scale).all()
    convex = raw_min > 1e-9 * scale
    np.testing.assert_allclose(fixed[convex], raw[convex], rtol=0, atol=16 * EPS * scale)  # measured: equal


@functools.cache
def quadratic_evaluator(t):
    action = make_tangent_action(t)
    quadratic = make_tangent_quadratic(t)

    @warp_kernel
    def evaluate(T: wp.array(dtype=make_tangent_type(t)), a: wp.array(dtype=t.vec), b: wp.array(dtype=t.vec),
                 full: wp.array(dtype=t.scalar), fast: wp.array(dtype=t.scalar)):
        i = wp.tid()
        Ti = T[i]
        M = wp.outer(a[i], b[i])
        full[i] = wp.ddot(M, action(Ti, M))
        fast[i] = quadratic(Ti, wp.transpose(Ti.U) * a[i], wp.transpose(Ti.V) * b[i])

    return evaluate


@pytest.mark.parametrize("dim", [2, 3])
def test_tangent_quadratic_form_of_a_rank_one_direction(dim):
    """(a b^T) : dP(a b^T) from the principal frames (the implicit system's
    diagonal) equals the full differential's contraction."""
    material = MATERIALS["snow"]()
    rng = np.random.default_rng(7)
    F = random_F(dim, 16, rng, spread=0.5)
    t = make_types(dim, "float64")
    n = len(F)
    T = wp.zeros(n, dtype=make_tangent_type(t))
    scratch = [wp.zeros(n, dtype=t.mat) for _ in range(3)]
    wp.launch(evaluator(t, type(material), True), n,
              inputs=[wp.array(F, dtype=t.mat), wp.array(F, dtype=t.mat), t.params(*material.packed_padded()),
                      t.history(*material.initial_history()), *scratch, T])
    full, fast = wp.zeros(n, dtype=t.scalar), wp.zeros(n, dtype=t.scalar)
    wp.launch(quadratic_evaluator(t), n, inputs=[T, wp.array(rng.standard_normal((n, dim)), dtype=t.vec),
                                                 wp.array(rng.standard_normal((n, dim)), dtype=t.vec), full, fast])
    # two orders of the same sums: 16 eps of the largest (measured 2.6 eps)
    np.testing.assert_allclose(fast.numpy(), full.numpy(), rtol=0, atol=16 * EPS * np.abs(full.numpy()).max())
