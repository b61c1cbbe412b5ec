"""The papers' scenes: their particles fill their shapes' volumes, their
first step is the same in every scheme, every scheme runs them a few steps
with no particle inside a collider, and the bowl holds the water."""

import json
import math

import numpy as np
import pytest

import mpm
from helpers import PAPER_SCENES, spec_for
from pipelines.run.runner import execute
from shapes import volume_and_area

EPS32 = np.finfo(np.float32).eps


def assert_fills_its_shapes(scene: mpm.Scene, volumes: dict[str, float]):
    """Per body, the particles' total volume n dx_p^d / ppc against the
    shape's volume (tests/shapes.py): a lattice of spacing h = dx_p /
    ppc^(1/d) that counts the points inside a shape misses at most the
    shell of half a cell's diagonal around its surface, |error| <=
    sqrt(d) / 2 A h (A the surface area; measured up to 0.4 of it, for
    boxes whose faces lie between lattice planes, else below 0.17)."""
    for b in scene.bodies:
        ppc = b.ppc or scene.ppc
        h = scene.particle_dx / round(ppc ** (1.0 / scene.dim))
        V, A, quadrature = volume_and_area(b.shape, scene.dim, h / 4)
        bound = 0.5 * math.sqrt(scene.dim) * A * h + quadrature
        assert abs(volumes[b.name] - V) <= bound, (b.name, volumes[b.name], V, bound)


@pytest.mark.parametrize("scene", sorted(PAPER_SCENES))
def test_paper_scene_fills_its_shapes_at_its_default_size(scene):
    """The particles sampled at the scene's default size (the size its file
    documents) fill each body's shape (assert_fills_its_shapes)."""
    s = spec_for([f"scene={scene}"]).scene
    rng = np.random.default_rng(0)
    volumes = {}
    for b in s.bodies:
        ppc = b.ppc or s.ppc
        x = mpm.sampling.sample_shape(b.shape, s.dim, s.particle_dx, ppc, s.jitter, rng, s.lattice_offset)
        volumes[b.name] = len(x) * s.particle_dx**s.dim / ppc
    assert_fills_its_shapes(s, volumes)


COLLIDER_SCENES = ["snow_bunnies", "viscous_cup", "water_bunny"]  # the paper scenes with colliders


@pytest.mark.parametrize("scene", sorted(PAPER_SCENES))
def test_paper_scene_steps_alike_in_every_scheme(scene, device):
    """At a tiny size (20 cells along x, 80 for the 2D dam break's 0.4 m
    domain, one wall cell so that every body fits; float32), the model's
    particle volumes fill the shapes (assert_fills_its_shapes); EMPM, TLMPM
    and A-ULMPM start from the same reference configuration, so their first
    step at one dt is the same arithmetic: positions and velocities agree to
    a few ulps (4 eps32 of max|x|, 64 eps32 of max|v|: the nodes' sums may
    add in another order; measured: equal), det F to 8 eps32; every scheme
    then takes two more steps with no failure, the particle masses
    untouched, and no particle inside a collider."""
    res = 80 if scene == "dam_break_2d" else 20
    spec = spec_for([f"scene={scene}", f"scene.resolution={res}", "scene.wall_cells=1"])
    assert bool(spec.scene.colliders) == (scene in COLLIDER_SCENES)
    schemes = {"empm": mpm.EMPM(), "tlmpm": mpm.TLMPM(), "aulmpm": spec_for([f"scene={scene}", "scheme=aulmpm"]).scheme}
    first, dt = {}, None
    for name, scheme in schemes.items():
        model, state = mpm.build(spec.scene, spec.kernel, "float32", device, spec.seed)
        if name == "empm":
            volume, body = model.volume.numpy().astype(np.float64), model.body.numpy()
            assert_fills_its_shapes(spec.scene, {b.name: volume[body == i].sum()
                                                 for i, b in enumerate(spec.scene.bodies)})
        solver = mpm.Solver(model, scheme, mpm.SolverOptions(transfer=spec.transfer))
        solver.prepare(state)
        mass = model.mass.numpy().copy()
        if dt is None:
            dt = solver.timestep.stable_dt(0.4, None, float(np.linalg.norm(state.v.numpy(), axis=1).max()))
        assert not solver.conditions.inside_colliders(state.x, 0.0).any()
        report = solver.advance(state, dt)
        assert report.reason is None, (name, report.reason)
        s = state.numpy()
        first[name] = (s["x"], s["v"], np.linalg.det(s["Fsn"] @ s["F0s"]))
        for k in range(2):
            report = solver.advance(state, dt)
            assert report.reason is None, (name, report.reason)
        np.testing.assert_array_equal(model.mass.numpy(), mass)
        inside = solver.conditions.inside_colliders(state.x, 3 * dt)
        assert len(inside) == len(spec.scene.colliders) and not inside.any(), (name, inside)
    x, v, J = first["empm"]
    for name in ("tlmpm", "aulmpm"):
        np.testing.assert_allclose(first[name][0], x, rtol=0, atol=4 * EPS32 * np.abs(x).max(), err_msg=name)
        np.testing.assert_allclose(first[name][1], v, rtol=0, atol=64 * EPS32 * np.abs(v).max(), err_msg=name)
        np.testing.assert_allclose(first[name][2], J, rtol=0, atol=8 * EPS32, err_msg=name)
    assert np.abs(v).max() > 0  # something moved


@pytest.mark.parametrize("scene", COLLIDER_SCENES)
def test_paper_scene_with_colliders_reports_them(scene, tmp_path):
    """Through the runner (A-ULMPM, three steps at the tiny size): metrics.json
    names every collider with the particles found inside it, none."""
    spec = spec_for([f"scene={scene}", "scheme=aulmpm", "scene.resolution=20", "scene.wall_cells=1",
                     "run.steps=3", "log.every=3"])
    metrics = execute(spec, tmp_path)
    assert metrics["status"] == "completed", metrics["reason"]
    assert metrics["steps"] == 3 and metrics["mass_drift"] == 0.0
    assert metrics["inside_colliders"] == {c.name: {"final": 0, "max": 0} for c in spec.scene.colliders}


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
