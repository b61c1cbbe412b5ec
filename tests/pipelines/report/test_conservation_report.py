"""The conservation section: the drift plot keeps the runs on which nothing
acts from outside (the recording holds no wall impulse), and says which it
left out and why."""

import json
import shutil

import pytest
import yaml
from omegaconf import OmegaConf

from helpers import compose_cfg
from pipelines.config.validate import resolve
from pipelines.report import write_report
from pipelines.report.sections.conservation import external_forces
from pipelines.run.runner import execute


@pytest.mark.parametrize("scene, expected", [
    ({"gravity": [0.0, 0.0], "walls": ["slip"] * 4}, []),
    ({"gravity": [0.0, -9.81]}, ["gravity"]),
    ({"gravity": [0.0, 0.0], "colliders": [{"type": "sphere"}], "regions": [{"type": "anchor"}],
      "loads": [{"type": "point"}]}, ["colliders", "kinematic regions", "loads"]),
    ({"gravity": [0, 0], "solution": {"type": "vortex"}}, ["body force"]),
    ({"gravity": [0, 0], "solution": {"type": "vibrating_bar"}}, []),  # an initial velocity, no force
    ({"gravity": [0, 0], "walls": ["slip", "open", "slip", "slip"]}, ["open walls"]),
])
def test_external_forces_are_read_from_the_config(scene, expected):
    assert external_forces({"scene": scene}) == expected
    assert external_forces(None) == ["unknown config"]


def _job(sweep, name, overrides):
    """A finished tiny run laid out as a sweep's job (its composed config in .hydra/)."""
    d = sweep / name
    cfg = compose_cfg(overrides)
    assert execute(resolve(cfg), d, OmegaConf.to_yaml(cfg), overrides)["status"] == "completed"
    (d / ".hydra").mkdir()
    (d / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    (d / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
    return d


def test_the_drift_plot_leaves_out_runs_with_external_forces(tmp_path):
    """A free rotating plate is plotted; the same recording under gravity is
    listed as left out; with only forced runs there is no plot."""
    sweep = tmp_path / "sweep"
    tiny = ["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=3", "log.every=0"]
    free = _job(sweep, "free", tiny + ["scheme=empm"])
    forced = sweep / "forced"
    shutil.copytree(free, forced)
    config = yaml.safe_load((forced / ".hydra" / "config.yaml").read_text())
    config["scene"]["gravity"] = [0.0, -9.81]
    (forced / ".hydra" / "config.yaml").write_text(yaml.safe_dump(config))
    metrics = json.loads((forced / "metrics.json").read_text())
    (forced / "metrics.json").write_text(json.dumps({**metrics, "config_hash": "forced"}))
    report = write_report(sweep).read_text()
    section = report.split("## Conservation", 1)[1].split("\n## ", 1)[0]
    assert "read from 1 recording(s)" in section and "conservation.png" in section
    assert "No drift plotted for the runs with external forces" in section and "forced (gravity)" in section
    assert "| none |" in section and "| gravity |" in section  # the table's external column
    assert (sweep / "conservation.png").stat().st_size > 0

    shutil.rmtree(free)
    (sweep / "conservation.png").unlink()
    section = write_report(sweep).read_text().split("## Conservation", 1)[1].split("\n## ", 1)[0]
    assert not (sweep / "conservation.png").exists() and "conservation.png" not in section
    assert "forced (gravity)" in section
