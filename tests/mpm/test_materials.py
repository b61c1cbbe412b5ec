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

EPS = np.finfo(np.float64).eps
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


def assert_within(actual, desired, atol, what):
    """|actual - desired| <= atol elementwise (atol an array broadcast to them)."""
    err = np.abs(np.asarray(actual) - np.asarray(desired))
    ratio = err / np.broadcast_to(atol, err.shape)
    assert np.all(ratio <= 1), f"{what}: error up to {ratio.max():.3g} times the tolerance"


def random_F(dim, n, rng, spread=0.3):
    F = np.eye(dim) + spread * rng.standard_normal((n, dim, dim))
    return F[np.linalg.det(F) > 0.3]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", ALL, ids=lambda m: m.name)
def test_stress_is_energy_derivative(material, dim):
    """P_ab = d psi / d F_ab, checked by centred differences (float64,
    h = 1e-6): the round-off of psi is eps times its terms, whose size is
    about |P| |F| + E (E: the first modulus), so the difference's is
    eps (|P| |F| + E) / h (16 times that allowed; the truncation
    O(h^2 |psi'''|) is below it)."""
    rng = np.random.default_rng(1)
    F = random_F(dim, 20, rng)
    P, _ = evaluate(material, F)
    h = 1e-6
    scale = np.abs(P).max(axis=(1, 2)) * np.abs(F).max(axis=(1, 2)) + material.packed()[0]
    for a in range(dim):
        for b in range(dim):
            Fp, Fm = F.copy(), F.copy()
            Fp[:, a, b] += h
            Fm[:, a, b] -= h
            dpsi = (evaluate(material, Fp)[1] - evaluate(material, Fm)[1]) / (2 * h)
            assert_within(P[:, a, b], dpsi, 16 * EPS * scale / h, f"P[{a}, {b}]")


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", ALL, ids=lambda m: m.name)
def test_rest_state_and_objectivity(material, dim):
    """No stress and no energy at rest (to round-off of the modulus, eps E);
    P(R F) = R P(F) and psi(R F) = psi(F) to round-off of the stress and
    energy terms (32 eps max|P|, 32 eps (|psi| + E))."""
    rng = np.random.default_rng(2)
    I = np.eye(dim)[None]
    P0, psi0 = evaluate(material, I)
    E = material.packed()[0]
    np.testing.assert_allclose(P0, 0.0, rtol=0, atol=4 * EPS * E)
    np.testing.assert_allclose(psi0, 0.0, rtol=0, atol=4 * EPS * E)
    # P(R F) = R P(F), psi(R F) = psi(F) for a proper rotation R
    F = random_F(dim, 10, rng)
    Q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
    R = Q.copy()
    if np.linalg.det(R) < 0:
        R[:, 0] *= -1
    P, psi = evaluate(material, F)
    PR, psiR = evaluate(material, R @ F)
    np.testing.assert_allclose(PR, R @ P, rtol=0, atol=32 * EPS * np.abs(P).max())
    np.testing.assert_allclose(psiR, psi, rtol=0, atol=32 * EPS * (np.abs(psi).max() + E))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", ALL + [mpm.Fluid(K=1e4, viscosity=2.0)], ids=lambda m: m.name)
def test_stress_and_energy_match_reference_formulas(material, dim):
    """Against the NumPy formulas of the reference solver (viscous term
    included), to round-off of the stress and energy terms (32 eps max|P|,
    32 eps (|psi| + E))."""
    rng = np.random.default_rng(3)
    F = random_F(dim, 10, rng)
    L = rng.standard_normal((len(F), dim, dim))
    P, psi = evaluate(material, F, L)
    ref = np.array([reference_stress(material.name, f, l, material.packed()) for f, l in zip(F, L)])
    np.testing.assert_allclose(P, ref, rtol=0, atol=32 * EPS * np.abs(ref).max())
    ref = np.array([reference_energy(material.name, f, material.packed()) for f in F])
    np.testing.assert_allclose(psi, ref, rtol=0, atol=32 * EPS * (np.abs(ref).max() + material.packed()[0]))


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
    np.testing.assert_allclose(out.numpy(), J[:, None, None] ** (1 / 3) * np.eye(3), rtol=4 * EPS)


def test_lame_parameters():
    mu, lam = mpm.materials.lame(1e5, 0.25)
    assert mu == pytest.approx(4e4, rel=EPS, abs=0) and lam == pytest.approx(4e4, rel=EPS, abs=0)


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
    # round-off of a few rotations' products and the SVD's iterations: 64 eps of |F| (measured up to 18 eps)
    scale = np.abs(F).max(axis=(1, 2))
    assert_within(np.einsum("nij,nj,nkj->nik", U, s, V), F, 64 * EPS * scale[:, None, None], "U S V^T")
    np.testing.assert_allclose(np.linalg.det(U), 1.0, rtol=0, atol=64 * EPS)
    np.testing.assert_allclose(np.linalg.det(V), 1.0, rtol=0, atol=64 * EPS)
    assert np.all(np.diff(s, axis=1) <= 64 * EPS * scale[:, None])
    assert_within(np.prod(s, axis=1), np.linalg.det(F), 64 * EPS * scale**dim, "det")
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


FLUIDS = [mpm.Fluid(K=1e5, gamma=7.0), mpm.materials.Viscous(K=3e4, gamma=3.0, viscosity=40.0, rho=1300.0)]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", FLUIDS, ids=lambda m: m.name)
def test_fluid_wave_speed_is_the_slope_of_its_own_pressure(material, dim):
    """c(J)^2 = dp/drho with rho = rho0 / J, where p(J) = -tr(sigma) / d is the
    pressure of the Cauchy stress sigma = P F^T / J that the material's own
    stress gives at F = J^(1/d) I (at rest, L = 0), by a centred difference
    in rho with relative step h = 1e-4 (float64). p(rho) = K ((rho / rho0)^gamma
    - 1) makes the difference's relative truncation h^2 (gamma - 1)(gamma - 2)
    / 6 (5e-8 for gamma = 7) and its round-off about eps / (gamma h) (3e-13)."""
    h = 1e-4
    eps = np.finfo(np.float64).eps
    rho0 = material.rho
    Js = np.array([0.5, 0.8, 0.95, 1.0, 1.05, 1.4])

    def pressure(rho):
        J = rho0 / rho
        F = J[:, None, None] ** (1.0 / dim) * np.eye(dim)
        P, _ = evaluate(material, F)
        sigma = P @ np.swapaxes(F, 1, 2) / J[:, None, None]
        return -np.trace(sigma, axis1=1, axis2=2) / dim

    rho = rho0 / Js
    slope = (pressure(rho * (1 + h)) - pressure(rho * (1 - h))) / (2 * h * rho)
    c2 = np.array([material.wave_speed(J) ** 2 for J in Js])
    g = material.gamma
    tol = 2 * h**2 * abs((g - 1) * (g - 2)) / 6 + 16 * eps / h
    np.testing.assert_allclose(c2, slope, rtol=tol, atol=0)
    # a compressed fluid is stiffer: the step limit's c(J_min) grows as J^((1 - gamma) / 2)
    assert np.all(np.diff(c2) < 0)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", SOLIDS, ids=lambda m: m.name)
def test_solid_wave_speed_is_its_own_p_wave_modulus(material, dim):
    """c^2 rho = dP_11 / dF_11 at F = I, the P-wave modulus lambda + 2 mu of
    the material's own stress (in 2D too: plane strain), by a centred
    difference with h = 1e-6: truncation O(h^2), round-off of P about eps
    (lambda + 2 mu) (F - R and J - 1 near the identity) over h: relative
    eps / h = 2.2e-10 (measured 3e-11)."""
    h = 1e-6
    eps = np.finfo(np.float64).eps
    F = np.stack([np.eye(dim), np.eye(dim)])
    F[0, 0, 0] += h
    F[1, 0, 0] -= h
    P, _ = evaluate(material, F)
    modulus = (P[0, 0, 0] - P[1, 0, 0]) / (2 * h)
    assert material.wave_speed() ** 2 * material.rho == pytest.approx(modulus, rel=eps / h, abs=0)
