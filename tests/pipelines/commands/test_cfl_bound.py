"""python -m pipelines.cfl_bound: the explicit step's linear stability bound
per kernel."""

import numpy as np
import pytest


def test_linear_bound_of_the_lumped_hat_kernel_is_the_cfl_number_one():
    """pipelines.cfl_bound against the closed form: linear elements with
    lumped mass have omega_max = 2 c / dx, i.e. k* = 1 exactly, in 1D and
    2D, with MLS or gradient weights; the smoother B-splines allow more
    (quadratic sqrt(3) in 1D with the exact gradient on a fine periodic
    lattice, within the lattice's resolution of the highest mode)."""
    from pipelines.cfl_bound import bound

    for dim in (1, 2):
        for mls in (True, False):
            assert bound("linear", mls, dim=dim, cells=8) == pytest.approx(1.0, rel=1e-9)
    assert bound("quadratic", False, dim=1, cells=40) == pytest.approx(np.sqrt(3.0), rel=1e-3)
    assert bound("linear", dim=1) < bound("quadratic", dim=1) < bound("cubic", dim=1)


def test_the_body_bound_predicts_the_stiff_balls_growth():
    """pipelines.cfl_bound.body_bound, a linear model of the explicit MLS
    step built from the stability ball's own particles (its light surface
    nodes, the APIC round trip), against the solver itself: the model's
    critical step lies between the maps' last stable and first unstable k
    (1.1 and 1.2, quadratic), and at k = 1.2 the solver's period-2 mode grows
    by the model's largest |eigenvalue| per step (measured 1.1877 over steps
    15-45 against 1.1880), float64 EMPM, E = 1e12 Pa (c >> the throw, the
    linear regime)."""
    import mpm
    from helpers import spec_for
    from pipelines.cfl_bound import body_bound
    from pipelines.run.stability_map import cfl_limit, point_spec

    spec = point_spec(spec_for(["scene=stability_ball_2d", "run.precision=float64"]), 1e12, 1.2, 60)
    model, state = mpm.build(spec.scene, spec.kernel, "float64", "cpu", spec.seed, samples=spec.take_samples())
    x, volume = state.x.numpy(), model.volume.numpy().astype(float)
    band = spec.scene.wall_cells * model.dx
    k_star, growth = body_bound(x, volume, "quadratic", model.dx, walls=(0, 1), lo=band, hi=1.0 - band)
    assert 1.1 < k_star < 1.2
    assert spec.run.dt == pytest.approx(1.2 * cfl_limit(spec.scene))
    solver = mpm.Solver(model, spec.scheme, mpm.SolverOptions(integrator=mpm.Explicit()))
    solver.prepare(state)
    v = []
    for _ in range(60):
        report = solver.advance(state, spec.run.dt)
        assert report.reason is None, report.reason
        v.append(state.v.numpy().astype(np.float64))
    v = np.asarray(v)
    period2 = np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=2).max(axis=1)  # the alternating mode's size
    # seeded by the ball's initial strain and the impact, it dominates from step ~10 and
    # saturates (large deformation) after ~50
    measured = (period2[45] / period2[15]) ** (1 / 30)
    assert measured == pytest.approx(growth, rel=2e-3), (measured, growth)
