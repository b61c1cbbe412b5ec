"""Bad input of every class refused in one line naming the key or file, the
value and what is accepted, before anything is compiled or allocated: mesh
files, selections that hold no particle, option types, unknown keys under
nested groups, output paths and numbers of the tools; and the warnings of
inputs that run (bodies overlapping at the start, a fixed step above the
stability limit)."""

from __future__ import annotations

import contextlib
import io
import re

import numpy as np
import pytest

from helpers import compose_cfg
from pipelines.config.overrides import check_groups, check_stability_map, replace_inline_mappings
from pipelines.config.validate import ConfigError, check_memory, resolve, validate


def outcome(overrides: list[str]) -> tuple[list[str], ConfigError | None]:
    """(warnings, None) or ([], the error) of pipelines.run's checks."""
    overrides = replace_inline_mappings(overrides)
    try:
        check_groups(overrides)
        return validate(compose_cfg(overrides), overrides)[1], None
    except ConfigError as e:
        return [], e


def refused(overrides: list[str]) -> ConfigError:
    warnings, err = outcome(overrides)
    assert err is not None, f"accepted: {overrides} ({warnings})"
    assert "\n" not in str(err) and "accepted: " in str(err), str(err)
    return err


# ------------------------------------------------------------------ mesh files
TET = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
BAD_MESHES = {  # file name -> (contents, a fragment of the problem); None: a directory
    "folder.obj": (None, "a directory"),
    "empty.obj": ("", "an empty file"),
    "notes.obj": ("these are notes, not vertices\n", "not a closed triangle mesh"),
    "short_vertex.obj": ("v 0 0 0\nv 1 0\nf 1 2 3\n", "not a readable mesh"),
    "header_only.ply": ("ply\nformat ascii 1.0\nelement vertex 3\n", "not a readable mesh"),
    "truncated.stl": ("solid x\nfacet normal 0 0\nendsolid\n", "not a closed triangle mesh"),
    "garbage.stl": ("\x00\x01binary garbage" * 7, "mesh"),
    "nan.obj": (TET.replace("v 1 0 0", "v nan 0 0"), "not finite"),
    "inf.obj": (TET.replace("v 0 1 0", "v 0 inf 0"), "not finite"),
    "flat.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\nf 1 3 2\nf 2 3 4\n", "no volume"),
    "open.obj": (TET.rsplit("f ", 1)[0] + "f 1 2 3\n", "open surface"),
    "bad_index.obj": (TET + "f 1 2 9\n", "not a readable mesh|past its"),
}


def _write(path, contents):
    if contents is None:
        path.mkdir()
    else:
        path.write_text(contents)
    return str(path)


@pytest.mark.parametrize("name", list(BAD_MESHES))
def test_a_bad_mesh_file_is_refused_naming_the_file(name, tmp_path):
    contents, fragment = BAD_MESHES[name]
    path = _write(tmp_path / name, contents)
    err = refused(["scene=yoyo", f"scene.bodies.0.shape.parts.0.mesh={path}"])
    assert err.key == "scene.bodies[0].shape.parts[0].mesh" and path in str(err)
    assert any(f in str(err) for f in fragment.split("|")), str(err)


def test_a_closed_mesh_file_is_accepted_and_one_too_small_names_the_file(tmp_path):
    path = _write(tmp_path / "tet.obj", TET)
    warnings, err = outcome(["scene=yoyo", f"scene.bodies.0.shape.parts.0.mesh={path}"])
    assert err is None
    err = refused(["scene=elastic_ball_3d", "scene.bodies.0.shape.type=mesh", f"scene.bodies.0.shape.mesh={path}",
                   "scene.bodies.0.shape.size=0.002", "scene.bodies.0.shape.radius=null"])
    assert err.key == "scene.bodies[0].shape" and path in str(err) and "holds no particle" in str(err)


# ------------------------------------------------------------------ selections
@pytest.mark.parametrize("overrides, key, fragments", [
    (["scene=cantilever_2d", "scene.loads.0.select.center=[0.2,0.1]"], "scene.loads[0].select",
     ["load 'tip'", "body 'beam'", "[0.175, 0.225] x [0.04, 0.16]", "domain [0, 1.2] x [0, 0.9]"]),
    (["scene=cantilever_2d", "scene.loads.0.body=null", "scene.loads.0.select.center=[1.1,0.2]"],
     "scene.loads[0].select", ["of any body"]),
    (["scene=cantilever_2d", "scene.regions.0.select.center=[0.2,0.1]"], "scene.regions[0].select",
     ["region 'clamp'", "body 'beam'", "the body's particles", "domain"]),
    (["scene=cantilever_2d", "scene.loads.0.kind=point", "scene.loads.0.select=null", "scene.loads.0.normal=null",
      "scene.loads.0.at=[1.15,0.7]"], "scene.loads[0].at",
     ["[1.15, 0.7] is 0.1064 m from the nearest particle of body 'beam'", "within 2 cells (0.05 m)"]),
    (["scene=cantilever_2d", "scene.loads.0.kind=point", "scene.loads.0.select=null", "scene.loads.0.normal=null",
      "scene.loads.0.at=[1.25,0.7]"], "scene.loads[0].at", ["outside the domain", "[0, 1.2] x [0, 0.9]"]),
    (["scene=cantilever_2d", "scene.regions.0.select.half_size=[0.001,0.001]"], "scene.regions[0].select",
     ["region 'clamp'"]),
    (["scene=yoyo", "scene.regions.0.select.center=[0.1,0.3,0.1]"], "scene.regions[0].select", ["'anchor'"]),
    (["scene=cantilever_2d", "scene.regions.0.body=null"], "scene.regions[0].body", ["beam"]),
    (["scene.bodies.0.shape.radius=0.001"], "scene.bodies[0].shape", ["body 'ball'", "holds no particle", "domain"]),
    (["scene=two_disks", "scene.bodies.1.ppc=1", "scene.bodies.1.shape.radius=0.004"], "scene.bodies[1].shape",
     ["body 'b'"]),
])
def test_a_selection_without_particles_is_refused_before_the_run(overrides, key, fragments):
    err = refused(overrides)
    assert err.key == key and all(f in str(err) for f in fragments), str(err)


def test_overlapping_bodies_are_warned_with_the_overlap_size():
    warnings, err = outcome(["scene=two_disks", "scene.bodies.1.shape.center=[0.45,0.5]"])
    assert err is None and len(warnings) == 1, warnings
    assert "'a'" in warnings[0] and "'b'" in warnings[0] and "overlap at the start" in warnings[0]
    n, area = (float(x) for x in re.search(r": (\d+) particles .* \(about ([\d.e+-]+) m\^2\)", warnings[0]).groups())
    assert n > 0 and area > 0
    assert outcome(["scene=two_disks"]) == ([], None)  # apart: nothing said


# ------------------------------------------------------------------ option types and unknown keys
@pytest.mark.parametrize("overrides, key", [
    (["integrator=implicit", "integrator.newton_max=abc"], "integrator.newton_max"),
    (["integrator=implicit", "integrator.cg_max=1.5"], "integrator.cg_max"),
    (["integrator=implicit", "integrator.halvings=[1]"], "integrator.halvings"),
    (["integrator=implicit", "integrator.newton_tol=nan"], "integrator.newton_tol"),
    (["integrator=implicit", "integrator.line_search=2"], "integrator.line_search"),
    (["integrator=implicit", "integrator.psd=maybe"], "integrator.psd"),
    (["integrator=implicit", "integrator.displacement={a: 1}"], "integrator.displacement"),
    (["integrator=explicit", "+integrator.newton_max=3"], "integrator.newton_max"),
    (["log.dJ=2"], "log.dJ"),
    (["run.plan=0"], "run.plan"),
    (["scene=1"], "scene"),
    (["scheme=null"], "scheme"),
    (["+scale.no_such_size=1"], "scale.no_such_size"),
    (["scale=paper", "+scale.update_cost_resolution.nope=3"], "scale.update_cost_resolution.nope"),
    (["+scene.sizes.default.resolutoin=8"], "scene.sizes.default.resolutoin"),
    (["scene.domain={a: 1}"], "scene.domain"),
    (["stability_map={a: 1}"], "stability_map"),
])
def test_a_value_of_the_wrong_type_or_an_unknown_key_is_refused(overrides, key):
    from pipelines.config.errors import describe

    try:
        err = refused(overrides)
        text = str(err)
    except Exception as e:  # noqa: BLE001 - composition errors: described in one line by the command line
        text = describe(e)
        assert text is not None, repr(e)
    assert text.startswith(f"{key}:") and "\n" not in text, text


def refusal(overrides: list[str]) -> str:
    """The one line pipelines.run prints for ``overrides``: a ConfigError of
    the checks, or a composition error described by the command line."""
    from pipelines.config.errors import describe

    overrides = replace_inline_mappings(overrides)
    try:
        check_groups(overrides)
        cfg = compose_cfg(overrides)
    except ConfigError as e:
        return str(e)
    except Exception as e:  # noqa: BLE001 - composition errors: described in one line by the command line
        text = describe(e)
        assert text is not None, repr(e)
        return text
    try:
        warnings = validate(cfg, overrides)[1]
    except ConfigError as e:
        return str(e)
    raise AssertionError(f"accepted: {overrides} ({warnings})")


# ------------------------------------------------------------------ keys of another option of a group
@pytest.mark.parametrize("overrides, key, fragments", [
    # the implicit integrator chosen by its key, or not at all: its options are not the explicit one's
    (["integrator.name=implicit", "integrator.newton_max=5"], "integrator.newton_max",
     ["not a parameter of explicit (its keys: name)", "with the group, integrator=implicit (its keys: name, "
      "newton_max, newton_tol,", "then set integrator.newton_max", "integrator.name=... does not change"]),
    (["integrator.newton_max=5"], "integrator.newton_max", ["integrator=implicit (its keys:"]),
    (["+integrator.newton_max=5"], "integrator.newton_max", ["integrator=implicit (its keys:"]),
    (["scheme.epsilon=0.1"], "scheme.epsilon", ["not a parameter of empm", "scheme=aulmpm (its keys: name, epsilon"]),
    (["scheme=tlmpm", "scheme.eta=0.5"], "scheme.eta", ["not a parameter of tlmpm", "scheme=aulmpm"]),
    (["material.K=1e5"], "material.K", ["not a parameter of fixed_corotated (its keys: model, rho, E, nu)",
                                        "material=fluid (or viscous)", "then set material.K"]),
    (["material=fluid", "material.E=1e5"], "material.E", ["material=fixed_corotated (or neo_hookean,"]),
    (["material=fluid", "material.yield_stress=1e5"], "material.yield_stress",
     ["material=von_mises (or viscoplastic)"]),
    # a kind changed by its key keeps the keys of the one it replaces
    (["material.model=fluid"], "material.model", ["fluid set by key keeps E, nu", "material=fluid (its keys: "
                                                  "model, rho, K, gamma, viscosity)"]),
    (["scheme=aulmpm", "scheme.name=empm"], "scheme.name", ["keeps epsilon, eta", "scheme=empm (its keys: name)"]),
    (["integrator=implicit", "integrator.name=explicit"], "integrator.name", ["integrator=explicit"]),
    # a body's own material, and a body that takes the group's
    (["scene=column_collapse_2d", "scene.bodies.0.material.K=5"], "scene.bodies[0].material.K",
     ["not a parameter of sand", "scene.bodies.0.material={model: fluid, ...} (or viscous)"]),
    (["scene.bodies.0.material.K=5"], "scene.bodies[0].material.K",
     ["no material of its own", "scene.bodies.0.material={model: fluid, ...}", "material=fluid material.K=..."]),
])
def test_a_key_of_another_option_names_the_option_that_takes_it(overrides, key, fragments):
    """An option of a group's other choice (``integrator.newton_max`` with the
    explicit integrator) was refused as ``unknown key; accepted: name``,
    which did not say what to change."""
    text = refusal(overrides)
    assert text.startswith(f"{key}: ") and "; accepted: " in text and "\n" not in text, text
    assert all(f in text for f in fragments), text


def test_a_kind_chosen_by_its_key_alone_still_runs():
    """Nothing of the option it replaces is kept: the explicit integrator and
    EMPM have no keys but their names."""
    from helpers import spec_for

    assert spec_for(["integrator.name=implicit"]).integrator.name == "implicit"
    assert spec_for(["scheme.name=aulmpm"]).scheme.name == "aulmpm"
    assert refusal(["material.Ee=1"]) == "material.Ee: unknown key; accepted: model, rho, E, nu"  # no option has it


# ------------------------------------------------------------------ shapes given whole
COMPOUND = "{type: compound, parts: [{type: box, center: [0.5,0.5], half_size: [0.1,0.1]}]}"


@pytest.mark.parametrize("overrides, check", [
    (["scene.bodies.0.shape=" + COMPOUND],
     lambda s: type(s.bodies[0].shape).__name__ == "Compound" and len(s.bodies[0].shape.parts) == 1),
    (["scene=yoyo", "scene.bodies.0.shape.parts.0={type: box, center: [0.5,0.95,0.5], half_size: [0.1,0.1,0.1]}"],
     lambda s: [type(p).__name__ for p in s.bodies[0].shape.parts] == ["Box", "Box"]),
    (["scene=cantilever_2d", "scene.loads.0.select={type: sphere, center: [1.05,0.7], radius: 0.05}"],
     lambda s: type(s.loads[0].select).__name__ == "Sphere"),
    (["scene=viscous_cup", "scene.colliders.0={type: sphere, center: [0.5,0.1,0.5], radius: 0.1}"],
     lambda s: s.colliders[0].type == "sphere" and s.colliders[0].radius == 0.1  # the cup's keys gone:
     and s.colliders[0].depth == 0.0 and s.colliders[0].boundary == "slip" and s.colliders[0].name == ""),
    (["scene.bodies.0.shape={radius: 0.25}"],  # without its type: merged into the scene's
     lambda s: s.bodies[0].shape.radius == 0.25 and tuple(s.bodies[0].shape.center) == (0.5, 0.6)),
])
def test_a_shape_or_collider_given_whole_replaces_the_scene_s(overrides, check):
    """A mapping with its type replaces the shape (collider) there: it was
    merged into the scene's, keeping the sphere's centre and radius, so that
    a correct compound was refused with ``center: not used by a compound``."""
    from helpers import spec_for

    spec = spec_for(replace_inline_mappings(overrides))
    assert check(spec.scene), spec.scene


@pytest.mark.parametrize("overrides, key, fragments", [
    (["scene.bodies.0.shape={type: compound}"], "scene.bodies[0].shape.parts",
     ["missing for a compound", "accepted: a list (the shapes, each a mapping with a type key)"]),
    (["scene.bodies.0.shape={type: compound, parts: []}"], "scene.bodies[0].shape.parts",
     ["[]; accepted: a non-empty list of shapes, each a mapping with a type key (box, sphere,"]),
    (["scene.bodies.0.shape={type: compound, parts: {type: box}}"], "scene.bodies.0.shape.parts",
     ["{type: box} is a mapping; accepted: a list"]),
    (["scene.bodies.0.shape={type: sphere, center: [0.5,0.5], radius: 0.1, parts: [{type: box}]}"],
     "scene.bodies[0].shape.parts", ["not used by a sphere; accepted: type, center, radius, inner_radius, "
                                     "rotation; or parts with a compound", "scene.bodies.0.shape={type: compound, "
                                     "...} (its keys: type, parts, rotation)"]),
    (["scene=elastic_ball_3d", "scene.bodies.0.shape={type: mesh, mesh: 'warp:bunny', center: [0.5,0.5,0.5], "
      "size: 0.3, parts: [{type: box}]}"], "scene.bodies[0].shape.parts",
     ["not used by a mesh; accepted: type, mesh, center, size, axis, rotation; or parts with a compound"]),
    (["scene.bodies.0.shape.parts=[{type: box, center: [0.5,0.5], half_size: [0.1,0.1]}]"],
     "scene.bodies[0].shape.parts", ["not used by a sphere", "{type: compound, ...}"]),
    (["scene.bodies.0.shape.type=compound"], "scene.bodies[0].shape.type",
     ["compound set by key keeps center, radius", "scene.bodies.0.shape={type: compound, ...}"]),
    (["scene.bodies.0.shape={type: compound, parts: [{type: box, center: [0.5,0.5], size: [0.2,0.2]}]}"],
     "scene.bodies[0].shape.parts[0].size", ["not used by a box; accepted: type, center, half_size, rotation"]),
    (["scene=viscous_cup", "scene.colliders.0.type=sphere"], "scene.colliders[0].type",
     ["keeps axis, depth, thickness", "scene.colliders.0={type: sphere, ...}"]),
])
def test_a_wrong_shape_names_its_type_and_keys(overrides, key, fragments):
    text = refusal(overrides)
    assert text.startswith(f"{key}: ") and "; accepted: " in text and "\n" not in text, text
    assert all(f in text for f in fragments), text


def test_a_new_size_is_accepted_and_chosen():
    assert outcome(["+scene.sizes.huge={resolution: 32}", "scene.size=huge"])[1] is None


@pytest.mark.parametrize("override, key", [("scene.ppc=100000", "scene.ppc"),
                                           ("scene.bodies.0.ppc=100000", "scene.bodies[0].ppc"),
                                           ("scene.particle_resolution=100000", "scene.particle_resolution"),
                                           ("scene.resolution=100000", "scene.resolution")])
def test_a_run_too_large_names_what_makes_it_large(override, key):
    with pytest.raises(ConfigError) as err:
        check_memory(resolve(compose_cfg([override])))
    assert err.value.key == key


def test_an_inline_material_replaces_the_body_s_own():
    """The documented override on a scene whose body brings its own material."""
    from helpers import spec_for

    over = replace_inline_mappings(["scene=column_collapse_2d", "scene.bodies.0.material={model: fluid, K: 5e4}"])
    m = spec_for(over).scene.bodies[0].material
    assert m.name == "fluid" and m.K == 5e4 and m.rho == 1000.0  # the fluid's own defaults, nothing of the sand
    err = refused(["scene=column_collapse_2d", "scene.bodies.0.material={model: fluid, E: 5e4}"])
    assert err.key == "scene.bodies[0].material.E"


def test_a_fixed_step_above_the_limit_is_warned_for_every_material():
    for material in ("fixed_corotated", "snow", "von_mises", "sand", "fluid"):
        warnings, err = outcome([f"material={material}", "run.dt=1e-2"])
        assert err is None and any("stability limit" in w for w in warnings), (material, warnings)
        assert outcome([f"material={material}", "run.dt=1e-7"]) == ([], None)


# ------------------------------------------------------------------ the tools' paths and numbers
def _call(main, argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as e:
            code = e.code
    return code, err.getvalue().strip()


def test_the_material_point_checks_its_output_and_numbers_before_computing(tmp_path, monkeypatch):
    import pipelines.material_point as mp

    monkeypatch.setattr(mp, "drive", lambda *a, **k: pytest.fail("computed before the checks"))
    (tmp_path / "notes.txt").write_text("mine")
    for argv, fragment in [(["--out", str(tmp_path / "missing" / "x.png")], "no folder"),
                           (["--out", str(tmp_path / "notes.txt")], "ending in .png"),
                           (["--out", str(tmp_path)], "ending in .png"),
                           (["--strain", "nan"], "--strain: nan"), (["--rate", "inf"], "--rate: inf"),
                           (["--rate", "0"], "--rate: 0"), (["--steps", "0"], "--steps: 0")]:
        code, err = _call(mp.main, argv)
        assert code == 2 and err.startswith("error: ") and fragment in err and "\n" not in err, err
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_the_material_point_writes_into_the_outputs_folder_by_default(tmp_path, monkeypatch):
    """Without --out its PNG and CSV go to outputs/material_point/ (made),
    not into the working directory (where they went)."""
    import pipelines.material_point as mp

    monkeypatch.chdir(tmp_path)
    code, err = _call(mp.main, ["--steps", "5", "--dim", "2"])
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "outputs" / "material_point").iterdir()) == [
        "stress_strain.csv", "stress_strain.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["outputs"]


@pytest.mark.parametrize("argv, closed_form", [
    # the Tait fluid: p = K (J^-gamma - 1), J = exp(d s) on the isotropic path
    (["material=fluid", "material.K=3e5", "--path", "isotropic", "--strain", "-0.05"],
     lambda s: {"pressure": 3e5 * (np.exp(3 * s) ** -7.0 - 1.0)}),
    # fixed corotated, 2D: F = e^s I, R = I, Cauchy = (2 mu (e^2s - e^s) + lam (J - 1) J) / J, J = e^2s
    (["material=fixed_corotated", "material.nu=0.25", "--path", "isotropic", "--dim", "2"],
     lambda s: {"sigma_xx": (2 * 4e4 * (np.exp(2 * s) - np.exp(s)) + 4e4 * (np.exp(2 * s) - 1) * np.exp(2 * s))
                / np.exp(2 * s)}),
])
def test_the_material_point_summary_and_table_are_float64(argv, closed_form, tmp_path):
    """The driver evaluates in float64 (mpm.materials.point_driver.MaterialPoint's
    default): its table and summary match float64 closed forms far below
    float32 round-off (1.2e-7), from the command line's config to the CSV."""
    import pipelines.material_point as mp

    out = tmp_path / "p.png"
    lines = io.StringIO()
    with contextlib.redirect_stdout(lines):
        assert mp.main(argv + ["--steps", "20", "--out", str(out)]) == 0
    data = np.genfromtxt(out.with_suffix(".csv"), delimiter=",", names=True)
    for column, want in closed_form(data["strain"]).items():
        assert np.allclose(data[column], want, rtol=1e-12, atol=1e-9 * np.abs(want).max()), column
    summary = lines.getvalue()
    assert f"final pressure {data['pressure'][-1]:.6g} Pa" in summary, summary


def test_replay_and_report_refuse_an_existing_file_as_an_output_folder(tmp_path):
    from pipelines.replay import main as replay
    from pipelines.report import main as report

    (tmp_path / "f.png").write_text("not a folder")
    (tmp_path / "recording.rrd").write_text("")
    code, err = _call(replay, [str(tmp_path), "--frames", str(tmp_path / "f.png")])
    assert code == 2 and err.startswith("error: --frames:") and "is a file" in err
    code, err = _call(report, [str(tmp_path), "--out", str(tmp_path / "f.png")])
    assert code == 2 and err.startswith("error: --out:") and "is a file" in err
    assert (tmp_path / "f.png").read_text() == "not a folder"


def test_replay_of_a_timings_file_says_what_to_replay(tmp_path):
    from pipelines.replay import main as replay

    timings = tmp_path / "recording.timings.rrd"
    timings.write_bytes(np.zeros(8, np.uint8).tobytes())
    code, err = _call(replay, [str(timings)])
    assert code == 2 and "wall-clock timings" in err and f"python -m pipelines.replay {tmp_path}" in err


@pytest.mark.parametrize("sweep,bad", [("scene=1,2", True), ("scene=yoyo,2", True), ("scheme=range(1,3)", True),
                                       ("scene=yoyo,elastic_ball_2d", False), ("scene=glob(elastic_*)", False)])
def test_a_sweep_over_a_group_names_options(sweep, bad):
    """-m scene=1,2 failed inside Hydra with a traceback in every job: each
    choice of a group's sweep is checked before anything runs."""
    if not bad:
        check_groups([sweep])
        return
    with pytest.raises(ConfigError) as e:
        check_groups([sweep])
    assert str(e.value).startswith(f"{sweep.split('=')[0]}: '{sweep.split('=', 1)[1]}' is not an option's name; "
                                   f"accepted: ")


def test_the_checked_particles_are_the_run_s(monkeypatch):
    """The particle check samples the bodies (mpm.model.sample_bodies) and
    hands them to mpm.build once, which then samples nothing: the same
    particles as a build that samples itself, and sampled once per run."""
    import mpm
    import mpm.model

    spec, _ = validate(compose_cfg(["scene=two_disks", "scene.jitter=0.5"]))
    assert spec.samples is not None and len(spec.samples) == 2
    calls = []
    original = mpm.model.sample_bodies
    monkeypatch.setattr(mpm.model, "sample_bodies", lambda *a: calls.append(a) or original(*a))
    model, state = mpm.build(spec.scene, spec.kernel, "float64", "cpu", spec.seed, samples=spec.take_samples())
    assert calls == [] and spec.samples is None  # taken once
    fresh, fresh_state = mpm.build(spec.scene, spec.kernel, "float64", "cpu", spec.seed)
    assert len(calls) == 1
    np.testing.assert_array_equal(state.x.numpy(), fresh_state.x.numpy())
    np.testing.assert_array_equal(model.mass.numpy(), fresh.mass.numpy())


@pytest.mark.parametrize("override", ["+stability_map={steps: 0}", "stability_map={E: [1e5], dt_cfl: [0.5]}",
                                      "stability_map.steps=0"])
def test_a_stability_map_without_its_experiment_is_one_line(override):
    """stability_map is empty until +experiment=stability fills it; Hydra
    cannot merge into the empty node (an internal message, 'NoneType' object
    has no attribute 'get'): the override is refused naming the way in; with
    the experiment its keys are checked as any other."""
    with pytest.raises(ConfigError) as caught:
        check_stability_map([override])
    message = str(caught.value)
    assert message.startswith("stability_map: ") and "+experiment=stability" in message and "\n" not in message
    check_stability_map(["+experiment=stability", "stability_map.steps=3"])
    with pytest.raises(ConfigError, match=r"stability_map.steps: 0 out of range; accepted: stability_map.steps >= 1"):
        resolve(compose_cfg(["+experiment=stability", "stability_map.steps=0"]))


@pytest.mark.parametrize("overrides, key, fragment", [
    (["scene=drum_2d", "scene.colliders.0.angular_velocity=[1.0,2.0]"], "scene.colliders[0].angular_velocity",
     "accepted: a number [rad/s] (about z) in 2D"),
    (["scene=drum_2d", "scene.colliders.0.angular_velocity=nan"], "scene.colliders[0].angular_velocity",
     "is not finite"),
    (["scene=drum_2d", "scene.colliders.0.pivot=[0.5,0.5,0.5]"], "scene.colliders[0].pivot",
     "accepted: a list of 2 numbers"),
    (["scene=drum_2d", "scene.colliders.0.pivot=[0.5,inf]"], "scene.colliders[0].pivot[1]", "is not finite"),
    (["scene=viscous_cup", "scene.colliders.0.angular_velocity=1.5"], "scene.colliders[0].angular_velocity",
     "accepted: a list of 3 numbers [rad/s] in 3D"),
    (["scene=viscous_cup", "scene.colliders.0.angular_velocity=[0.0,inf,0.0]"],
     "scene.colliders[0].angular_velocity[1]", "is not finite"),
])
def test_a_bad_turning_collider_names_its_key(overrides, key, fragment):
    err = refused(overrides)
    assert err.key == key and fragment in str(err), str(err)


def test_a_turning_collider_reaches_the_solver():
    """The scene keys become mpm.Collider's: a number about z in 2D, three
    numbers in 3D, the pivot where given (else the shape's centre)."""
    from helpers import spec_for

    drum = spec_for(["scene=drum_2d"]).scene.colliders[0]
    assert drum.angular_velocity == 1.5 and drum.pivot is None and drum.rest_pivot(2) == (0.5, 0.5)
    cup = spec_for(["scene=viscous_cup", "scene.colliders.0.angular_velocity=[0.0,2.0,0.0]",
                    "scene.colliders.0.pivot=[0.5,0.3,0.5]"]).scene.colliders[0]
    assert tuple(cup.angular_velocity) == (0.0, 2.0, 0.0) and tuple(cup.pivot) == (0.5, 0.3, 0.5)


def test_a_rigid_body_is_read_and_its_bad_keys_refused():
    """scene.rigid_bodies: a box of the floating_box_2d scene becomes an
    mpm.RigidBody; a negative density, a cup shape and a body outside the
    domain are refused in one line naming the key."""
    from helpers import spec_for

    body = spec_for(["scene=floating_box_2d"]).scene.rigid_bodies[0]
    assert type(body).__name__ == "RigidBody" and body.density == 500.0 and body.shape.boundary == "separate"
    assert refused(["scene=floating_box_2d", "scene.rigid_bodies.0.density=-1"]).key == "scene.rigid_bodies[0].density"
    for overrides, key in ((["scene.rigid_bodies.0.shape={type: cup, center: [0.2,0.2], radius: 0.05, depth: 0.05, "
                             "thickness: 0.01}"], "rigid_bodies[0].shape"),
                           (["scene.rigid_bodies.0.shape.center=[0.9,0.2]"], "rigid_bodies[0].shape.center")):
        text = refusal(replace_inline_mappings(["scene=floating_box_2d"] + overrides))
        assert key in text.split(": ")[0] and "; accepted: " in text and "\n" not in text, text


def test_a_joint_is_read_and_its_bad_keys_refused():
    """scene.joints: the hinge of the pendulum_jelly_2d scene becomes an
    mpm.Joint; a missing body, an unknown type, a ball in 2D, an anchor
    outside the domain or of the wrong size, an axis in 2D and a missing
    child are refused in one line naming the key, with the accepted values."""
    from helpers import spec_for

    joint = spec_for(["scene=pendulum_jelly_2d"]).scene.joints[0]
    assert type(joint).__name__ == "Joint" and joint.child == "bob" and joint.parent is None
    assert tuple(joint.anchor) == (0.5, 0.45) and joint.type == "revolute"
    base = ["scene=pendulum_jelly_2d"]
    for override, key, accepted in (
            ("scene.joints.0.child=lid", "scene.joints[0].child", "a rigid body's index (0 to 0) or name (bob)"),
            ("scene.joints.0.child=2", "scene.joints[0].child", "a rigid body's index"),
            ("scene.joints.0.child=null", "scene.joints[0].child", ""),
            ("scene.joints.0.parent=jelly", "scene.joints[0].parent", "null (the world) or a rigid body's index"),
            ("scene.joints.0.type=hinge", "scene.joints[0].type", "revolute, ball"),
            ("scene.joints.0.type=ball", "scene.joints[0].type", "accepted: revolute, prismatic, fixed (in 2D; ball "
                                                                 "in 3D)"),
            ("scene.joints.0.anchor=[0.5,1.5]", "scene.joints[0].anchor", "a point in [0, 1] x [0, 1] [m]"),
            ("scene.joints.0.anchor=[0.5]", "scene.joints[0].anchor", ""),
            ("scene.joints.0.axis=[0,0,1]", "scene.joints[0].axis", "a list of 2 numbers"),
            ("scene.joints.0.axis=[0,1]", "scene.joints[0].axis", "null (about z in 2D)")):
        err = refused(base + [override])
        assert err.key == key and accepted in str(err), (override, str(err))
    assert refused(base + ["run.graph=true"]).key == "run.graph"  # (the step is read back every step)



def test_rigid_contact_is_read_and_its_bad_keys_refused():
    """scene.rigid_contact and its penalty reach mpm.Scene; an unknown mode
    and a stiffness that is not positive are refused in one line."""
    from helpers import spec_for

    s = spec_for(["scene=pendulum_jelly_2d", "scene.rigid_contact=all", "scene.rigid_contact_stiffness=2e5",
                  "scene.rigid_contact_damping=50"]).scene
    assert (s.rigid_contact, s.rigid_contact_stiffness, s.rigid_contact_damping) == ("all", 2e5, 50.0)
    err = refused(["scene=pendulum_jelly_2d", "scene.rigid_contact=floor"])
    assert err.key == "scene.rigid_contact" and "none, walls, all" in str(err)
    assert refused(["scene=pendulum_jelly_2d", "scene.rigid_contact_stiffness=0"]).key == \
        "scene.rigid_contact_stiffness"


def test_an_elastic_collider_is_read_and_refused_under_the_implicit_integrator():
    """boundary: elastic, its stiffness and its damping reach mpm.Collider;
    the implicit integrator, where its springs do not act, and a stiffness
    or a damping out of range are refused in one line naming the
    collider's key (a rigid body's shape's too) and the accepted range."""
    from helpers import spec_for

    elastic = ["scene=drum_2d", "scene.colliders.0.boundary=elastic"]
    drum = spec_for(elastic + ["scene.colliders.0.stiffness=0.25", "scene.colliders.0.damping=0.5"]).scene.colliders[0]
    assert (drum.boundary, drum.stiffness, drum.damping) == ("elastic", 0.25, 0.5)
    err = refused(elastic + ["integrator=implicit"])
    assert err.key == "scene.colliders[0].boundary" and "integrator=explicit" in str(err)
    assert refused(elastic + ["scene.colliders.0.stiffness=5"]).key == "scene.colliders[0].stiffness"
    for bad in ("-0.5", "1.5"):
        err = refused(elastic + [f"scene.colliders.0.damping={bad}"])
        assert err.key == "scene.colliders[0].damping" and "1" in str(err), str(err)
    err = refused(["scene=pendulum_jelly_2d", "scene.rigid_bodies.0.shape.damping=2"])
    assert err.key == "scene.rigid_bodies[0].shape.damping", str(err)
    assert refused(["scene=drum_2d", "scene.colliders.0.boundary=springy"]).key == "scene.colliders[0].boundary"


def test_elastic_contact_between_bodies_is_read_and_refused_under_the_implicit_integrator():
    """scene.contact=elastic and its stiffness and friction reach mpm.Scene;
    the implicit integrator, where its springs do not act (mpm.body_springs),
    and a stiffness out of range are refused in one line naming the key."""
    from helpers import spec_for

    elastic = ["scene=two_disks", "scene.contact=elastic"]
    scene = spec_for(elastic + ["scene.contact_stiffness=0.25", "scene.contact_friction=0.3"]).scene
    assert (scene.contact, scene.contact_stiffness, scene.contact_friction) == ("elastic", 0.25, 0.3)
    err = refused(elastic + ["integrator=implicit"])
    assert err.key == "scene.contact" and "integrator=explicit" in str(err)
    assert refused(elastic + ["scene.contact_stiffness=5"]).key == "scene.contact_stiffness"
