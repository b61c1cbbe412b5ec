"""The explicit step limit, term by term (mpm.stepping.timestep), and the strain rate
the solver reports for it."""

import functools
import math

import numpy as np
import pytest

import mpm
from helpers import DEVICE
from mpm.stepping.timestep import STRAIN_STEP, step_limits

EPS = np.finfo(np.float64).eps


def test_terms_and_the_fresh_reference():
    """wave: cfl s dx / (c + v); viscous: cfl (s dx)^2 / (2 d nu); strain
    rate: STRAIN_STEP cfl / |L|; fresh: the same with s = 1 (to an ulp or two:
    the same operations, maybe in another order)."""
    approx = functools.partial(pytest.approx, rel=2 * EPS, abs=0)
    dx, c, v, cfl, nu, d = 0.01, 20.0, 5.0, 0.4, 1e-3, 2
    lim = step_limits(dx, 0.5, c, v, cfl, nu, d, rate=100.0)
    assert lim.wave == approx(cfl * 0.5 * dx / (c + v))
    assert lim.viscous == approx(cfl * (0.5 * dx) ** 2 / (2 * d * nu))
    assert lim.strain_rate == approx(STRAIN_STEP * cfl / 100.0)
    assert lim.fresh == approx(min(cfl * dx / (c + v), cfl * dx**2 / (2 * d * nu), lim.strain_rate))
    assert lim.dt == min(lim.wave, lim.viscous, lim.strain_rate)
    assert lim.binding == "wave" and lim.reference_factor == approx(0.5)
    # no rate, no viscosity: those terms are off; the step a fresh reference allows is the wave's
    lim = step_limits(dx, 1.0, c, 0.0, cfl, 0.0, d, rate=0.0)
    assert math.isinf(lim.viscous) and math.isinf(lim.strain_rate) and lim.reference_factor == 1.0
    # a fast shear binds through the strain rate, which an update does not change
    lim = step_limits(dx, 0.8, c, 0.0, cfl, 0.0, d, rate=1e4)
    assert lim.binding == "strain_rate" and lim.reference_factor == 1.0


def test_reported_strain_rate_is_the_current_velocity_gradient():
    """TLMPM: G2P's velocity gradient is taken in the reference,
    grad_v = dv/dX, and L = grad_v (F^sn)^-1 with F^sn at the step's start;
    the solver reports max |L| itself (not the bound |grad_v| / s_min, which
    a sheared reference cell inflates)."""
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32,
                      bodies=[mpm.Body(mpm.Box((0.5, 0.5), (0.12, 0.12)), mpm.NeoHookean(E=2e3, nu=0.3),
                                       angular_velocity=10.0)],
                      gravity=(0.0, 0.0), walls=("slip",) * 4)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", DEVICE)
    solver = mpm.Solver(model, mpm.TLMPM())
    solver.prepare(state)
    dt = 2e-4
    for _ in range(400):  # the plate turns 0.8 rad: its reference cells are far from the current ones
        F_old = state.Fsn.numpy().copy()
        report = solver.advance(state, dt)
    s = state.numpy()
    grad_v = (s["Fsn"] - F_old) / dt
    L = grad_v @ np.linalg.inv(F_old)
    # (F_new - F_old) / dt cancels all but dt |L| ~ 2e-3 of F's digits: relative round-off eps / (dt |L|)
    rate = np.linalg.norm(L, axis=(1, 2)).max()
    np.testing.assert_allclose(report.max_rate[0], rate, rtol=2 * EPS / (dt * rate))
    # a turn: |L| is about the spin, sqrt(2) omega in the Frobenius norm
    assert math.sqrt(2) * 10.0 * 0.5 < report.max_rate[0] < 2.0 * math.sqrt(2) * 10.0


def _report(n_bodies, **fields):
    """A StepReport written by hand: the figures a step would leave, the rest neutral."""
    z = np.zeros(n_bodies)
    base = dict(max_speed=0.0, nonfinite=0, outside=0, marked=z.astype(np.int64), max_dJ=z,
                min_J=np.full(n_bodies, np.inf), min_stretch=np.full(n_bodies, np.inf), max_rate=z,
                stiffening=z, box_lo=np.zeros((n_bodies, 2)), box_hi=np.ones((n_bodies, 2)))
    return mpm.StepReport(**{**base, **{k: np.asarray(v, float) if k not in ("max_speed",) else v
                                        for k, v in fields.items()}})


def _independent_limits(material, dx, dim, cfl, J, s, stiffening, rate, speed):
    """The step limit's terms from the material parameters alone (module
    docstring of mpm.stepping.timestep): the P-wave speed sqrt((lambda + 2 mu) / rho)
    with the Lame parameters of E, nu (3D / plane strain, also in 2D:
    mpm.materials.base.lame), the fluid's c^2 = dp/drho = K gamma
    (rho / rho0)^(gamma - 1) / rho0 of p = K ((rho / rho0)^gamma - 1) at the
    most compressed J = rho0 / rho (1e-3 <= J <= 1: a stretched fluid keeps
    its rest speed), grown by sqrt(stiffening) when > 0; the stretch s within
    [1e-3, 1]; nu = eta / rho."""
    if hasattr(material, "K"):
        Jc = min(max(J, 1e-3), 1.0)
        c2 = material.K * material.gamma * (1.0 / Jc) ** (material.gamma - 1.0) / material.rho
        nu = material.viscosity / material.rho
    else:
        mu = material.E / (2.0 * (1.0 + material.nu))
        lam = material.E * material.nu / ((1.0 + material.nu) * (1.0 - 2.0 * material.nu))
        c2 = (lam + 2.0 * mu) / material.rho
        nu = 0.0
    c = math.sqrt(c2 * (stiffening if stiffening > 0 else 1.0))
    s = min(max(s, 1e-3), 1.0)

    def terms(s):
        wave = cfl * s * dx / (c + speed)
        viscous = cfl * (s * dx) ** 2 / (2 * dim * nu) if nu > 0 else math.inf
        strain = STRAIN_STEP * cfl / rate if rate > 0 else math.inf
        return wave, viscous, strain

    wave, viscous, strain = terms(s)
    return wave, viscous, strain, min(terms(1.0))


def test_step_rule_against_the_material_parameters():
    """StepRule.limits and stable_dt of a five-body scene (two elastic
    solids, an inviscid and a viscous fluid, snow), on reports built by
    hand, term by term against the closed forms of _independent_limits, to
    float64 round-off of a few operations (4 eps; measured: equal): at rest (no report,
    particles at max_speed), then compressed, stretched and fast, with a
    stiffened snow body, a non-finite J (no particle tracked: J = 1) and a
    moving collider whose speed every particle may have to take."""
    bodies = [mpm.Body(mpm.Sphere((0.2, 0.3), 0.05), mpm.FixedCorotated(E=3e5, nu=0.35, rho=1200.0)),
              mpm.Body(mpm.Sphere((0.4, 0.3), 0.05), mpm.NeoHookean(E=5e4, nu=0.45, rho=900.0)),
              mpm.Body(mpm.Sphere((0.6, 0.3), 0.05), mpm.Fluid(K=2e5, gamma=7.0, rho=1000.0)),
              mpm.Body(mpm.Sphere((0.8, 0.3), 0.05), mpm.materials.Viscous(K=3e4, gamma=3.0, viscosity=40.0,
                                                                             rho=1300.0)),
              mpm.Body(mpm.Sphere((0.5, 0.7), 0.05), mpm.materials.Snow(E=1.4e5, nu=0.2, rho=400.0))]
    collider = mpm.Collider("half_space", point=(0.0, 0.1), normal=(0.0, 1.0), velocity=(0.0, 1.5))
    for colliders, u in (([], 0.0), ([collider], 1.5)):
        scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=40, bodies=bodies, colliders=colliders, ppc=1)
        model, _ = mpm.build(scene, mpm.KERNELS["quadratic"], "float32", DEVICE)
        rule = mpm.Solver(model).timestep
        dx, cfl = 1.0 / 40, 0.4
        cases = [(None, dict(J=[1.0] * 5, s=[1.0] * 5, stiff=[0.0] * 5, rate=[0.0] * 5, speed=3.0)),
                 (_report(5, max_speed=2.0, min_J=[0.9, np.inf, 0.8, 0.6, 0.97], min_stretch=[0.7, 0.5, 0.9, 0.2, 1e-5],
                          stiffening=[0.0, 0.0, 0.0, 0.0, 2.5], max_rate=[10.0, 0.0, 300.0, 100.0, 5.0]),
                  dict(J=[0.9, 1.0, 0.8, 0.6, 0.97], s=[0.7, 0.5, 0.9, 0.2, 1e-5], stiff=[0.0, 0.0, 0.0, 0.0, 2.5],
                       rate=[10.0, 0.0, 300.0, 100.0, 5.0], speed=2.0)),
                 (_report(5, max_speed=40.0, min_J=[1.2, 1.5, 1.3, 2e-4, 1.0], min_stretch=[3.0, 1.0, 1.0, 0.5, 0.9],
                          max_rate=[0.0, 1e4, 0.0, 0.0, 0.0]),
                  dict(J=[1.2, 1.5, 1.3, 2e-4, 1.0], s=[3.0, 1.0, 1.0, 0.5, 0.9], stiff=[0.0] * 5,
                       rate=[0.0, 1e4, 0.0, 0.0, 0.0], speed=40.0))]
        for report, f in cases:
            got = rule.limits(cfl, report, max_speed=3.0)
            speed = max(f["speed"], u)
            want = [_independent_limits(b.material, dx, 2, cfl, f["J"][i], f["s"][i], f["stiff"][i], f["rate"][i],
                                        speed) for i, b in enumerate(bodies)]
            for b, (lim, (wave, viscous, strain, fresh)) in enumerate(zip(got, want)):
                for name, value, expected in (("wave", lim.wave, wave), ("viscous", lim.viscous, viscous),
                                              ("strain_rate", lim.strain_rate, strain), ("fresh", lim.fresh, fresh)):
                    assert value == pytest.approx(expected, rel=4 * EPS, abs=0), (b, name, report is None)
                assert lim.binding == ("wave", "viscous", "strain_rate")[int(np.argmin([wave, viscous, strain]))]
            assert rule.stable_dt(cfl, report, max_speed=3.0) == pytest.approx(
                min(min(w[:3]) for w in want), rel=4 * EPS, abs=0)
        # every term binds somewhere: the cases exercise them all
        bindings = {lim.binding for report, _ in cases for lim in rule.limits(cfl, report, max_speed=3.0)}
        assert bindings == {"wave", "viscous", "strain_rate"}
