"""The papers' scenes in the config: named sizes, colliders and meshes
(their runs: tests/mpm/test_paper_scene_runs.py)."""

import numpy as np
import pytest

from helpers import PAPER_SCENES, compose_cfg, group_options, spec_for
from pipelines.run.provenance import config_hash
from pipelines.run.runner import execute
from pipelines.config.validate import ConfigError

SIZED = [s for s in group_options("scene") if compose_cfg([f"scene={s}"]).scene.sizes]


@pytest.mark.slow
def test_every_paper_scene_names_a_default_and_a_paper_size():
    assert PAPER_SCENES <= set(SIZED)
    for s in SIZED:
        sizes = compose_cfg([f"scene={s}"]).scene.sizes
        assert {"default", "paper"} <= set(sizes), s
        assert spec_for([f"scene={s}"]).scene.resolution == sizes.default.resolution
        assert spec_for([f"scene={s}", "scene.size=paper"]).scene.resolution == sizes.paper.resolution


def test_size_errors_name_the_accepted_sizes():
    with pytest.raises(ConfigError, match=r"scene.size: 'huge' unknown .*accepted: default, paper"):
        spec_for(["scene=water_bunny", "scene.size=huge"])
    with pytest.raises(ConfigError, match=r"scene.size: 'paper' unknown .*accepted: default$"):
        spec_for(["scene=vortex_2d", "scene.size=paper"])
    # an explicit resolution wins over the size's
    assert spec_for(["scene=water_bunny", "scene.size=paper", "scene.resolution=40"]).scene.resolution == 40


def test_collider_config_errors_are_one_line():
    base = ["scene=water_bunny"]
    with pytest.raises(ConfigError, match=r"scene.colliders\[0\].type: 'cone' unknown; accepted: half_space"):
        spec_for(base + ["scene.colliders.0.type=cone"])
    with pytest.raises(ConfigError, match=r"scene.colliders\[0\].boundary: 'glue' unknown; accepted: sticky, slip, "
                                          r"separate"):
        spec_for(base + ["scene.colliders.0.boundary=glue"])
    with pytest.raises(ConfigError, match=r"scene.colliders\[0\].friction: -1.0 out of range"):
        spec_for(base + ["scene.colliders.0.friction=-1"])
    with pytest.raises(ConfigError, match=r"scene.colliders\[0\].half_size: not used by a sphere collider"):
        spec_for(base + ["scene.colliders.0.half_size=[1,1,1]"])
    with pytest.raises(ConfigError, match=r"scene.colliders\[0\].radius: missing for a sphere collider"):
        spec_for(base + ["scene.colliders.0.radius=null"])
    with pytest.raises(ConfigError, match=r"scene.bodies\[0\].shape.rotation: 'sideways'"):
        spec_for(base + ["scene.bodies.0.shape.rotation=sideways"])


def test_colliders_from_the_config():
    spec = spec_for(["scene=viscous_cup"])
    cup, = spec.scene.colliders
    assert (cup.type, cup.boundary, cup.friction, cup.depth, cup.thickness) == ("cup", "separate", 0.2, 0.35, 0.06)
    spec = spec_for(["scene=water_bunny", "scene.colliders.0.velocity=[0.0,1.0,0.0]",
                     "scene.colliders.0.end=0.5"])
    c = spec.scene.colliders[0]
    assert c.inside and c.velocity == (0.0, 1.0, 0.0) and c.end == 0.5
    assert np.allclose(c.offset(2.0), [0.0, 0.5, 0.0])


def test_random_orientations_follow_the_seed():
    def rotations(seed):
        spec = spec_for(["scene=snow_bunnies", f"seed={seed}"])
        return [b.shape.R for b in spec.scene.bodies]

    a, b, c = rotations(0), rotations(0), rotations(1)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.allclose(a[0], a[1])  # each copy its own orientation
    assert not np.allclose(a[0], c[0])
    for R in a:
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("fmt", ["obj", "stl", "ply"])
def test_mesh_files_by_path(fmt, tmp_path):
    """A box mesh written by trimesh fills with the box's volume; the config
    hash follows the file's contents."""
    import trimesh

    path = tmp_path / f"block.{fmt}"
    trimesh.creation.box(extents=(2.0, 1.0, 1.0)).export(path)
    over = ["scene=cube_drop_3d", "scene.bodies.0.shape.type=mesh", f"scene.bodies.0.shape.mesh='{path}'",
            "scene.bodies.0.shape.half_size=null", "scene.bodies.0.shape.center=[0.5,0.5,0.5]",
            "scene.bodies.0.shape.size=0.5", "scene.resolution=32", "run.steps=1"]
    spec = spec_for(over)
    metrics = execute(spec, tmp_path / "run")
    assert metrics["status"] == "completed"
    # 0.5 x 0.25 x 0.25 m^3 (cell-aligned) at 8 particles per (1/32 m)^3 cell
    assert metrics["particles"] == pytest.approx(0.5 * 0.25 * 0.25 * 8 * 32**3, rel=0.01)
    assert list(spec.meshes) == [str(path)]
    cfg = {"scene": {"mesh": str(path)}}
    before = config_hash(cfg, "code", files=spec.meshes)
    trimesh.creation.box(extents=(2.0, 1.0, 1.5)).export(path)
    from mpm.meshes import file_digest
    file_digest.cache_clear()
    assert config_hash(cfg, "code", files=spec_for(over).meshes) != before


def test_shipped_meshes_and_unknown_files():
    spec = spec_for(["scene=falling_bodies"])
    assert set(spec.meshes) == {"warp:bunny", "warp:bear"}
    with pytest.raises(ConfigError, match=r"scene.bodies\[0\].shape.mesh: 'warp:dragon': no such file; "
                                          r"accepted: .*warp:bunny, warp:bear"):
        spec_for(["scene=falling_bodies", "scene.bodies.0.shape.mesh=warp:dragon"])
