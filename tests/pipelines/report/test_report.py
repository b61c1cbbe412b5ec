"""The sweep report: slope fit, Pareto front, and a report over a hand-made
sweep (no simulation)."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from omegaconf import OmegaConf

from pipelines.report import write_report
from pipelines.report.common import pareto_front
from pipelines.report.jobs import assign_labels, load_jobs
from pipelines.report.sections.convergence import fit_slope
from pipelines.sweeps.callback import ReportCallback

ROOT = Path(__file__).resolve().parents[3]
N_PARTICLES = 40


def test_fit_slope_exact():
    h = np.array([0.1, 0.05, 0.025, 0.0125])
    slope, intercept = fit_slope(h, 3.0 * h ** 2)
    assert slope == pytest.approx(2.0, abs=1e-12)
    assert intercept == pytest.approx(np.log10(3.0), abs=1e-12)


def test_fit_slope_noisy():
    rng = np.random.default_rng(0)
    h = 1.0 / np.array([8, 16, 32, 64, 128])
    e = 0.7 * h ** 1.5 * np.exp(0.02 * rng.standard_normal(h.size))
    slope, _ = fit_slope(h, e)
    assert slope == pytest.approx(1.5, abs=0.05)


def test_fit_slope_needs_two_spacings():
    with pytest.raises(ValueError):
        fit_slope([0.1, 0.1], [1.0, 2.0])


def test_pareto_front():
    times = [1.0, 2.0, 3.0, 2.5, 4.0, 0.5, np.nan]
    errors = [5.0, 2.0, 1.0, 3.0, 1.5, 10.0, 0.1]
    # (2.5, 3) is dominated by (2, 2); (4, 1.5) by (3, 1); the NaN point is never on the front
    expected = [True, True, True, False, False, True, False]
    assert pareto_front(times, errors).tolist() == expected


# ------------------------------------------------------------- a fake sweep
def _job(root: Path, name: str, metrics: dict, overrides: list[str], state: dict | None = None) -> Path:
    d = root / name
    (d / ".hydra").mkdir(parents=True)
    (d / "metrics.json").write_text(json.dumps(metrics))
    (d / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    scene = metrics.get("scene", "beam")
    (d / ".hydra" / "config.yaml").write_text(
        f"scene:\n  name: {scene}\n  resolution: {metrics.get('resolution', 16)}\n"
        "  domain: [1.0, 1.0]\nrun:\n  steps: ${scene.resolution}\n")
    if state is not None:
        np.savez(d / "final_state.npz", step=100, time=0.1, **state)
    return d


def _metrics(scheme, kernel, res, **extra) -> dict:
    m = {"status": "completed", "reason": "", "steps": 100, "sim_time": 0.1, "dt": 1e-3,
         "step_time_ms": 1.0 + res / 16, "loop_time_s": 0.1 * res / 8 * (1.5 if scheme == "aulmpm" else 1.0),
         "wall_time_s": 2.0, "compile_time_s": 1.0, "particles": N_PARTICLES,
         "particle_steps_per_s": 1e6, "scene": "beam", "resolution": res, "dx": 1.0 / res,
         "precision": "float64", "scheme": scheme, "kernel": kernel, "transfer": "mls",
         "config_hash": f"{scheme}-{kernel}-{res}", "config_updates": {"total": 3, "beam": 3},
         "updates_per_1e4_steps": 300.0, "update_time_ms": 2.0 if scheme == "empm" else 0.5,
         "fracture": {"total": 0.01 if scheme == "empm" else 0.001, "beam": 0.01},
         "fragments": {"total": 1, "beam": 1}, "mass_drift": 0.0, "momentum_drift": 1e-15,
         "angular_momentum_drift": 1e-14}
    m.update(extra)
    return m


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("sweep")
    rng = np.random.default_rng(1)
    X0 = rng.random((N_PARTICLES, 2))
    num = 0
    for scheme, c in (("empm", 1.0), ("aulmpm", 0.5)):
        x_ref = X0 + 0.01 * rng.random((N_PARTICLES, 2))
        v_ref = rng.standard_normal((N_PARTICLES, 2))
        px, pv = rng.standard_normal((2, N_PARTICLES, 2))
        for res in (8, 16, 32):
            dx = 1.0 / res
            dev = 0.0 if res == 32 else c * dx ** 2  # deviation from the finest job ~ dx^2
            _job(root, str(num), _metrics(scheme, "quadratic", res),
                 [f"scheme={scheme}", f"scene.resolution={res}"],
                 {"x": x_ref + dev * px, "v": v_ref + 3 * dev * pv, "X0": X0})
            num += 1
    # a second kernel (speed ratio), an unstable job, a duplicate of job 1
    _job(root, str(num), _metrics("empm", "cubic", 16, step_time_ms=3.0),
         ["scheme=empm", "kernel=cubic", "scene.resolution=16"])
    num += 1
    _job(root, str(num), _metrics("aulmpm", "quadratic", 64, status="unstable", config_hash="unstable",
                                  reason="step 120 (t = 0.012 s): non-finite velocities"),
         ["scheme=aulmpm", "scheme.epsilon=0.1", "scene.resolution=64"])
    num += 1
    _job(root, str(num), _metrics("empm", "quadratic", 16, skipped=str(root / "1")),
         ["scheme=empm", "scene.resolution=16"])
    num += 1
    # a scene with an analytic solution, in a deeper directory
    for res, err in ((16, 4e-3), (32, 1e-3)):
        _job(root / "analytic", str(res),
             _metrics("tlmpm", "quadratic", res, scene="rotating_plate_2d", config_hash=f"plate-{res}",
                      error={"displacement": err, "velocity": 10 * err, "displacement_max": 2 * err,
                             "velocity_max": 20 * err, "displacement_scale": 0.1, "velocity_scale": 1.0}),
             ["scheme=tlmpm", "scene=rotating_plate_2d", f"scene.resolution={res}"])
    return root


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def report(sweep, tmp_path_factory) -> Path:
    return write_report(sweep, tmp_path_factory.mktemp("out"))


def test_report_files(report):
    out = report.parent
    assert report.name == "report.md"
    for name in ("runs.csv", "error_vs_time.png", "pareto.csv", "convergence.csv", "convergence.png",
                 "update_cost.csv", "speed.csv", "speed.png", "conservation.csv", "fracture.csv",
                 "fracture.png"):
        assert (out / name).is_file(), name
    assert not (out / "conservation.png").exists()  # no recordings
    text = report.read_text()
    for name in ("runs.csv", "error_vs_time.png", "convergence.png", "speed.png", "fracture.png"):
        assert f"]({name})" in text
    assert "No recording.rrd" in text


def test_runs_deduplicated_and_labelled(report):
    rows = _rows(report.parent / "runs.csv")
    assert len(rows) == 10  # 11 jobs, one duplicate
    hashes = [r["config_hash"] for r in rows]
    assert len(set(hashes)) == len(hashes)
    dup = [r for r in rows if r["config_hash"] == "empm-quadratic-16"]
    assert dup[0]["dir"] == "1" and dup[0]["skipped"] == ""
    labels = {r["label"] for r in rows}
    assert "aulmpm · quadratic · mls · scheme.epsilon=0.1" in labels
    assert {"empm · quadratic · mls", "aulmpm · quadratic · mls", "empm · cubic · mls",
            "tlmpm · quadratic · mls"} <= labels
    kinds = {r["dir"]: (r["error_kind"], r["error_reference"]) for r in rows}
    assert kinds["0"] == ("self", "2") and kinds["2"] == ("", "")
    assert kinds["analytic/16"][0] == "analytic"
    text = report.read_text()
    assert "non-finite velocities" in text and "unstable" in text


def test_self_convergence_order(report):
    rows = {(r["scene"], r["label"]): r for r in _rows(report.parent / "convergence.csv")}
    for label in ("empm · quadratic · mls", "aulmpm · quadratic · mls"):
        r = rows[("beam", label)]
        assert int(r["n_displacement"]) == 2
        assert float(r["slope_displacement"]) == pytest.approx(2.0, abs=0.05)
        assert float(r["slope_velocity"]) == pytest.approx(2.0, abs=0.05)
    plate = rows[("rotating_plate_2d", "tlmpm · quadratic · mls")]
    assert float(plate["slope_displacement"]) == pytest.approx(2.0, abs=1e-9)
    pareto = _rows(report.parent / "pareto.csv")
    assert pareto and {r["quantity"] for r in pareto} == {"displacement", "velocity"}


def test_update_cost_and_speed(report):
    rows = _rows(report.parent / "update_cost.csv")
    reductions = [float(r["reduction"]) for r in rows if r["reduction"]]
    assert reductions and all(red == pytest.approx(4.0) for red in reductions)
    assert len(reductions) == 3  # one per resolution
    speed = _rows(report.parent / "speed.csv")
    cubic = [r for r in speed if r["label"] == "empm · cubic · mls"]
    assert float(cubic[0]["ms_per_step_vs_quadratic"]) == pytest.approx(3.0 / 2.0)
    fracture = _rows(report.parent / "fracture.csv")
    assert len(fracture) == 9  # completed jobs only


def test_empty_sweep(tmp_path):
    path = write_report(tmp_path)
    assert "No job found" in path.read_text()


def test_callback(tmp_path, capsys):
    sweep = tmp_path / "sweep"
    sweep.mkdir()
    ReportCallback().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}}))
    assert (sweep / "report.md").is_file()
    blocker = tmp_path / "file"
    blocker.write_text("")
    ReportCallback().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(blocker / "x")}}}))
    assert "warning: sweep report failed" in capsys.readouterr().err


@pytest.mark.slow
def test_cli(sweep, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pipelines.report", str(sweep)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str(sweep / "report.md")
    assert (sweep / "runs.csv").is_file()
    out = tmp_path / "cli"
    proc = subprocess.run([sys.executable, "-m", "pipelines.report", str(sweep), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert (out / "report.md").is_file()
    missing = subprocess.run([sys.executable, "-m", "pipelines.report", str(tmp_path / "nope")],
                             cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert missing.returncode == 2 and "no such directory" in missing.stderr


def test_run_settings_that_change_the_method_split_labels(tmp_path):
    """A sweep over run.dt is two methods, not one convergence line; run.force is not."""
    for i, (dt, force) in enumerate((("1e-4", "false"), ("2e-4", "true"))):
        _job(tmp_path, str(i), _metrics("empm", "quadratic", 16, config_hash=f"h{i}"),
             ["scheme=empm", f"run.dt={dt}", f"run.force={force}"])
    jobs, _ = load_jobs(tmp_path)
    assign_labels(jobs)
    assert sorted(j.label for j in jobs) == ["empm · quadratic · mls · run.dt=1e-4",
                                             "empm · quadratic · mls · run.dt=2e-4"]


def test_a_plain_sweep_sorts_by_value_and_leaves_out_what_it_lacks(tmp_path):
    """``-m material.E=5e4,1e5,2e5`` (directories named by the overrides, as
    Hydra names them): the per-job table orders E by value, not as text, the
    sections of other experiments are left out of report.md, named once at
    its end instead of one "Not available" section each, the scene's
    physical responses are plotted against E beside the costs, and the report says
    that the jobs ran at the same time (their 2 s wall-clock spans, ending
    when metrics.json was written, overlap); once they are 10 s apart, not."""
    sweep = tmp_path / "sweep"
    values = ("50000.0", "100000.0", "200000.0")  # as Hydra writes 5e4,1e5,2e5: as text, 100000.0 comes first
    for i, E in enumerate(values):
        responses = {"peak_compression": {"value": 0.3 / (i + 1), "unit": "-", "quantity": "height",
                                          "reduce": "drop", "body": "ball", "reached": True},
                     "rebound_height": {"value": (0.2, 0.25, 0.3)[i], "unit": "m", "quantity": "bottom",
                                        "reduce": "max_after_min", "body": "ball", "reached": i != 2}}
        _job(sweep, f"material.E={E}", _metrics("empm", "quadratic", 16, config_hash=f"E{i}", responses=responses,
                                                step_time_ms=1.0 + i, updates_per_1e4_steps=1e4),
             ["scheme=empm", f"material.E={E}"])
    text = write_report(sweep, tmp_path / "out").read_text()
    rows = _rows(tmp_path / "out" / "runs.csv")
    assert [r["dir"] for r in rows] == [f"material.E={E}" for E in values]
    # every per-job table orders E by value
    assert [r["label"].split("=")[-1] for r in _rows(tmp_path / "out" / "speed.csv")] == list(values)
    update_table = text.split("## Configuration-update cost", 1)[1].split("##", 1)[0]
    assert [update_table.index(f"E={E} |") for E in values] == sorted(update_table.index(f"E={E} |") for E in values)
    # what each response measures; a value the run ended before reaching is named; a constant is a sentence
    assert "*rebound height* [m]: the lowest particle's height" in text
    assert "Not reached: *rebound height* in job material.E=200000.0" in text and "Not reached: *peak" not in text
    assert "configuration updates 1e+04 per 10⁴ steps;" in text.split("The same in every job: ", 1)[1].split("\n")[0]
    # the scene's responses against E, by value, beside the costs
    response = [r for r in _rows(tmp_path / "out" / "response.csv") if r["parameter"] == "material.E"]
    rebound = [(float(r["value"]), float(r["response_value"])) for r in response if r["response"] == "rebound_height"]
    assert rebound == [(5e4, 0.2), (1e5, 0.25), (2e5, 0.3)]
    assert {r["response"] for r in response} >= {"peak_compression", "rebound_height", "step_time_ms"}
    assert "updates_per_1e4_steps" not in {r["response"] for r in response}
    assert "Not available" not in text
    tail = text.split("## Sections without data in this sweep", 1)[1]
    assert "Cantilever under a tip load" in tail and "Stability maps: the largest stable time step" in tail
    assert "3 of the 3 jobs ran while another did" in text
    for i, d in enumerate(sorted(sweep.iterdir())):
        os.utime(d / "metrics.json", (1e9 + 10 * i, 1e9 + 10 * i))
    assert "ran while another did" not in write_report(sweep, tmp_path / "again").read_text()
