"""The trade-off experiment's error measure and its report section, on a
small synthetic sweep."""

import csv

import numpy as np
import pytest

from pipelines.report import write_report
from pipelines.report.sections.tradeoff import center_of_mass, mass_distribution, shape_error
from test_report import _job, _metrics


def lattice(lo, hi, h):
    """Particles on a lattice of spacing h filling [lo, hi]^2, as the scenes sample bodies."""
    g = np.arange(lo + h / 2, hi, h)
    return np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)


def test_mass_distribution_conserves_mass_and_ignores_particle_count():
    rng = np.random.default_rng(0)
    x = lattice(0.2, 0.8, 0.01)
    f = mass_distribution(x, None, (1.0, 1.0))
    assert f.sum() == pytest.approx(1.0, abs=1e-12)
    # the same body sampled with 4x as many particles of other masses: the
    # distributions agree to the sampling's edge effects
    y = lattice(0.2, 0.8, 0.005)
    assert shape_error(x, None, y, np.full(len(y), 3.0), (1.0, 1.0)) < 1e-3
    # identical: zero; disjoint halves of the domain: one
    assert shape_error(x, None, x, None, (1.0, 1.0)) == 0.0
    a = rng.uniform([0.05, 0.05], [0.4, 0.95], size=(2000, 2))
    b = a + [0.5, 0.0]
    assert shape_error(a, None, b, None, (1.0, 1.0)) == pytest.approx(1.0)


def test_shape_error_grows_with_a_shift():
    """A uniform block shifted by s (less than a bin) loses the fraction
    s / width of its mass to new bins, up to the linear weights' smoothing:
    the distance is of that order and grows monotonically with s."""
    rng = np.random.default_rng(1)
    x = rng.uniform([0.3, 0.3, 0.3], [0.7, 0.7, 0.7], size=(30000, 3))
    errs = [shape_error(x, None, x + [s, 0, 0], None, (1.0, 1.0, 1.0)) for s in (0.01, 0.02, 0.04)]
    assert errs[0] < errs[1] < errs[2]
    assert 0.3 * 0.04 / 0.4 < errs[2] < 2.0 * 0.04 / 0.4
    np.testing.assert_allclose(center_of_mass(x + [0.04, 0, 0], None) - center_of_mass(x, None),
                               [0.04, 0, 0], atol=1e-12)


def test_report_reads_a_tradeoff_sweep(tmp_path):
    """Reference, EMPM and three A-ULMPM points: errors against the reference,
    the Pareto front, the plot."""
    rng = np.random.default_rng(2)
    ref = rng.uniform(0.3, 0.7, size=(8000, 2))
    X0 = rng.uniform(0.3, 0.7, size=(2000, 2))
    points = {  # name: (scheme, run time [s], shift of the final state)
        "reference": ("empm", 50.0, 0.0), "empm": ("empm", 5.0, 0.02),
        "paper": ("aulmpm", 9.0, 0.01), "distortion": ("aulmpm", 4.0, 0.03),
        "distortion_s0.9": ("aulmpm", 6.0, 0.05)}
    for name, (scheme, t, shift) in points.items():
        x = ref if name == "reference" else X0 + [shift, 0.0]
        _job(tmp_path, name, _metrics(scheme, "quadratic", 16, scene="droplet_2d", loop_time_s=t,
                                      config_hash=name),
             ["scene=droplet_2d", f"+tradeoff={name}", "+experiment=aulmpm_tradeoff"],
             state={"x": x, "v": np.zeros_like(x), "X0": x, "mass": np.ones(len(x))})
    write_report(tmp_path)
    rows = {r["point"]: r for r in csv.DictReader(open(tmp_path / "tradeoff.csv"))}
    assert set(rows) == set(points)
    assert rows["reference"]["shape error"] == ""
    for name, (_, _, shift) in points.items():
        if name != "reference":
            x = X0 + [shift, 0.0]
            assert float(rows[name]["shape error"]) == pytest.approx(shape_error(x, None, ref, None, (1.0, 1.0)))
    err = {n: float(r["shape error"]) for n, r in rows.items() if n != "reference"}
    assert err["paper"] < err["empm"] < err["distortion"] < err["distortion_s0.9"]
    assert (tmp_path / "tradeoff.png").is_file()
    text = (tmp_path / "report.md").read_text()
    front = next(line for line in text.splitlines() if line.startswith("droplet_2d: on the Pareto front"))
    # distortion (fastest), empm (faster than paper... 5 s, better than distortion), paper (best);
    # distortion_s0.9 is dominated by empm
    assert "distortion," in front and "empm" in front and "paper" in front and "s0.9" not in front


def test_report_reads_a_stiff_integration_sweep(tmp_path):
    """Reference, explicit and implicit points: RMS errors against the
    reference (same particles), the cheapest point per error target, the plot."""
    from pipelines.report.sections.integration import cheapest, rms

    rng = np.random.default_rng(3)
    x_ref = rng.uniform(0.3, 0.7, size=(500, 2))
    points = {  # name: (integrator, run time [s], shift of the final positions [m])
        "reference": ("explicit", 80.0, 0.0), "explicit": ("explicit", 10.0, 1e-4),
        "implicit_dt1e-4": ("implicit", 20.0, 5e-4), "implicit_dt1e-3": ("implicit", 2.0, 5e-3)}
    for name, (integrator, t, shift) in points.items():
        x = x_ref + [shift, 0.0]
        metrics = _metrics("empm", "quadratic", 32, scene="elastic_ball_2d", loop_time_s=t, config_hash=name,
                           integrator=integrator)
        if integrator == "implicit":
            metrics["implicit"] = {"newton_mean": 2.0, "cg_per_newton": 30.0}
        _job(tmp_path, name, metrics, ["scene=elastic_ball_2d", f"+stiff={name}", "+experiment=implicit_stiff"],
             state={"x": x, "v": np.zeros_like(x), "X0": x_ref, "mass": np.ones(len(x))})
    write_report(tmp_path)
    rows = {r["point"]: r for r in csv.DictReader(open(tmp_path / "integration.csv"))}
    assert set(rows) == set(points) and rows["reference"]["position error [m]"] == ""
    for name, (_, _, shift) in points.items():
        if name != "reference":
            assert float(rows[name]["position error [m]"]) == pytest.approx(shift, rel=1e-9)
    assert float(rows["implicit_dt1e-4"]["Newton / step"]) == 2.0
    text = (tmp_path / "report.md").read_text()
    assert "position error <= 0.0001 m (1x the explicit point's): fastest `explicit`" in text
    assert "(10x the explicit point's): fastest `explicit`" in text
    assert "(100x the explicit point's): fastest `implicit_dt1e-3` in 2 s" in text
    assert (tmp_path / "integration.png").is_file()
    pts = [("a", 1.0, 3.0), ("b", 2.0, 1.0)]
    assert cheapest(pts, 2.0)[0] == "b" and cheapest(pts, 0.5) is None
    assert rms(np.zeros((2, 2)), np.ones((2, 2))) == pytest.approx(np.sqrt(2))
