"""Every scene of conf/scene/ at its smallest size, its initial particles
recorded (no step) and replayed as one frame: every body is drawn in its
colour and every collider appears."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from omegaconf import OmegaConf

import mpm
from helpers import CONF, compose_cfg
from pipelines.config.validate import resolve
from pipelines.recording import recordings
from pipelines.recording.display import render_frames
from pipelines.recording.colours import PALETTE
from pipelines.recording.rerun_sink import RerunSink
from pipelines.recording.sinks import RunMeta

SCENES = sorted(p.stem for p in (CONF / "scene").glob("*.yaml"))


def smallest(scene: str) -> list[str]:
    """The overrides of ``scene`` at its smallest declared size."""
    sizes = yaml.safe_load((CONF / "scene" / f"{scene}.yaml").read_text()).get("sizes") or {}
    size = min(sizes, key=lambda k: sizes[k].get("resolution", float("inf")), default=None)
    return [f"scene={scene}"] + ([f"scene.size={size}"] if size else [])


def record_initial(scene: str, path: Path) -> recordings.Recording:
    """The scene's initial particles through the run's sink, read back."""
    cfg = compose_cfg(smallest(scene))
    spec = resolve(cfg)
    s = spec.scene
    model, state = mpm.build(s, spec.kernel, "float32", "cpu", spec.seed)
    sink = RerunSink(path, threaded=False)
    sink.start(RunMeta(name=scene, dim=s.dim, domain=model.domain, wall_cells=s.wall_cells, dx=model.dx,
                       body_names=[b.name for b in s.bodies], particle_body=model.body.numpy(),
                       particle_radius=0.5 * s.particle_dx / max(b.ppc or s.ppc for b in s.bodies) ** (1 / s.dim),
                       properties={"config": {"yaml": OmegaConf.to_yaml(cfg, resolve=True)}},
                       colliders=list(s.colliders)))
    sink.particles(0, 0.0, state.x.numpy().copy(), None)
    sink.scalars(0, 0.0, {"mass": float(model.mass.numpy().sum())})
    sink.timings(0, 0.0, {"step_time_ms": 0.0})
    sink.close()
    return recordings.read(path)


def counts(rec, out: Path, view: str) -> np.ndarray:
    """Pixels of each body's colour in the frame (legend markers included)."""
    from PIL import Image

    img = np.asarray(Image.open(render_frames(rec, out, view=view)[0]).convert("RGB"), np.int32)
    return np.array([np.all(np.abs(img - c.astype(np.int32)) <= 30, axis=-1).sum() for c in PALETTE[:n_bodies(rec)]])


def n_bodies(rec) -> int:
    return int(rec.body.max()) + 1


def empty(rec, colliders: bool = True):
    """The recording without particles (the legend kept), and without
    collider geometry unless ``colliders``."""
    dim = rec.dim
    geo = {}
    for name, g in (rec.colliders or {}).items():
        if colliders:
            geo[name] = g
        else:
            geo[name] = [] if isinstance(g, list) else (g[0], np.zeros((0, 3), int))
    return dataclasses.replace(rec, positions=[np.zeros((0, dim))], colors=rec.colors[:0], colliders=geo)


@pytest.mark.parametrize("scene", SCENES)
def test_every_body_and_collider_of_every_scene_is_drawn(tmp_path, scene):
    rec = record_initial(scene, tmp_path / "recording.rrd")
    views = ["xy"] if rec.dim == 2 else ["xy", "xz", "zy"]
    legend_only = counts(empty(rec), tmp_path / "legend", "xy")
    seen = np.zeros(n_bodies(rec), bool)
    for view in views:  # in 3D a body hidden behind another in one projection shows in another
        seen |= counts(rec, tmp_path / view, view) - legend_only >= 20
        if seen.all():
            break
    for b in np.flatnonzero(~seen):  # inside another body in every projection (a hydrant's water): drawn alone
        alone = rec.body == b
        only = dataclasses.replace(rec, positions=[rec.positions[0][alone]], colors=rec.colors[alone])
        seen[b] = (counts(only, tmp_path / f"alone{b}", views[0]) - legend_only)[b] >= 20
    assert seen.all(), f"{scene}: bodies not drawn: {np.flatnonzero(~seen).tolist()}"
    if rec.colliders:
        from PIL import Image

        with_them = np.asarray(Image.open(render_frames(empty(rec), tmp_path / "c1", view="xy")[0]), np.int32)
        without = np.asarray(Image.open(render_frames(empty(rec, False), tmp_path / "c0", view="xy")[0]), np.int32)
        assert np.any(with_them != without, axis=-1).sum() > 200, f"{scene}: colliders not drawn"
