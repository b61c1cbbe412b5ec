"""Constitutive models: the stress is the derivative of the stored energy,
vanishes at rest, and is objective. Each Warp function is run through a tiny
test kernel."""

import functools

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.launch import warp_kernel
from mpm.types import make_types
from reference_mpm import energy as reference_energy
from reference_mpm import polar_rotation
from reference_mpm import stress as reference_stress

SOLIDS = [mpm.FixedCorotated(E=1e5, nu=0.3), mpm.NeoHookean(E=1e5, nu=0.3)]
ALL = SOLIDS + [mpm.Fluid(K=1e5, gamma=7.0, viscosity=0.0)]


@functools.cache
def evaluator(t, cls):
    stress_energy = cls.stress_energy(t)

    @warp_kernel
    def evaluate(F: wp.array(dtype=t.mat), L: wp.array(dtype=t.mat), prm: t.params,
                 P: wp.array(dtype=t.mat), psi: wp.array(dtype=t.scalar)):
        i = wp.tid()
        Pi, psii = stress_energy(F[i], L[i], prm)
        P[i] = Pi
        psi[i] = psii

    return evaluate


def evaluate(material, F, L=None, dim=None):
    dim = F.shape[-1]
    t = make_types(dim, "float64")
    L = np.zeros_like(F) if L is None else L
    P = wp.zeros(len(F), dtype=t.mat)
    psi = wp.zeros(len(F), dtype=t.scalar)
    wp.launch(evaluator(t, type(material)), len(F),
              inputs=[wp.array(F, dtype=t.mat), wp.array(L, dtype=t.mat),
                      t.params(*material.packed_padded()), P, psi])
    return P.numpy(), psi.numpy()


def random_F(dim, n, rng, spread=0.3):
    F = np.eye(dim) + spread * rng.standard_normal((n, dim, dim))
    return F[np.linalg.det(F) > 0.3]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", ALL, ids=lambda m: m.name)
def test_stress_is_energy_derivative(material, dim):
    """P_ab = d psi / d F_ab, checked by centred differences (float64,
    h = 1e-6: truncation O(h^2 |psi'''|), round-off O(eps |psi| / h))."""
    rng = np.random.default_rng(1)
    F = random_F(dim, 20, rng)
    P, _ = evaluate(material, F)
    h = 1e-6
    for a in range(dim):
        for b in range(dim):
            Fp, Fm = F.copy(), F.copy()
            Fp[:, a, b] += h
            Fm[:, a, b] -= h
            dpsi = (evaluate(material, Fp)[1] - evaluate(material, Fm)[1]) / (2 * h)
            np.testing.assert_allclose(P[:, a, b], dpsi, rtol=1e-5, atol=1e-4 * material.packed()[0])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", ALL, ids=lambda m: m.name)
def test_rest_state_and_objectivity(material, dim):
    rng = np.random.default_rng(2)
    I = np.eye(dim)[None]
    P0, psi0 = evaluate(material, I)
    np.testing.assert_allclose(P0, 0.0, atol=1e-9)
    np.testing.assert_allclose(psi0, 0.0, atol=1e-9)
    # P(R F) = R P(F), psi(R F) = psi(F) for a proper rotation R
    F = random_F(dim, 10, rng)
    Q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
    R = Q.copy()
    if np.linalg.det(R) < 0:
        R[:, 0] *= -1
    P, psi = evaluate(material, F)
    PR, psiR = evaluate(material, R @ F)
    np.testing.assert_allclose(PR, R @ P, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(psiR, psi, rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", ALL + [mpm.Fluid(K=1e4, viscosity=2.0)], ids=lambda m: m.name)
def test_stress_and_energy_match_reference_formulas(material, dim):
    """Against the NumPy formulas of the reference solver (viscous term included)."""
    rng = np.random.default_rng(3)
    F = random_F(dim, 10, rng)
    L = rng.standard_normal((len(F), dim, dim))
    P, psi = evaluate(material, F, L)
    ref = np.array([reference_stress(material.name, f, l, material.packed()) for f, l in zip(F, L)])
    np.testing.assert_allclose(P, ref, rtol=1e-10, atol=1e-8)
    ref = np.array([reference_energy(material.name, f, material.packed()) for f in F])
    np.testing.assert_allclose(psi, ref, rtol=1e-10, atol=1e-8)


def test_fluid_projection_keeps_volume_change():
    t = make_types(3, "float64")
    project = mpm.Fluid.project(t)

    @warp_kernel
    def run(F: wp.array(dtype=t.mat), out: wp.array(dtype=t.mat)):
        i = wp.tid()
        out[i] = project(F[i], t.params())

    F = random_F(3, 10, np.random.default_rng(4))
    out = wp.zeros(len(F), dtype=t.mat)
    wp.launch(run, len(F), inputs=[wp.array(F, dtype=t.mat), out])
    J = np.linalg.det(F)
    np.testing.assert_allclose(out.numpy(), J[:, None, None] ** (1 / 3) * np.eye(3), rtol=1e-12)


def test_lame_parameters():
    mu, lam = mpm.materials.lame(1e5, 0.25)
    assert mu == pytest.approx(4e4) and lam == pytest.approx(4e4)


@pytest.mark.parametrize("dim", [2, 3])
def test_svd_with_proper_rotations_also_for_repeated_singular_values(dim):
    """F = U diag(sigma) V^T with det U = det V = 1, sigma descending and the
    sign of an inversion on the last one, for rotations, reflections and
    repeated singular values (where wp.svd2 alone is wrong)."""
    from mpm.materials.decompositions import make_svd

    t = make_types(dim, "float64")
    svd = make_svd(t)

    @warp_kernel
    def run(F: wp.array(dtype=t.mat), U: wp.array(dtype=t.mat), s: wp.array(dtype=t.vec),
            V: wp.array(dtype=t.mat)):
        i = wp.tid()
        u, sg, v = svd(F[i])
        U[i] = u
        s[i] = sg
        V[i] = v

    rng = np.random.default_rng(5)
    Fs = [np.eye(dim), -np.eye(dim), np.eye(dim)[::-1], np.diag([1.0] * (dim - 1) + [-0.5])]
    for _ in range(20):
        Q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
        Fs += [Q, 1.3 * Q, Q @ np.diag([1.0] * (dim - 1) + [0.7]), rng.standard_normal((dim, dim))]
    F = np.array(Fs)
    U, s, V = (wp.zeros(len(F), dtype=T) for T in (t.mat, t.vec, t.mat))
    wp.launch(run, len(F), inputs=[wp.array(F, dtype=t.mat), U, s, V])
    U, s, V = U.numpy(), s.numpy(), V.numpy()
    np.testing.assert_allclose(np.einsum("nij,nj,nkj->nik", U, s, V), F, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(U), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(V), 1.0, atol=1e-12)
    assert np.all(np.diff(s, axis=1) <= 1e-12)
    np.testing.assert_allclose(np.prod(s, axis=1), np.linalg.det(F), atol=1e-12)
    assert np.all(s[:, :-1] >= 0)


def polar_extended(F):
    """The polar rotation of F (det F > 0) by Newton's iteration
    X <- (X + X^-T) / 2 in extended precision (long double: eps 1.1e-19 on
    x86), each inverse refined there: below float64's round-off. LAPACK's
    SVD, whose U V^T the reference takes otherwise, missed by 16 ulps on a
    near-identity F on some CPUs."""
    X = F.astype(np.longdouble)
    eye = np.eye(len(F), dtype=np.longdouble)
    for _ in range(100):
        Y = np.linalg.inv(X.astype(np.float64)).astype(np.longdouble)
        for _ in range(2):
            Y = Y + Y @ (eye - X @ Y)
        X, X_old = 0.5 * (X + Y.T), X
        if np.abs(X - X_old).max() <= 4 * np.finfo(np.longdouble).eps:
            break
    return X.astype(np.float64)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_polar_rotation_to_round_off(dim, precision):
    """rotation(F) is the proper rotation maximising tr(R^T F), i.e. U V^T of
    the SVD with the last column of U flipped when det F < 0 (reference:
    NumPy's float64 SVD). Where det F > 0 (3D: the scaled Newton iteration)
    it holds to a few ulps for stretches up to 100 %, repeated singular values
    and a condition number of 1e3; an inverted 3D F goes through wp.svd3,
    exact in float64 only."""
    from mpm.materials.decompositions import make_rotation

    t = make_types(dim, precision)
    rotation = make_rotation(t)

    @warp_kernel
    def run(F: wp.array(dtype=t.mat), R: wp.array(dtype=t.mat)):
        i = wp.tid()
        R[i] = rotation(F[i])

    rng = np.random.default_rng(6)
    n = 400
    Q, _ = np.linalg.qr(rng.standard_normal((n, dim, dim)))
    Q[:, :, 0] *= np.sign(np.linalg.det(Q))[:, None]
    A = rng.standard_normal((n, dim, dim)) * np.repeat([0.0, 0.02, 0.3, 1.0], n // 4)[:, None, None]
    F = Q @ (np.eye(dim) + 0.5 * (A + A.transpose(0, 2, 1)))
    F[:4] = [np.eye(dim), 2.0 * Q[0], np.diag([1e-3] + [1.0] * (dim - 2) + [1e3]) @ Q[1],
             np.diag([1.0, 0.7, -0.5][-dim:])]  # distinct sigma: a unique closest rotation
    R = wp.zeros(n, dtype=t.mat)
    wp.launch(run, n, inputs=[wp.array(F, dtype=t.mat), R])
    R = R.numpy().astype(np.float64)
    expected = np.array([polar_rotation(f) for f in F])
    proper = np.linalg.det(F) > 0
    expected[proper] = [polar_extended(f) for f in F[proper]]
    eps = np.finfo(np.float32 if precision == "float32" else np.float64).eps
    error = np.abs(R - expected).max(axis=(1, 2))
    inverted = np.linalg.det(F) < 0
    assert inverted[3] and not inverted[:3].any() and not inverted[4:n // 2].any()
    # a few ulps of the computed rotation plus the reference's own error, which
    # grows with the condition number (the polar factor's sensitivity)
    sigma = np.linalg.svd(F, compute_uv=False)
    tolerance = 8 * eps + 8 * sigma[:, 0] / sigma[:, -1] * np.finfo(np.float64).eps
    assert np.all(error[~inverted] < tolerance[~inverted]), (error / tolerance)[~inverted].max()
    np.testing.assert_allclose(np.linalg.det(R[~inverted]), 1.0, atol=8 * eps)
    if precision == "float64" or dim == 2:
        assert np.all(error[inverted] < 1e3 * tolerance[inverted]), (error / tolerance)[inverted].max()
