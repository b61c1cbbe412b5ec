"""The explicit step limit, term by term (mpm.timestep), and the strain rate
the solver reports for it."""

import math

import numpy as np
import pytest

import mpm
from helpers import DEVICE
from mpm.timestep import STRAIN_STEP, step_limits


def test_terms_and_the_fresh_reference():
    """wave: cfl s dx / (c + v); viscous: cfl (s dx)^2 / (2 d nu); strain
    rate: STRAIN_STEP cfl / |L|; fresh: the same with s = 1."""
    dx, c, v, cfl, nu, d = 0.01, 20.0, 5.0, 0.4, 1e-3, 2
    lim = step_limits(dx, 0.5, c, v, cfl, nu, d, rate=100.0)
    assert lim.wave == pytest.approx(cfl * 0.5 * dx / (c + v))
    assert lim.viscous == pytest.approx(cfl * (0.5 * dx) ** 2 / (2 * d * nu))
    assert lim.strain_rate == pytest.approx(STRAIN_STEP * cfl / 100.0)
    assert lim.fresh == pytest.approx(min(cfl * dx / (c + v), cfl * dx**2 / (2 * d * nu), lim.strain_rate))
    assert lim.dt == min(lim.wave, lim.viscous, lim.strain_rate)
    assert lim.binding == "wave" and lim.reference_factor == pytest.approx(0.5)
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
    np.testing.assert_allclose(report.max_rate[0], np.linalg.norm(L, axis=(1, 2)).max(), rtol=1e-9)
    # a turn: |L| is about the spin, sqrt(2) omega in the Frobenius norm
    assert math.sqrt(2) * 10.0 * 0.5 < report.max_rate[0] < 2.0 * math.sqrt(2) * 10.0
