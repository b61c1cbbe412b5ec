"""The papers' scenes run: every scene a few steps with every scheme, and the
bowl that holds water."""

import json

import pytest

from helpers import PAPER_SCENES, spec_for
from pipelines.run.runner import execute


SLOW_SCENES = {("hydrant", "tlmpm")}  # (scene, scheme) over about 8 s on two cores


@pytest.mark.parametrize("scene, scheme", [
    pytest.param(scene, scheme, id=f"{scene}-{scheme}",
                 marks=[pytest.mark.slow] if (scene, scheme) in SLOW_SCENES else [])
    for scheme in ("empm", "tlmpm", "aulmpm") for scene in sorted(PAPER_SCENES)])
def test_paper_scene_runs_a_few_steps(scene, scheme, tmp_path):
    """At a tiny size: 20 cells along x (80 for the 2D dam break's 0.4 m
    domain), one wall cell so that every body fits."""
    res = 80 if scene == "dam_break_2d" else 20
    spec = spec_for([f"scene={scene}", f"scheme={scheme}", f"scene.resolution={res}", "scene.wall_cells=1",
                     "run.steps=3", "log.every=3"])
    metrics = execute(spec, tmp_path)
    assert metrics["status"] == "completed", metrics["reason"]
    assert metrics["steps"] == 3
    if spec.scene.colliders:
        assert set(metrics["inside_colliders"]) == {c.name for c in spec.scene.colliders}


@pytest.mark.slow
def test_bowl_holds_the_water_in_aulmpm(tmp_path):
    """Fluid-structure interaction (A-ULMPM paper, Fig. 11) at a small size:
    after the splash no water lies below the rim outside the bowl."""
    spec = spec_for(["scene=bowl_fsi", "scheme=aulmpm", "scene.resolution=32", "scene.wall_cells=2",
                     "run.duration=1.0", "log.every=0"])
    metrics = execute(spec, tmp_path)
    assert metrics["status"] == "completed", metrics["reason"]
    assert metrics["spilled"] == {"water/bowl": 0.0}
    assert metrics["fragments"]["bowl"] == 1
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["spilled"] == {"water/bowl": 0.0}
