"""Every scene x material in conf/ composes and validates; every scene runs
with its material, every material runs in a 2D and a 3D scene."""

import json

import pytest

from helpers import compose_cfg, group_options, spec_for
from pipelines.run.runner import execute

SCENES = group_options("scene")
MATERIALS = group_options("material")


def test_groups_found():
    assert {"elastic_ball_2d", "droplet_2d", "rotating_plate_2d", "cube_drop_3d"} <= set(SCENES)
    assert {"fixed_corotated", "neo_hookean", "fluid"} <= set(MATERIALS)


@pytest.mark.parametrize("material", MATERIALS)
@pytest.mark.parametrize("scene", SCENES)
def test_scene_material_composes(scene, material):
    spec = spec_for([f"scene={scene}", f"material={material}"])
    # the group's material goes to every body that does not bring its own
    cfg_bodies = compose_cfg([f"scene={scene}"]).scene.bodies
    for b, cb in zip(spec.scene.bodies, cfg_bodies):
        if cb.material is None:
            assert b.material.name == material
        else:
            assert b.material.name == cb.material.model


@pytest.mark.parametrize("overrides", [[f"scene={s}"] for s in SCENES]
                         + [[f"scene={s}", f"material={m}"] for m in MATERIALS
                            for s in ("elastic_ball_2d", "cube_drop_3d")],
                         ids=lambda o: ",".join(x.split("=")[1] for x in o))
def test_scene_material_runs(overrides, tmp_path):
    spec = spec_for(overrides + ["run.steps=4", "log.every=2"])
    metrics = execute(spec, tmp_path)
    assert metrics["status"] == "completed", metrics["reason"]
    assert metrics["steps"] == 4 and metrics["particles"] > 100
    saved = json.loads((tmp_path / "metrics.json").read_text())
    for key in ("status", "reason", "steps", "sim_time", "particles", "grid_nodes", "dt",
                "wall_time_s", "compile_time_s", "step_time_ms", "log_time_ms", "mass_drift",
                "momentum_drift", "angular_momentum_drift", "energy_initial", "energy_final"):
        assert key in saved, key
    assert (tmp_path / "recording.rrd").stat().st_size > 0


def test_material_group_applies_unless_the_scene_assigns():
    spec = spec_for(["scene=elastic_ball_2d", "material=neo_hookean", "material.E=3e4"])
    assert spec.scene.bodies[0].material.name == "neo_hookean"
    assert spec.scene.bodies[0].material.E == 3e4
    # the droplet's default material is the fluid, the command line still wins
    assert spec_for(["scene=droplet_2d"]).scene.bodies[0].material.name == "fluid"
    assert spec_for(["scene=droplet_2d", "material=neo_hookean"]).scene.bodies[0].material.name \
        == "neo_hookean"
    # a body with its own material keeps it
    spec = spec_for(["scene=elastic_ball_2d", "material=neo_hookean",
                     "scene.bodies.0.material={model: fluid, K: 5.0e4}"])
    assert spec.scene.bodies[0].material.name == "fluid" and spec.scene.bodies[0].material.K == 5e4


def test_run_length_and_logging_defaults():
    spec = spec_for(["scene=cube_drop_3d"])
    assert spec.end == (None, 1.0) and spec.log.every is None and spec.log.fps == 60  # frames in simulated time
    spec = spec_for(["scene=elastic_ball_2d", "run.steps=7", "log.every=0"])
    assert spec.end == (7, None) and spec.log.every == 0
