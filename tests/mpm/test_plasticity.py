"""Return mappings at one material point (mpm.materials.point_driver, float64)
against their closed forms: yield where the model says, stay on the yield
surface, projections idempotent, elastic states untouched."""

import math

import numpy as np
import pytest

import mpm
from mpm.materials.point_driver import MaterialPoint, deformation_path, velocity_path

EPS = np.finfo(np.float64).eps
PLASTIC = [mpm.materials.Snow(), mpm.materials.Sand(), mpm.materials.VonMises(),
           mpm.materials.NACC(), mpm.materials.Viscoplastic()]


def principal(tau):
    """Principal values of symmetric stresses (..., d, d), descending."""
    return np.linalg.eigvalsh(tau)[..., ::-1]


def von_mises_stress(tau):
    """sqrt(3/2) |dev tau| (3D)."""
    d = tau.shape[-1]
    dev = tau - np.trace(tau, axis1=-2, axis2=-1)[..., None, None] / d * np.eye(d)
    return np.sqrt(1.5 * np.sum(dev * dev, axis=(-2, -1)))


@pytest.mark.parametrize("H", [0.0, 2.0e5])
def test_von_mises_uniaxial_tension_yields_at_sigma_y(H):
    """Uniaxial Kirchhoff stress along x (lateral stresses solved to zero),
    stretch to 3 % Hencky strain. With principal directions fixed the Hencky
    strains add, so the 1-D closed form holds exactly:
        tau_xx = E eps                                    eps <= sigma_y / E,
        tau_xx = sigma_y + E H / (E + H) (eps - sigma_y / E)    beyond,
    and on the plastic branch sqrt(3/2)|dev tau| = sigma_y + H eps_p.
    The driver solves the lateral stresses to tol = 1e-13 of the axial one,
    or to their round-off, eps times stresses of the order of E (E eps ~
    2e-10 Pa): tau_xx within 8 tol sigma_y + 16 eps E (measured 1e-9 Pa),
    the lateral ones within 8 tol |tau_xx| + 16 eps E; the yield condition to round-off, 128 eps
    (measured 47 eps); eps_p = eps - tau_xx / E within 16 eps (a logarithm
    of stretches ~ 1; measured 6 eps). (With H > 0 the float64 solver's
    hardening term 2 H / 3 misses by 3e-8, and tau_xx by 1e-10 sigma_y.)"""
    E, sy, tol = 1.0e6, 1.0e4, 1e-13
    mat = mpm.materials.VonMises(E=E, nu=0.3, yield_stress=sy, hardening=H)
    eps = np.linspace(0.0, 0.03, 121)
    r = MaterialPoint(mat, 3).uniaxial_stress(np.exp(eps), dt=1e-3, tol=tol)
    tau = r.tau[:, 0]
    expected = np.where(eps <= sy / E, E * eps, sy + E * H / (E + H) * (eps - sy / E))
    floor = 16 * EPS * E
    np.testing.assert_allclose(tau[:, 0, 0], expected, rtol=0, atol=8 * tol * sy + floor)
    assert np.all(np.abs(tau[:, [1, 2], [1, 2]]) <= 8 * tol * np.abs(tau[:, :1, 0]) + floor)
    plastic = eps > sy / E + 1e-4
    eps_p = r.history[:, 0, 1]
    np.testing.assert_allclose(von_mises_stress(tau)[plastic], sy + H * eps_p[plastic], rtol=128 * EPS)
    # the equivalent plastic strain is the axial plastic strain: eps - tau_xx / E
    np.testing.assert_allclose(eps_p[plastic], eps[plastic] - tau[plastic, 0, 0] / E, rtol=0, atol=16 * EPS)


@pytest.mark.parametrize("dim", [2, 3])
def test_von_mises_shear_stays_on_the_surface(dim):
    """Simple shear far past yield: |dev tau| never exceeds sqrt(2/3) sigma_y
    and sits on it once yielding (perfect plasticity); in 3D simple shear
    that is tau_xy -> sigma_y / sqrt(3)."""
    sy = 1.0e4
    mat = mpm.materials.VonMises(E=1e6, nu=0.3, yield_stress=sy)
    L = np.zeros((dim, dim))
    L[0, 1] = 1.0
    r = MaterialPoint(mat, dim).run(velocity_path(L, 1e-3, 300), 1e-3)
    tau = r.tau[:, 0]
    dev = tau - np.trace(tau, axis1=-2, axis2=-1)[:, None, None] / dim * np.eye(dim)
    norm = np.sqrt(np.sum(dev * dev, axis=(-2, -1)))
    assert norm.max() <= math.sqrt(2 / 3) * sy * (1 + 128 * EPS)
    yielded = r.history[:, 0, 1] > 0
    assert yielded.sum() > 200
    np.testing.assert_allclose(norm[yielded], math.sqrt(2 / 3) * sy, rtol=128 * EPS)  # measured 50 eps
    if dim == 3:
        assert tau[-1, 0, 1] == pytest.approx(sy / math.sqrt(3), rel=2e-3)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("phi,cohesion", [(30.0, 0.0), (20.0, 0.0), (35.0, 500.0)])
def test_drucker_prager_shear_strength_is_tan_phi_times_normal_stress(phi, cohesion, dim):
    """Isotropic compression, then axial compression at constant volume (the
    lateral sides expand alike): the lateral stresses stay equal, so in 3D the
    state is on the triaxial-compression meridian where the cone is exactly
    Mohr-Coulomb (2D: the cone is Mohr-Coulomb). With compression positive,
    once yielding
        (s1 - s3) = (s1 + s3 + 2 c cot phi) sin phi,
    i.e. the Mohr circle touches tau = c + sigma_n tan phi, never crossing it."""
    mat = mpm.materials.Sand(E=1e5, nu=0.3, friction_angle=phi, cohesion=cohesion)
    n1, n2 = 20, 200
    a = np.concatenate([np.linspace(1.0, 0.99, n1 + 1), 0.99 * np.linspace(1.0, 0.9, n2 + 1)[1:]])
    b = np.concatenate([np.linspace(1.0, 0.99, n1 + 1), (0.99**dim / a[n1 + 1:]) ** (1 / (dim - 1))])
    F = np.array([np.diag([ai] + [bi] * (dim - 1)) for ai, bi in zip(a, b)])
    r = MaterialPoint(mat, dim).run(deformation_path(F), 1e-3)
    s = -principal(r.tau[:, 0])[:, ::-1]  # compression positive, s1 the largest
    s1, s3 = s[:, 0], s[:, -1]
    shift = 2 * cohesion / math.tan(math.radians(phi))
    gap = (s1 + s3 + shift) * math.sin(math.radians(phi)) - (s1 - s3)
    scale = np.abs(s1).max()
    # round-off of principal stresses from an SVD, logarithms and eigvalsh: 1024 eps of the
    # largest (measured 290 eps)
    assert gap.min() >= -1024 * EPS * scale  # never outside the cone
    yielded = r.history[:, 0, 1] > 0
    assert yielded.sum() > n2 // 2
    np.testing.assert_allclose(gap[yielded], 0.0, atol=1024 * EPS * scale)
    # the Mohr circle's tangency: max over planes of tau - sigma_n tan phi is c
    centre, radius = (s1 + s3) / 2, (s1 - s3) / 2
    cos, sin = math.cos(math.radians(phi)), math.sin(math.radians(phi))
    tau_f, sigma_n = radius * cos, centre - radius * sin
    np.testing.assert_allclose((tau_f - sigma_n * math.tan(math.radians(phi)))[yielded], cohesion,
                               atol=1024 * EPS * scale)


@pytest.mark.parametrize("dim", [2, 3])
def test_drucker_prager_holds_no_tension(dim):
    """Stretched in any direction from rest (no cohesion), sand carries no
    stress at all, and it remembers the dilation (volume correction)."""
    rng = np.random.default_rng(0)
    mat = mpm.materials.Sand(E=1e5, nu=0.3, friction_angle=30.0)
    mp = MaterialPoint(mat, dim)
    F = np.eye(dim) + 0.05 * rng.standard_normal((50, dim, dim))
    F = F[np.linalg.det(F) > 1.001]
    F_E, P, _, hist = mp.evaluate(F, mp.initial_history(len(F)), 1e-3)
    assert np.abs(P).max() < 1e-9 * mat.E
    # a logarithm of a volume ratio near 1: its round-off is absolute, a few eps (measured 10 eps)
    np.testing.assert_allclose(hist[:, 0], np.log(np.linalg.det(F)), rtol=0, atol=32 * EPS)
    # compressed back to the original volume, the grains only just touch:
    # no pressure until the remembered dilation is used up
    J = np.linalg.det(F)
    back = np.eye(dim) * (1 / J[:, None, None]) ** (1 / dim) @ F_E
    _, P2, _, hist2 = mp.evaluate(back, hist, 1e-3)
    assert np.abs(P2).max() < 1e-6 * mat.E and np.abs(hist2[:, 0]).max() < 1e-9


@pytest.mark.parametrize("dim", [2, 3])
def test_sand_hardening_follows_klar(dim):
    """With Klar's hardening the cone the return mapping uses has the friction
    angle phi(q) = phi0 + (h1 q - h3) exp(-h2 q), q = sqrt(3/2) eps_p the
    accumulated plastic strain at the start of the step: on the yielding
    steps of a triaxial compression (s1 - s3) = (s1 + s3) sin phi(q), and phi
    moves from phi0 - h3 towards phi0 as q grows."""
    mat = mpm.materials.Sand(E=1e5, nu=0.3, friction_angle=35.0, h1=9.0, h2=0.2, h3=10.0)
    n1, n2 = 20, 400
    a = np.concatenate([np.linspace(1.0, 0.99, n1 + 1), 0.99 * np.linspace(1.0, 0.6, n2 + 1)[1:]])
    b = np.concatenate([np.linspace(1.0, 0.99, n1 + 1), (0.99**dim / a[n1 + 1:]) ** (1 / (dim - 1))])
    F = np.array([np.diag([ai] + [bi] * (dim - 1)) for ai, bi in zip(a, b)])
    r = MaterialPoint(mat, dim).run(deformation_path(F), 1e-3)
    s = -principal(r.tau[1:, 0])[:, ::-1]
    s1, s3 = s[:, 0], s[:, -1]
    phi = np.radians(mat.friction_angle_at(r.history[:-1, 0, 1]))  # q before each step
    yielded = np.diff(r.history[:, 0, 1]) > 0
    assert yielded.sum() > n2 // 2
    np.testing.assert_allclose((s1 - s3)[yielded], ((s1 + s3) * np.sin(phi))[yielded],
                               rtol=0, atol=1024 * EPS * np.abs(s1).max())
    q = r.history[[n1 + 1, -1], 0, 1] / math.sqrt(2 / 3)
    assert mat.friction_angle_at(r.history[-1, 0, 1]) > mat.friction_angle_at(r.history[n1 + 2, 0, 1])
    np.testing.assert_allclose(mat.friction_angle_at(q * math.sqrt(2 / 3)),
                               35.0 + (9.0 * q - 10.0) * np.exp(-0.2 * q), rtol=16 * EPS)


@pytest.mark.parametrize("dim", [2, 3])
def test_snow_clamps_and_moves_volume_into_J_P(dim):
    """Singular values of F_E stay in [1 - theta_c, 1 + theta_s]; the
    plastic volume goes to J_P so that det F = det F_E J_P along any path;
    the moduli harden by exp(xi (1 - J_P))."""
    rng = np.random.default_rng(1)
    mat = mpm.materials.Snow()
    steps = 60
    L = rng.standard_normal((dim, dim)) * 2.0 - 1.5 * np.eye(dim)  # net compression
    r = MaterialPoint(mat, dim).run(velocity_path(L, 2e-3, steps), 2e-3)
    sig = np.linalg.svd(r.F_E[:, 0], compute_uv=False)
    assert sig.min() >= 1 - mat.theta_c - 1e-12 and sig.max() <= 1 + mat.theta_s + 1e-12
    J_P = np.exp(r.history[:, 0, 0])
    # J_P sums the steps' logarithms: a few eps per step (measured up to 7 eps per step)
    np.testing.assert_allclose(np.linalg.det(r.F[:, 0]), np.linalg.det(r.F_E[:, 0]) * J_P, rtol=16 * EPS * steps)
    assert J_P[-1] < 0.9  # it was compacted
    # the stress is fixed corotated with the hardened moduli
    fields = mat.fields(r.history[-1], np.linalg.det(r.F_E[-1]))
    h = fields["hardening"][0]
    # density: rho0 / J with J = det F = J_E J_P
    assert fields["density_ratio"][0] == pytest.approx(1 / np.linalg.det(r.F[-1, 0]), rel=16 * EPS * steps, abs=0)
    mu, lam = mpm.materials.lame(mat.E, mat.nu)
    FE = r.F_E[-1, 0]
    U, s, Vt = np.linalg.svd(FE)
    R = U @ Vt
    J = np.linalg.det(FE)
    P = 2 * h * mu * (FE - R) + h * lam * (J - 1) * J * np.linalg.inv(FE).T
    # round-off of the terms before F - R cancels: eps h (2 mu + lam) |F_E| (16 times; measured 1.4)
    np.testing.assert_allclose(r.P[-1, 0], P, rtol=0, atol=16 * EPS * h * (2 * mu + lam) * np.abs(FE).max())
    assert h == pytest.approx(math.exp(mat.xi * (1 - J_P[-1])), rel=16 * EPS, abs=0)


def nacc_yield(mat, tau, alpha, dim):
    """(y, p, p0) of the NACC ellipse for Kirchhoff stresses tau (n, d, d)."""
    kappa = mat.kappa()
    p0 = kappa * (1e-5 + np.sinh(mat.xi * np.maximum(-alpha, 0.0)))
    p = -np.trace(tau, axis1=-2, axis2=-1) / dim
    s = tau + p[:, None, None] * np.eye(dim)
    q2 = 1.5 * np.sum(s * s, axis=(-2, -1))
    M = mat.slope()
    return (1 + 2 * mat.beta) * q2 + M * M * (p + mat.beta * p0) * (p - p0), p, p0


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("hardening", [False, True])
def test_nacc_stress_stays_within_its_ellipse(hardening, dim):
    """Random compressive and shearing paths: after every step the pressure
    lies in [-beta p0, p0] and the state inside or on the ellipse y <= 0 that
    the return mapping used (the one of alpha at the start of the step)."""
    rng = np.random.default_rng(2)
    mat = mpm.materials.NACC(E=2e4, nu=0.3, alpha0=-0.05, beta=0.5, xi=3.0, hardening=hardening)
    for trial in range(4):
        L = rng.standard_normal((dim, dim)) * 3.0 - 1.0 * np.eye(dim)
        r = MaterialPoint(mat, dim).run(velocity_path(L, 1e-3, 100), 1e-3)
        y, p, p0 = nacc_yield(mat, r.tau[1:, 0], r.history[:-1, 0, 0], dim)
        scale = mat.kappa() ** 2
        assert np.all(y <= 1e-9 * scale), (trial, y.max() / scale)
        assert np.all(p <= p0 * (1 + 1e-9)) and np.all(p >= -mat.beta * p0 * (1 + 1e-9))
        assert r.history[-1, 0, 1] > 0  # it did yield
        if not hardening:
            np.testing.assert_array_equal(r.history[:, 0, 0], mat.alpha0)


def test_nacc_compaction_hardens():
    """Isotropic compression past the tip p0 compacts the clay: alpha = ln J_P
    falls by the plastic volume change, the pressure sits on the tip p0 of the
    step's ellipse, and the next ellipse is larger."""
    mat = mpm.materials.NACC(E=2e4, nu=0.3, alpha0=-0.01, beta=0.5, xi=3.0)
    F = np.array([np.eye(3) * s for s in np.linspace(1.0, 0.8, 101)])
    r = MaterialPoint(mat, 3).run(deformation_path(F), 1e-3)
    alpha = r.history[:, 0, 0]
    assert np.all(np.diff(alpha) <= 0.0) and alpha[-1] < mat.alpha0 - 0.05
    y, p, p0 = nacc_yield(mat, r.tau[1:, 0], alpha[:-1], 3)
    compacted = np.diff(alpha) < 0
    assert compacted.sum() > 10
    np.testing.assert_allclose(p[compacted], p0[compacted], rtol=64 * EPS)
    # J = J_E J_P: the plastic part is exp(alpha - alpha0)
    J, J_E = np.linalg.det(r.F[:, 0]), np.linalg.det(r.F_E[:, 0])
    np.testing.assert_allclose(J, J_E * np.exp(alpha - mat.alpha0), rtol=4 * EPS * len(F))  # a few eps per step


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", PLASTIC, ids=lambda m: m.name)
def test_projection_is_idempotent_and_leaves_elastic_states_alone(material, dim):
    """A second return mapping of a returned state changes nothing (a
    rate-independent projection; the viscoplastic relaxation at dt = 0 and
    NACC without hardening, whose ellipse stays put); a state inside the yield
    surface is returned unchanged, history included."""
    rng = np.random.default_rng(3)
    if isinstance(material, mpm.materials.NACC):
        material = mpm.materials.NACC(hardening=False)
    dt = 0.0 if isinstance(material, mpm.materials.Viscoplastic) else 1e-3
    mp = MaterialPoint(material, dim)
    F = np.eye(dim) + 0.15 * rng.standard_normal((40, dim, dim)) - 0.05 * np.eye(dim)
    F = F[np.linalg.det(F) > 0.5]
    h0 = mp.initial_history(len(F))
    if isinstance(material, mpm.materials.Viscoplastic):  # relax first, then project at dt = 0
        F1, _, _, h1 = mp.evaluate(F, h0, 1e-2)
    else:
        F1, _, _, h1 = mp.evaluate(F, h0, dt)
    F2, _, _, h2 = mp.evaluate(F1, h1, dt)
    # round-off of one more SVD, logarithm and exponential of F ~ 1 (measured up to 20 eps)
    np.testing.assert_allclose(F2, F1, rtol=0, atol=64 * EPS)
    np.testing.assert_allclose(h2[:, 0], h1[:, 0], rtol=0, atol=64 * EPS)
    np.testing.assert_allclose(h2[:, 1], h1[:, 1], rtol=0, atol=64 * EPS)
    # a state well inside the elastic region (tiny deformation, compressed a
    # little for the frictional models) is untouched
    small = np.eye(dim) * 0.9995 + 1e-5 * rng.standard_normal((10, dim, dim))
    h = mp.initial_history(len(small))
    F3, _, _, h3 = mp.evaluate(small, h, 1e-3)
    np.testing.assert_allclose(F3, small, rtol=0, atol=32 * EPS)
    np.testing.assert_array_equal(h3, h)


@pytest.mark.parametrize("n", [1.0, 0.5, 2.0])
def test_viscoplastic_steady_shear_follows_herschel_bulkley(n):
    """Steady simple shear at rate g: tau_xy = tau_Y + K g^n once the elastic
    strain has settled (stiff elasticity: strain ~ tau / mu ~ 1e-5); below
    the yield stress nothing flows. Three rates per flow index."""
    tau_Y, K = 50.0, 10.0
    mat = mpm.materials.Viscoplastic(E=1e7, nu=0.3, yield_stress=tau_Y, viscosity=K, flow_index=n)
    for g in (0.5, 2.0, 8.0):
        L = np.zeros((3, 3))
        L[0, 1] = g
        dt = 2e-5 / g
        r = MaterialPoint(mat, 3).run(velocity_path(L, dt, 1500), dt)
        # the elastic transient has decayed after the 1,500 steps (measured 7e-8)
        assert r.tau[-1, 0, 0, 1] == pytest.approx(tau_Y + K * g**n, rel=1e-6), g
    # below yield: elastic, no plastic strain
    L = np.zeros((3, 3))
    L[0, 1] = 1.0
    soft = mpm.materials.Viscoplastic(E=1e4, nu=0.3, yield_stress=1e3, viscosity=K, flow_index=n)
    r = MaterialPoint(soft, 3).run(velocity_path(L, 1e-3, 20), 1e-3)
    assert r.history[-1, 0, 1] == 0.0


def test_viscoplastic_relaxation_does_not_depend_on_dt():
    """Shear, then hold: the stress relaxes towards the yield stress with the
    time constant K / mu_hat of the flow rule whatever the step (n = 1: the
    implicit update is exact for the linear relaxation at fixed strain)."""
    mat = mpm.materials.Viscoplastic(E=1e5, nu=0.3, yield_stress=50.0, viscosity=10.0)
    out = []
    for dt in (1e-4, 5e-5):
        mp = MaterialPoint(mat, 3)
        L = np.zeros((3, 3))
        L[0, 1] = 1.0
        n_load = int(round(0.02 / dt))
        F = velocity_path(L, dt, n_load)
        F = np.concatenate([F, np.repeat(F[-1:], int(round(0.02 / dt)), axis=0)])
        out.append(mp.run(F, dt).tau[-1, 0, 0, 1])
    assert out[0] == pytest.approx(out[1], rel=5e-7)  # measured 5e-8 (the loading's O(dt) path)
    assert out[0] > 50.0 / math.sqrt(1.0) * 0.99


@pytest.mark.parametrize("hardening", [0.0, 1.0e4])
def test_float64_von_mises_return_mapping_is_the_closed_form(hardening):
    """One float64 return mapping of 200 random trial states (2D, most of them
    past yield) against the NumPy closed form of reference_mpm.plastic_return,
        delta = (2 mu |dev eps| - sqrt(2/3) sigma_y) / (2 mu + 2 H / 3),
    to round-off: F_E within 32 eps (an SVD, a logarithm and an exponential of
    F ~ 1; measured 5 eps without hardening), eps_p within 32 eps. With
    H = 1e4 Pa the solver's 2/3 is the float32 0.6666666865, which moves
    delta by 2.4e-9 of itself and F_E by 2e-10."""
    from reference_mpm import plastic_return

    mat = mpm.materials.VonMises(E=1e5, nu=0.3, yield_stress=1e3, hardening=hardening)
    F = np.eye(2) + 0.04 * np.random.default_rng(7).standard_normal((200, 2, 2))
    h0 = np.zeros((len(F), 2))
    FE, _, _, h = MaterialPoint(mat, 2).evaluate(F, h0, 2e-4)
    ref = [plastic_return(mat, f, hh, 2e-4) for f, hh in zip(F, h0)]
    assert np.count_nonzero([r[1][1] for r in ref]) > 150  # past yield
    eps = np.finfo(np.float64).eps
    np.testing.assert_allclose(FE, np.array([r[0] for r in ref]), rtol=0, atol=32 * eps)
    np.testing.assert_allclose(h, np.array([r[1] for r in ref]), rtol=0, atol=32 * eps)
