"""Every scene in conf/ resolves to the objects its file describes, with
the material group reaching exactly the bodies that bring no material of
their own; every scene runs as configured; every scene's bodies, and every
material in 2D and 3D, conserve mass and momentum in a closed box."""

import dataclasses
import json

import numpy as np
import pytest
from omegaconf import OmegaConf

import mpm
from helpers import CONF, group_options, spec_for
from mpm.meshes import MeshShape
from pipelines.config.schema import SceneConfig
from pipelines.run.runner import execute

SCENES = group_options("scene")
MATERIALS = group_options("material")
EPS32 = np.finfo(np.float32).eps


def test_groups_found():
    assert {"elastic_ball_2d", "droplet_2d", "rotating_plate_2d", "cube_drop_3d"} <= set(SCENES)
    assert {"fixed_corotated", "neo_hookean", "fluid"} <= set(MATERIALS)
    assert set(MATERIALS) == set(mpm.MATERIALS)


# ---------------------------------------------------------------- the files, read as they are

def _merge(base: dict, top: dict) -> dict:
    """Hydra's merge of two mappings: mappings recursively, anything else replaced."""
    out = dict(base)
    for k, v in top.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def read_yaml(path) -> dict:
    """A config file as plain data (OmegaConf's YAML loader, as Hydra reads it:
    1.0e5 is a number), nothing composed or interpolated."""
    return OmegaConf.to_container(OmegaConf.load(path), resolve=False)


def _defaults(d: dict) -> list:
    return d.get("defaults") or []


def scene_file(name: str) -> dict:
    """conf/scene/<name>.yaml with the scene files its defaults list names merged under it."""
    d = read_yaml(CONF / "scene" / f"{name}.yaml")
    base = {}
    for entry in _defaults(d):
        if isinstance(entry, str) and entry not in ("_self_", "scene_schema"):
            base = _merge(base, scene_file(entry))
    return _merge(base, {k: v for k, v in d.items() if k != "defaults"})


def scene_default_material(name: str) -> str:
    """The material group a scene composes with: its own override, else conf/config.yaml's."""
    for entry in _defaults(read_yaml(CONF / "scene" / f"{name}.yaml")):
        if isinstance(entry, dict) and "override /material@_global_.material" in entry:
            return entry["override /material@_global_.material"]
        if isinstance(entry, str) and entry not in ("_self_", "scene_schema"):
            return scene_default_material(entry)
    config = read_yaml(CONF / "config.yaml")
    return next(e["material"] for e in config["defaults"] if isinstance(e, dict) and "material" in e)


def material_file(name: str) -> dict:
    """The material group's values: the model's own defaults (the group is
    defined in code: mpm.MATERIALS, pipelines.config.physics)."""
    cls = mpm.MATERIALS[name]
    return {f.name: getattr(cls(), f.name) for f in dataclasses.fields(cls) if f.name != "model"}


def assert_material(material, values: dict, where: str):
    """``material`` is the class of ``values["model"]`` with every value given."""
    assert type(material) is mpm.MATERIALS[values["model"]], where
    for k, v in values.items():
        assert getattr(material, k) == v, f"{where}: {k} = {getattr(material, k)!r}, the file says {v!r}"


def assert_shape(shape, d: dict, dim: int, where: str):
    """``shape`` is the object the shape mapping ``d`` describes."""
    if d.get("rotation") is not None:
        assert isinstance(shape, mpm.scene.Rotated), where
        R = shape.R
        assert np.allclose(R @ R.T, np.eye(dim), rtol=0, atol=8 * np.finfo(float).eps), where
        if d["rotation"] != "random":
            np.testing.assert_array_equal(R, mpm.scene.rotation_matrix(d["rotation"], dim), err_msg=where)
        shape = shape.shape
    kind = d["type"]
    cls = {"box": mpm.Box, "sphere": mpm.Sphere, "cylinder": mpm.Cylinder, "mesh": MeshShape,
           "bowl": mpm.scene.Bowl, "compound": mpm.Compound}[kind]
    assert type(shape) is cls, f"{where}: {type(shape).__name__}, the file says {kind}"
    if kind == "compound":
        assert len(shape.parts) == len(d["parts"]), where
        for i, (part, pd) in enumerate(zip(shape.parts, d["parts"])):
            assert_shape(part, pd, dim, f"{where}.parts[{i}]")
        return
    assert tuple(shape.center) == tuple(d["center"]), where
    expected = {"box": {"half_size": tuple(d.get("half_size") or ())},
                "sphere": {"radius": d.get("radius"), "inner_radius": d.get("inner_radius") or 0.0},
                "cylinder": {"radius": d.get("radius"), "half_height": d.get("half_height"),
                             "axis": 1 if d.get("axis") is None else d["axis"],
                             "inner_radius": d.get("inner_radius") or 0.0},
                "mesh": {"source": d.get("mesh"), "size": d.get("size"),
                         "up": 1 if d.get("axis") is None else d["axis"]},
                "bowl": {"radius": d.get("radius"), "thickness": d.get("thickness"), "rim": d.get("rim"),
                         "axis": 1 if d.get("axis") is None else d["axis"]}}[kind]
    for k, v in expected.items():
        got = getattr(shape, k)
        assert (tuple(got) if isinstance(got, (tuple, list)) else got) == v, f"{where}.{k}: {got!r} != {v!r}"


def _sized(f: dict, key: str, default):
    """A scene value that the default size may set (``sizes.default``), else the file's, else the schema's."""
    sized = (f.get("sizes") or {}).get("default") or {}
    if key in sized:
        return sized[key]
    value = f.get(key, default)
    return default if isinstance(value, str) and value.startswith("${") else value


def _by_size(f: dict, values) -> tuple:
    """A list of the file's whose entries may name a value of the default
    size, "${scene.sizes.${scene.size}.<key>}" (an incline's tilted gravity),
    with those entries read from ``sizes.default``."""
    sized = (f.get("sizes") or {}).get("default") or {}
    prefix = "${scene.sizes.${scene.size}."
    return tuple(sized[v[len(prefix):-1]] if isinstance(v, str) and v.startswith(prefix) else v for v in values)


def _other_material(default: str) -> str:
    return "viscous" if default != "viscous" else "sand"


@pytest.mark.parametrize("scene", SCENES)
def test_scene_resolves_to_its_file(scene):
    """The resolved scene is what conf/scene/<scene>.yaml says, read here as
    plain YAML: dimension, domain, resolution and wall band of the default
    size, walls per face, gravity, particles per cell, and per body its name,
    shape (kind, centre, sizes, rotation), velocity and material - its own
    mapping's values, else every value of the material group it composes
    with (its model's defaults). With another material group (one case per scene:
    the group's values are checked once per material in
    test_material_group_reaches_every_body_without_its_own), the bodies that
    bring their own material keep it and the others take the group's."""
    f = scene_file(scene)
    schema = SceneConfig()
    spec = spec_for([f"scene={scene}"])
    s = spec.scene
    dim = f.get("dim", schema.dim)
    assert spec.scene_name == f["name"] == scene
    assert s.dim == dim and s.domain == tuple(f["domain"])
    assert s.resolution == _sized(f, "resolution", schema.resolution)
    assert s.wall_cells == _sized(f, "wall_cells", schema.wall_cells)
    assert s.ppc == _sized(f, "ppc", schema.ppc)
    walls = f.get("walls", schema.walls)
    assert s.walls == (tuple([walls] * 2 * dim) if isinstance(walls, str) else tuple(walls))
    assert s.gravity == _by_size(f, f["gravity"]) and s.contact == f.get("contact", schema.contact)
    assert s.dx == s.domain[0] / s.resolution
    assert [c.type for c in s.colliders] == [c["type"] for c in f.get("colliders") or []]
    assert [c.name for c in s.colliders] == [c.get("name", "") for c in f.get("colliders") or []]
    assert len(s.regions) == len(f.get("regions") or [])
    assert [b.name for b in s.bodies] == [b["name"] for b in f["bodies"]]
    group = scene_default_material(scene)
    for i, (b, fb) in enumerate(zip(s.bodies, f["bodies"])):
        where = f"{scene}.bodies[{i}]"
        assert_shape(b.shape, fb["shape"], dim, f"{where}.shape")
        velocity = fb.get("velocity")
        assert (b.velocity is None and velocity is None) or tuple(b.velocity) == _by_size(f, velocity), where
        assert_material(b.material, fb.get("material") or {"model": group, **material_file(group)}, where)
    own = [fb.get("material") is not None for fb in f["bodies"]]
    assert spec.material_used == (not all(own))

    other = _other_material(group)
    swapped = spec_for([f"scene={scene}", f"material={other}"])
    for i, (b, b0, fb) in enumerate(zip(swapped.scene.bodies, s.bodies, f["bodies"])):
        if fb.get("material") is not None:
            assert b.material == b0.material, f"{scene}.bodies[{i}] lost its own material"
        else:
            assert_material(b.material, {"model": other, **material_file(other)}, f"{scene}.bodies[{i}]")


# scenes whose bodies take the material group: a 2D one, one of four 3D bodies whose
# default group is not the config's, one that overrides the group to the fluid
GROUP_SCENES = ("elastic_ball_2d", "viscous_cup", "water_bunny")


@pytest.mark.parametrize("material", MATERIALS)
def test_material_group_reaches_every_body_without_its_own(material):
    """material=<m> gives every body of the scenes that take the group an
    instance of m with every default value of its model, whatever group
    the scene itself composes with; an override of one of its values reaches
    all of them."""
    values = {"model": material, **material_file(material)}
    assert set(values) <= {f.name for f in dataclasses.fields(mpm.MATERIALS[material])}
    for scene in GROUP_SCENES:
        spec = spec_for([f"scene={scene}", f"material={material}"])
        assert spec.material_used
        for i, b in enumerate(spec.scene.bodies):
            assert_material(b.material, values, f"{scene}.bodies[{i}]")
    spec = spec_for(["scene=viscous_cup", f"material={material}", "material.rho=1234.5"])
    assert [b.material.rho for b in spec.scene.bodies] == [1234.5] * len(spec.scene.bodies)


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


# ---------------------------------------------------------------- runs

def closed_box(spec, velocities: bool = True) -> mpm.Scene:
    """The scene's bodies alone: open walls, no gravity, colliders, rigid
    bodies, joints, regions or closed-form solution (its body force), so that nothing outside the
    bodies acts; each body thrown towards the domain's centre (plus a sideways
    part of its own) and spinning, so that they move, turn and, where they
    touch, push each other."""
    s = spec.scene
    d = s.dim
    mid = np.asarray(s.domain) / 2
    bodies = []
    for i, b in enumerate(s.bodies):
        lo, hi = (np.asarray(x, float) for x in b.shape.bounds())
        u = mid - 0.5 * (lo + hi)
        u = u / max(np.linalg.norm(u), 1e-9) + 0.3 * np.roll(np.eye(d)[0], i)
        bodies.append(dataclasses.replace(b, velocity=tuple(u) if velocities else b.velocity,
                                          angular_velocity=(2.0 if d == 2 else (1.0, 2.0, -1.0)) if velocities
                                          else b.angular_velocity))
    return dataclasses.replace(s, bodies=bodies, walls=("open",) * (2 * d), gravity=(0.0,) * d, colliders=[],
                               rigid_bodies=[], joints=[], regions=[], solution=None)


def assert_conserved(scene, spec, steps: int, device: str):
    """float32, EMPM at the stable step (CFL 0.4): the particle masses are
    untouched, and the total momentum and the angular momentum about the
    centre of mass change by round-off only, at most 4 eps32 per step of
    their scales sum m |v| and sum m (|x - c| |v| + |A|) (P2G and G2P
    conserve both exactly; their float32 sums round, measured up to 1.3 eps32
    per step over the scenes); returns the first and last diagnostics. With
    elastic contact between the bodies (mpm.body_springs) only the momentum:
    a spring's reaction acts at the particles under it, not on its line of
    action, and its tangential part is a couple over the height between them,
    so the angular momentum changes by the contact's discretisation (the
    rolling slab's box, 6.0 eps32 per step; two disks, 1.5e-5 of its scale
    over their strike, RESULTS.md)."""
    model, state = mpm.build(scene, spec.kernel, "float32", device, spec.seed)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(transfer=spec.transfer))
    solver.prepare(state)
    names = solver.diagnostics.names
    mass = model.mass.numpy().copy()
    d0 = solver.measure(state, elastic=True)
    report = None
    for _ in range(steps):
        report = solver.advance(state, solver.timestep.stable_dt(0.4, report, 2.0))
        assert report.reason is None, report.reason
    d1 = solver.measure(state, elastic=True)
    np.testing.assert_array_equal(model.mass.numpy(), mass)
    assert d1[names.index("mass")] == d0[names.index("mass")]
    for kind in ("momentum",) if scene.contact == "elastic" else ("momentum", "angular_momentum"):
        idx = [i for i, n in enumerate(names) if n.startswith(kind) and not n.endswith("scale")]
        scale = max(d0[names.index(f"{kind}_scale")], d1[names.index(f"{kind}_scale")])
        change = np.linalg.norm(d1[idx] - d0[idx])
        assert change <= 4 * EPS32 * steps * scale, f"{kind}: {change / (EPS32 * steps * scale):.2f} eps32 per step"
    return names, d0, d1


@pytest.mark.parametrize("scene", SCENES)
def test_scene_runs_and_its_bodies_conserve_momentum(scene, tmp_path, device):
    """As configured, four steps complete through the command line's runner,
    with the particle mass unchanged (mass_drift exactly 0), metrics.json and
    a recording; in a closed box (closed_box) the same bodies conserve
    momentum and angular momentum to float32 round-off (assert_conserved)."""
    spec = spec_for([f"scene={scene}", "run.steps=4", "log.every=2"])
    metrics = execute(spec, tmp_path)
    assert metrics["status"] == "completed", metrics["reason"]
    assert metrics["steps"] == 4 and metrics["particles"] > 100
    assert metrics["mass_drift"] == 0.0
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["status"] == "completed" and saved["steps"] == 4
    for key in ("reason", "sim_time", "particles", "grid_nodes", "dt", "wall_time_s", "compile_time_s",
                "step_time_ms", "log_time_ms", "mass_drift", "momentum_drift", "angular_momentum_drift",
                "energy_initial", "energy_final"):
        assert key in saved, key
    assert (tmp_path / "recording.rrd").stat().st_size > 0
    assert_conserved(closed_box(spec), spec, 4, device)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("material", MATERIALS)
def test_every_material_conserves_momentum_in_2d_and_3d(material, dim, device):
    """A ball (2D) or a cube (3D) of each material group, pre-strained
    (compressed, so that sand holds a stress, and sheared: it rings), thrown and spinning in a closed box
    for ten steps: mass, momentum and angular momentum as in
    assert_conserved, while the stress did work (the elastic energy
    changed by more than a percent)."""
    scene = "elastic_ball_2d" if dim == 2 else "cube_drop_3d"
    F = [[0.94, 0.05], [-0.03, 0.96]] if dim == 2 else [[0.95, 0.03, 0.0], [0.0, 0.94, 0.02], [0.01, 0.0, 0.97]]
    spec = spec_for([f"scene={scene}", f"material={material}", "scene.resolution=24",
                     "scene.bodies.0.deformation=" + json.dumps(F)])
    names, d0, d1 = assert_conserved(closed_box(spec), spec, 10, device)
    e = names.index("elastic_energy")
    assert d0[e] > 0 and abs(d1[e] - d0[e]) > 0.01 * d0[e]
