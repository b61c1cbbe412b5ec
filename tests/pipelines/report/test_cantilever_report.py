"""The cantilever section (pipelines.report.sections.cantilever) on a real
run of conf/scene/cantilever_2d.yaml, and the load's record in metrics.json
and the recording (pipelines.run.load_track)."""

import csv
import json

import numpy as np
import pytest

from helpers import ROOT, run_cli
from mpm.beams import cantilever_tip
from pipelines.recording.recordings import read
from pipelines.report import write_report


def test_cantilever_against_beam_theory(tmp_path):
    """EMPM, quadratic, MLS, 4 cells across the beam, float64: the static
    tip deflection (the load point's time-mean over the hold) is within 2 %
    of 2D elasticity (measured +0.82 %; RESULTS.md, +experiment=cantilever);
    metrics.json records the resolved traction (8 particles on the 0.1 m
    face, P = 4 N/m) and the recording the load and the load point's
    displacement per step, the force ramped to P by 2.5 s."""
    sweep = tmp_path / "sweep"
    p = run_cli(["scene=cantilever_2d", "run.precision=float64", "log.fps=4", "log.progress=false",
                 f"hydra.run.dir={sweep / 'empm'}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    metrics = json.loads((sweep / "empm" / "metrics.json").read_text())
    load, = metrics["loads"]
    assert load["kind"] == "traction" and load["particles"] == 8
    assert load["area"] == pytest.approx(0.1, rel=1e-12)
    assert load["total_force"] == pytest.approx([0.0, -4.0], rel=1e-12)
    assert load["hold_start"] == pytest.approx(2.5) and load["hold_time"] == pytest.approx(2.5, rel=1e-3)
    ref = cantilever_tip(4.0, 0.8, 0.1, 1.0e6, 0.0)["elasticity"]
    assert -load["displacement_hold_mean"][1] == pytest.approx(ref, rel=0.02)
    rec = read(sweep / "empm" / "recording.rrd", particles=False)
    steps, force = rec.scalars["load/tip/force_y"]
    times = dict(zip(*rec.clock))
    ramped = [f for s, f in zip(steps, force) if times.get(s, 0.0) >= 2.5]
    assert ramped and np.allclose(ramped, -4.0, rtol=1e-12)
    report = write_report(sweep, tmp_path / "out")
    assert "## Cantilever under a tip load" in report.read_text()
    with open(report.parent / "cantilever.csv", newline="") as f:
        row, = list(csv.DictReader(f))
    assert row["cells across"] == "4" and abs(float(row["vs 2D elasticity [%]"])) < 2.0
