"""The cantilever section (pipelines.report.sections.cantilever) with a
completed job whose grid spacing is unknown (no dx in its metrics.json, no
domain in its config): its row has no cells across and no order, and the
section no longer fails dividing by the missing spacing."""

import csv

from pipelines.report.jobs import Job
from pipelines.report.sections.cantilever import SCENE, section_cantilever


def _job(tmp_path, name: str, dx: float | None) -> Job:
    """A completed cantilever job: the beam of conf/scene/cantilever_2d.yaml
    (L = 0.8 m, H = 0.1 m, E = 1 MPa, nu = 0, P = 4 N/m), its tip 1 mm down."""
    metrics = {"status": "completed", "scene": SCENE, "scheme": "empm", "kernel": "quadratic",
               "transfer": "mls", "loads": [{"total_force": [0.0, -4.0],
                                             "displacement_hold_mean": [0.0, -1.0e-3]}]}
    if dx is not None:
        metrics["dx"] = dx
    config = {"scene": {"bodies": [{"shape": {"center": [0.5, 0.5], "half_size": [0.5, 0.05]},
                                    "material": {"E": 1.0e6, "nu": 0.0}}],
                        "regions": [{"select": {"center": [0.15, 0.5], "half_size": [0.05, 0.1]}}]}}
    return Job(path=tmp_path / name, rel=name, metrics=metrics, config=config)


def test_a_job_without_a_grid_spacing_has_no_order(tmp_path):
    jobs = [_job(tmp_path, "coarse", 0.025), _job(tmp_path, "unknown", None)]
    lines = section_cantilever(jobs, tmp_path)
    assert any(line.startswith("## Cantilever under a tip load") for line in lines)
    with open(tmp_path / "cantilever.csv", newline="") as f:
        coarse, unknown = list(csv.DictReader(f))
    assert coarse["cells across"] == "4" and coarse["order"] == ""
    assert unknown["cells across"] == "" and unknown["order"] == ""
    assert unknown["deflection [mm]"] == coarse["deflection [mm]"]
