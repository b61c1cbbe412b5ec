"""run.reference: the error a run measures against a finer run's final state
(pipelines.run.runner)."""

import json

import numpy as np
import pytest

from helpers import ROOT, run_cli


@pytest.mark.slow
def test_error_against_a_reference_run(tmp_path):
    """run.reference: the run measures E = sqrt(sum |phi - phi_ref|^2 / n_p)
    against a finer run's final state with the same particles (paper eq. 36)."""
    from pipelines.recording.recordings import read

    common = ["scene=rotating_plate_2d", "scene.particle_resolution=32", "run.steps=20", "run.dt=1e-4",
              "run.precision=float64", "log.every=0"]
    ref, coarse = tmp_path / "ref", tmp_path / "coarse"
    p = run_cli(common + ["scene.resolution=32", f"hydra.run.dir={ref}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    p = run_cli(common + ["scene.resolution=16", f"run.reference={ref}", f"hydra.run.dir={coarse}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    err = json.loads((coarse / "metrics.json").read_text())["error"]
    a, b = np.load(coarse / "final_state.npz"), np.load(ref / "final_state.npz")
    expected = np.sqrt(np.sum((a["x"] - b["x"]) ** 2) / len(a["x"]))
    assert err["solution"] == "reference" and err["displacement"] == pytest.approx(expected, rel=1e-12)
    assert 0 < err["displacement"] < 1e-3 and err["velocity"] > 0
    steps, values = read(coarse / "recording.rrd").scalars["error/velocity"]
    assert steps[-1] == 20 and values[-1] == pytest.approx(err["velocity"], rel=1e-12)
    # another particle set: no error, a reason
    other = tmp_path / "other"
    p = run_cli(common[:1] + common[2:] + ["scene.resolution=16", f"run.reference={ref}",
                                          f"hydra.run.dir={other}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    err = json.loads((other / "metrics.json").read_text())["error"]
    assert "displacement" not in err and "other particles" in err["problem"]
