"""What the single definition of the configuration guarantees
(pipelines.config.fields): every field of every group has a type, a default
and a doc; the options defined in code are those definitions; every file in
conf/ validates and holds values only; an unknown key is refused at every
depth; the accepted values in the messages are the definition's."""

import dataclasses
import re
import typing

import pytest
from omegaconf import MISSING, OmegaConf

import mpm
from helpers import CONF, compose_cfg, group_options, spec_for
from mpm.params import in_range
from pipelines.config import schema
from pipelines.config.colliders import COLLIDERS, ColliderConfig
from pipelines.config.errors import describe
from pipelines.config.fields import ConfigError, bounds, unwrap
from pipelines.config.physics import GROUPS
from pipelines.config.scene import SOLUTION, BodyConfig, SceneConfig
from pipelines.config.settings import KernelConfig, LogSettings, RunSettings
from pipelines.config.shapes import SHAPES, ShapeConfig
from pipelines.config.validate import resolve

CLASSES = list(schema.group_fields())
FAMILIES = [*GROUPS.values(), SHAPES, COLLIDERS, SOLUTION]
DISCRIMINATORS = {(cls, family.key) for family in FAMILIES for cls in family.variants.values()}


def _message(overrides: list[str]) -> tuple[str, str]:
    """(key, one-line message) of the configuration error ``overrides`` make."""
    try:
        resolve(compose_cfg(overrides))
    except ConfigError as e:
        return e.key, str(e)
    except Exception as e:  # noqa: BLE001 - Hydra's own, described as on the command line
        text = describe(e)
        assert text is not None, repr(e)
        return text.split(": ", 1)[0], text
    raise AssertionError(f"{overrides}: accepted")


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_field_has_a_type_a_default_and_a_doc(cls):
    types = typing.get_type_hints(cls)
    assert (cls.__doc__ or "").strip(), f"{cls.__name__} has no docstring"
    defaults = {next(iter(d)) for d in OmegaConf.to_container(OmegaConf.load(CONF / "config.yaml").defaults)
                if isinstance(d, dict)}
    for f in dataclasses.fields(cls):
        assert f.name in types, f"{cls.__name__}.{f.name}: no type"
        assert f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING, \
            f"{cls.__name__}.{f.name}: no default"
        if f.default == MISSING:  # the defaults list picks the option; a scene names itself
            assert (cls is schema.Config and f.name in defaults) or (cls is SceneConfig and f.name == "name"), f.name
        # a discriminator (type, model, name of a family's class) is documented by its class's docstring
        assert f.metadata.get("doc") or (cls, f.name) in DISCRIMINATORS, f"{cls.__name__}.{f.name}: no doc"


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_default_is_accepted_by_its_own_field(cls):
    types = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        value = f.default if f.default_factory is dataclasses.MISSING else f.default_factory()
        meta = f.metadata
        if value is None or value == MISSING or (isinstance(value, str) and value.startswith("${")):
            continue
        optional, base = unwrap(types[f.name])
        if base in (int, float) and not isinstance(value, bool):
            assert in_range(float(value), meta) or not any(meta.get(b) is not None for b in ("gt", "ge", "lt", "le")), \
                f"{cls.__name__}.{f.name} = {value}"
        if meta.get("choices"):
            assert value in meta["choices"], f"{cls.__name__}.{f.name} = {value!r}"


@pytest.mark.parametrize("group", sorted(schema.option_nodes()))
def test_options_defined_in_code_are_the_definitions(group):
    """material=fluid is mpm.materials.Fluid's defaults, nothing restated in
    conf/ (which has no folder for these groups)."""
    nodes = schema.option_nodes()[group]
    assert not (CONF / group).exists()
    assert group_options(group) == sorted(nodes)
    for name, node in nodes.items():
        composed = OmegaConf.to_container(compose_cfg([f"{group}={name}"])[group], resolve=True)
        assert composed == dataclasses.asdict(node), name
    registry = {"material": mpm.materials.MATERIALS, "scheme": mpm.SCHEMES,
                "integrator": mpm.integrators.INTEGRATORS, "kernel": mpm.KERNELS}[group]
    assert set(nodes) == set(registry)


def _file_cases():
    for path in sorted(CONF.rglob("*.yaml")):
        group = path.parent.name
        if path.parent.parent.name == "hydra":  # a Hydra option (the default launcher): the root config takes it
            yield path, []
        elif path.parent == CONF:
            yield path, []
        elif group in ("scene", "scale"):
            yield path, [f"{group}={path.stem}"]
        elif group == "tradeoff":  # its grids are named per scene
            yield path, ["scene=droplet_2d", f"+tradeoff={path.stem}"]
        else:
            yield path, [f"+{group}={path.stem}"]


@pytest.mark.parametrize("path, overrides", list(_file_cases()), ids=lambda v: getattr(v, "stem", ""))
def test_every_file_in_conf_validates_and_holds_values_only(path, overrides):
    defaults = OmegaConf.to_container(OmegaConf.load(path)).get("defaults") or []
    if path.name == "config.yaml":  # the root's one link to its definition, then the groups' options
        assert defaults[0] == "config_schema" and all(isinstance(d, (dict, str)) for d in defaults[1:])
        defaults = defaults[1:]
    hydra_option = path.parent.parent.name == "hydra"  # starts from one of Hydra's own (conf/hydra/launcher/cores)
    for entry in defaults:  # overrides of other groups, or another option of the same group to start from
        assert (entry == "_self_" or isinstance(entry, dict) or entry in group_options(path.parent.name)
                or hydra_option and entry == "joblib"), entry
    assert path.name == "config.yaml" or "_schema" not in path.read_text()
    resolve(compose_cfg(overrides))


def _full(path: str) -> str:
    """The key as messages name it: list indices in brackets."""
    return re.sub(r"\.(\d+)", r"[\1]", path)


def _mappings(node, path=""):
    """Paths of every mapping below ``node`` (plain values) whose keys are
    defined (not the free tables: hydra, scale, scene.sizes)."""
    if isinstance(node, dict):
        if path in ("hydra", "scale", "scene.sizes"):
            return
        yield path
        for k, v in node.items():
            yield from _mappings(v, f"{path}.{k}" if path else str(k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _mappings(v, f"{path}.{i}")


UNKNOWN_CASES = [[], ["scene=yoyo"], ["scene=water_bunny"], ["scene=vortex_2d"], ["+experiment=stability"],
                 ["scene=viscous_cup", "integrator=implicit", "scheme=aulmpm"]]


@pytest.mark.slow
@pytest.mark.parametrize("base", UNKNOWN_CASES, ids=lambda b: ",".join(b) or "default")
def test_an_unknown_key_is_refused_at_every_depth_naming_the_accepted_keys(base):
    paths = list(_mappings(OmegaConf.to_container(compose_cfg(base))))
    assert len(paths) >= 9
    for path in paths:
        added = f"{path}.zz_unknown" if path else "zz_unknown"
        key, text = _message(base + [f"+{added}=1"])
        assert key == _full(added), text
        assert re.search(r"(unknown key|not a parameter of \w+); accepted: \w", text), text


def _bad_value(f, tp, meta):
    """A value just outside the field's declared range or names, and the
    message the definition makes of it (without the key), or None."""
    optional, base = unwrap(tp)
    if meta.get("choices"):
        bad = "bogus" if base is str else max(meta["choices"]) + 1
        return bad, f"{bad!r} unknown; accepted: {', '.join(map(str, meta['choices']))}"
    if base not in (int, float) or meta.get("parse"):
        return None
    for b, step in (("gt", 0), ("ge", -1), ("lt", 0), ("le", 1)):
        if meta.get(b) is not None:
            return base(meta[b] + step), None
    return None


def _range_cases():
    groups = [("run", RunSettings, []), ("log", LogSettings, []), ("kernel", KernelConfig, []),
              ("detect", mpm.Detection, []), ("scene", SceneConfig, []), ("scene.bodies.0", BodyConfig, []),
              ("", schema.Config, [])]
    for group, family in GROUPS.items():
        groups += [(group, cls, [f"{group}={name}"]) for name, cls in family.variants.items()]
    for prefix, cls, base in groups:
        types = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            case = _bad_value(f, types[f.name], f.metadata)
            if case is None:
                continue
            key = f"{prefix}.{f.name}" if prefix else f.name
            full = _full(key)
            bad, text = case
            if text is None:
                text = f"{bad} out of range; accepted: {bounds(full, f.name, f.metadata)}"
            yield base + [f"{key}={bad}"], full, text


@pytest.mark.slow
def test_the_accepted_values_in_messages_are_the_definition_s():
    """Every ranged or named field of every group, given a value just outside
    what its metadata declares, is refused with exactly that declaration."""
    cases = list(_range_cases())
    assert len(cases) >= 60
    wrong = []
    for overrides, key, text in cases:
        got_key, got = _message(overrides)
        if got != f"{key}: {text}" and not got.startswith(f"{key}: {text.split('; accepted')[0]}"):
            wrong.append(f"{overrides}: {got} (expected {key}: {text})")
        elif "accepted: " in text and got.split("accepted: ")[-1] != text.split("accepted: ")[-1]:
            wrong.append(f"{overrides}: {got} (expected {key}: {text})")
    assert not wrong, "\n".join(wrong)


def test_the_flat_nodes_are_derived_from_the_kinds():
    for family, flat in ((SHAPES, ShapeConfig), (COLLIDERS, ColliderConfig)):
        assert [f.name for f in dataclasses.fields(flat)] == family.keys()
        assert flat.__dataclass_fields__[family.key].default == next(iter(family.variants))
        for cls in family.variants.values():
            assert {f.name for f in dataclasses.fields(cls)} <= set(family.keys())
    # keys every collider has keep their type and default; the others are null unless set
    assert ColliderConfig.__dataclass_fields__["boundary"].default == "slip"
    assert ColliderConfig.__dataclass_fields__["radius"].default is None
    # a key of another kind, and a key of none, in the scene's own words
    key, text = _message(["scene.bodies.0.shape.half_size=[0.1,0.1]"])
    assert text == ("scene.bodies[0].shape.half_size: not used by a sphere; accepted: type, center, radius, "
                    "inner_radius, rotation; or half_size with a box, the whole shape given as "
                    "scene.bodies.0.shape={type: box, ...} (its keys: type, center, half_size, rotation)")
    key, text = _message(["scene.bodies.0.shape.radiuss=1"])  # refused by Hydra, typed by the flat node
    assert text.startswith("scene.bodies[0].shape.radiuss: unknown key; accepted: type, center, half_size")
    key, text = _message(["scene=yoyo", "scene.bodies.0.shape.parts.0.center=null"])
    assert text == ("scene.bodies[0].shape.parts[0].center: missing for a mesh; accepted: a list of 3 numbers "
                    "(centre [m])")
    key, text = _message(["scene.bodies.0.shape={type: mesh, mesh: 'warp:bunny', center: [0.5, 0.5], size: 0.1}"])
    assert text == "scene.bodies[0].shape.type: mesh is 3D only; accepted in 2D: box, sphere, bowl, compound"


def test_values_no_type_states_are_checked_where_they_are_untyped():
    """Inline materials and closed-form solutions are free mappings to Hydra:
    their values are checked against their class all the same."""
    assert _message(["scene.bodies.0.material={model: fluid, K: abc}"])[1] == \
        "scene.bodies[0].material.K: 'abc' is not a number; accepted: a number, 0.0 < K"
    assert _message(["scene.bodies.0.material={model: fluid, K: true}"])[1] == \
        "scene.bodies[0].material.K: True is not a number; accepted: a number, 0.0 < K"
    assert _message(["scene.bodies.0.material={model: nacc, hardening: 3}"])[1] == \
        "scene.bodies[0].material.hardening: 3 is not true or false; accepted: true, false"
    assert _message(["scene=vibrating_bar_2d", "scene.solution.mode=1.5"])[1] == \
        "scene.solution.mode: 1.5 is not an integer; accepted: an integer, scene.solution.mode >= 1"
    assert _message(["scene=water_bunny", "scene.colliders.0.inside=maybe"])[0] == "scene.colliders[0].inside"
    # null where the definition has no null: refused by the field's own check
    assert _message(["scene.walls=null"])[1].startswith("scene.walls: None; accepted: one of sticky, slip, open")
    assert _message(["scene=yoyo", "scene.regions.0.body=null"])[1] == ("scene.regions[0].body: missing; accepted: a "
                                                                      "body's index (0 to 0) or name (yoyo)")


def test_run_sync_every_and_graph():
    spec = spec_for([])
    assert spec.run.sync_every is None and spec.run.graph is None
    spec = spec_for(["run.sync_every=10", "run.graph=true"])
    assert spec.run.sync_every == 10 and spec.run.graph is True
    assert _message(["run.sync_every=0"])[1] == "run.sync_every: 0 out of range; accepted: run.sync_every >= 1"
    assert _message(["run.sync_every=2.5"])[1] == "run.sync_every: '2.5' is not an integer; accepted: an integer"
    assert _message(["run.graph=maybe"])[1] == "run.graph: 'maybe' is not true or false; accepted: true, false"
    doc = RunSettings.__dataclass_fields__["sync_every"].metadata["doc"]
    assert "null: 1 on the CPU, 10 on CUDA" in doc
