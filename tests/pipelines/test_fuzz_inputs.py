"""Generated bad input for every config key and every command-line option
of every entry point: each is refused in one line (exit code 2), or
accepted, never a traceback, a hang or a half-written run directory.

The config keys are those of the composed configs of a few scenes that
between them use every kind of entry (bodies, regions, loads, colliders,
meshes, a closed-form solution, every group); each key gets values of the
wrong type, out of range, NaN and infinities, empty values, and every
mapping an unknown key. They are checked in this process through the
function ``pipelines.run`` checks a config with
(:func:`pipelines.config.validate.validate`); a few go through real
processes to check the exit code and the run directory."""

from __future__ import annotations

import contextlib
import copy
import functools
import importlib
import io
import re
import subprocess
import sys

import pytest
from hydra import compose, initialize_config_dir
from hydra._internal.config_loader_impl import ConfigLoaderImpl
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from helpers import CONF, ROOT
from pipelines.config.errors import describe
from pipelines.config.validate import ConfigError, validate
from pipelines.config.overrides import GROUPS, check_groups, replace_inline_mappings

# configs whose keys between them cover every part of the schema
BASES = {
    "default": [],
    "groups": ["integrator=implicit", "scheme=aulmpm", "material=sand", "kernel=cubic", "scene.resolution=24"],
    "regions_loads": ["scene=cantilever_2d", "scene.size=coarse"],
    "colliders": ["scene=viscous_cup"],
    "mesh": ["scene=yoyo"],
    "solution": ["scene=vibrating_bar_2d"],
}
NUMBER_BAD = ["abc", "nan", "'[1, 2]'", "{a: 1}", "true"]  # refused wherever a number is expected
NUMBER_ODD = ["-inf", "-1", "0", "1e400", "null"]  # refused or accepted, never a traceback
BOOL_BAD = ["abc", "2", "0", "[true]", "nan"]
TEXT_ODD = ["''", "no_such_value", "1", "null", "{a: 1}"]
LIST_BAD = ["abc", "[abc]", "[nan]", "[[1]]", "{a: 1}"]
LIST_ODD = ["[]", "[1, 2, 3, 4]", "[inf, 0]", "[-1, -1]"]
MAP_ODD = ["abc", "[]", "{}", "null", "1"]


PARSER = OverridesParser.create()


@functools.cache
def composed(base: str):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="config", overrides=BASES[base])


def outcome(base: str, extra: list[str]) -> tuple[str, str]:
    """("accepted", warnings) or ("refused", the one-line message), as
    ``pipelines.run`` ends before its run; raises what it would not describe
    (a traceback on the command line). Overrides of keys are applied to the
    base's composed config by Hydra's own code, as composing applies them
    (group overrides compose afresh)."""
    overrides = replace_inline_mappings(extra)
    try:
        check_groups(overrides)
        if any(o.split("=")[0].lstrip("+~") in GROUPS for o in overrides):
            with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
                cfg = compose(config_name="config", overrides=BASES[base] + overrides)
        else:
            cfg = copy.deepcopy(composed(base))
            ConfigLoaderImpl._apply_overrides_to_config(PARSER.parse_overrides(overrides), cfg)
        _, warnings = validate(cfg, overrides)
        return "accepted", "\n".join(warnings)
    except ConfigError as e:
        return "refused", str(e)
    except Exception as e:  # noqa: BLE001 - what the command line describes in one line, else a traceback
        message = describe(e)
        if message is None:
            raise
        return "refused", message


def leaves(node, path: str = ""):
    """(dotted key, value) of every leaf and (dotted key, None) of every
    mapping of a plain config, lists indexed by number."""
    if isinstance(node, dict):
        yield path, None
        for k, v in node.items():
            yield from leaves(v, f"{path}.{k}" if path else str(k))
    elif isinstance(node, list) and node and all(isinstance(x, dict) for x in node):
        for i, v in enumerate(node):
            yield from leaves(v, f"{path}.{i}")
    else:
        yield path, node


def resolved(cfg, key: str):
    try:
        return OmegaConf.select(cfg, key, throw_on_resolution_failure=False)
    except Exception:  # noqa: BLE001 - an interpolation into another scene's size: not a value to type
        return None


def cases(base: str, skip: set[str]) -> list[tuple[list[str], str, str]]:
    """(overrides, key, what is expected: "refused" or "any") for every key of
    the config of ``base``, keys already in ``skip`` left out."""
    cfg = composed(base)
    size = cfg.scene.get("size")
    out = []
    plain = OmegaConf.to_container(cfg, resolve=False)
    plain.pop("hydra", None)
    for key, value in leaves(plain):
        pattern = re.sub(r"\.\d+(?=\.|$)", ".0", key)  # the first element of a list stands for the others
        if pattern in skip or (key.startswith(("scale.", "scene.sizes.")) and value is not None):
            continue  # the values of sizes: read through the scene's interpolations, checked there
        skip.add(pattern)
        v = resolved(cfg, key) if key else cfg
        if value is None and (key == "" or OmegaConf.is_dict(v)):  # a mapping: an unknown key
            unknown = f"{key}.no_such_key" if key else "no_such_key"
            # a new size is a size to choose (scene.size), and only the chosen size's keys are read
            free = key == "scene.sizes" or (key.startswith("scene.sizes.") and key != f"scene.sizes.{size}")
            out.append(([f"+{unknown}=1"], unknown, "any" if free else "refused"))
            if key:
                out += [([f"{key}={x}"], key, "any") for x in MAP_ODD]
            continue
        if isinstance(v, bool):
            out += [([f"{key}={x}"], key, "refused") for x in BOOL_BAD]
        elif isinstance(v, (int, float)):
            out += [([f"{key}={x}"], key, "refused") for x in NUMBER_BAD]
            out += [([f"{key}={x}"], key, "any") for x in NUMBER_ODD]
        elif OmegaConf.is_list(v) and v and all(isinstance(x, (int, float)) for x in v):
            out += [([f"{key}={x}"], key, "refused") for x in LIST_BAD]
            out += [([f"{key}={x}"], key, "any") for x in LIST_ODD]
        elif isinstance(v, str) or v is None or OmegaConf.is_list(v):
            out += [([f"{key}={x}"], key, "any") for x in TEXT_ODD + LIST_ODD]
    return out


@functools.cache
def all_cases() -> dict[str, list]:
    """Every base's cases, each key once (in the first base that has it)."""
    skip: set[str] = set()
    return {name: cases(name, skip) for name in BASES}


def check_one(base: str, overrides: list[str], key: str, expected: str) -> str | None:
    """Why this case fails (None: it passes)."""
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            result, text = outcome(base, overrides)
    except Exception as e:  # noqa: BLE001 - the failure this test looks for
        return f"{type(e).__name__}: {e}"
    if result == "refused":
        if "\n" in text or not text.strip():
            return f"not one line: {text!r}"
        names = {key.split(".")[-1], key.split(".")[0]}
        if not any(n in text for n in names):
            return f"does not name {key}: {text}"
    elif expected == "refused":
        return "accepted"
    return None


@pytest.mark.parametrize("base", [pytest.param(b, marks=pytest.mark.slow) if b in ("default", "regions_loads", "colliders")
                                  else b for b in BASES])
def test_every_config_key_refuses_bad_values_in_one_line(base):
    generated = all_cases()[base]
    assert len(generated) > (20 if base != "default" else 200)
    wrong = {" ".join(o): why for o, key, exp in generated if (why := check_one(base, o, key, exp))}
    assert not wrong, "\n".join(f"{k}: {v}" for k, v in sorted(wrong.items()))


# ------------------------------------------------------------------ the other entry points' options
MAINS = {"pipelines.replay": "pipelines.replay", "pipelines.export": "pipelines.export.command",
         "pipelines.report": "pipelines.report",
         "pipelines.material_point": "pipelines.material_point", "pipelines.bench": "pipelines.bench.__main__",
         "pipelines.granular": "pipelines.report.sections.granular", "pipelines.cfl_bound": "pipelines.cfl_bound",
         "pipelines.bench.gpu_kit": "pipelines.bench.gpu_kit"}


def tool_main(module: str):
    """The main(argv) that ``python -m module`` calls."""
    return importlib.import_module(MAINS[module]).main


def call(module: str, argv: list[str]) -> tuple[int, str]:
    """(exit code, stderr) of ``python -m module argv``, in this process."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = tool_main(module)(argv) or 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else 1
    return code, err.getvalue()


def options_of(module: str) -> set[str]:
    """The options its --help lists."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        try:
            tool_main(module)(["--help"])
        except SystemExit:
            pass
    return set(re.findall(r"(?<![\w-])(--[a-z][\w-]*)", out.getvalue())) - {"--help"}


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    """A finished tiny run, a plain file, a directory, a missing path."""
    from helpers import spec_for
    from pipelines.run.runner import execute

    root = tmp_path_factory.mktemp("tools")
    execute(spec_for(["scene.resolution=16", "run.steps=2", "log.every=1"]), root / "run")
    (root / "file.txt").write_text("not a mesh, a run or a recording\n")
    (root / "dir").mkdir()
    return {"run": str(root / "run"), "file": str(root / "file.txt"), "dir": str(root / "dir"),
            "missing": str(root / "missing" / "deeper")}


# per entry point: what comes before the options, and per option the values it must refuse
# ({file}, {dir}, {missing}, {run} are paths); "=1" on a flag gives it a value it does not take
TOOLS = {
    "pipelines.replay": (["{run}"], {
        "--web": ["--web=1"], "--reproduce": ["--reproduce=1"], "--repair": ["--repair=yes"],
        "--frames": ["--frames {file}", "--frames"], "--every": ["--every 0", "--every -3", "--every abc"],
        "--view": ["--view abc", "--view 2d"], "--color": ["--color no_such_field --frames {dir}/f"],
        "--elev": ["--elev nan", "--elev inf", "--elev abc"], "--azim": ["--azim nan", "--azim -inf", "--azim x"],
    }),
    "pipelines.export": (["{run}", "--format", "usd"], {
        "--format": ["--format abc", "--format ply", "--format"], "--every": ["--every 0", "--every -3", "--every abc"],
        "--out": ["--out {file}", "--out"],
    }),
    "pipelines.report": (["{dir}"], {"--out": ["--out {file}", "--out"]}),
    "pipelines.material_point": ([], {
        "--path": ["--path abc"], "--strain": ["--strain nan", "--strain inf", "--strain abc"],
        "--steps": ["--steps 0", "--steps -1", "--steps 1.5", "--steps 10000000000"],
        "--rate": ["--rate 0", "--rate -1", "--rate nan", "--rate inf"], "--dim": ["--dim 4", "--dim abc"],
        "--cycle": ["--cycle=1"], "--out": ["--out {file}", "--out {dir}", "--out {missing}.png", "--out"],
    }),
    "pipelines.bench": ([], {
        "--steps": ["--steps 0", "--steps abc"], "--cold": ["--cold=1"], "--json": ["--json {dir}", "--json {file}"],
        "--paper": ["--paper=1"], "--scaling": ["--scaling=1"], "--only": ["--only abc", "--only speed,abc"],
        "--large": ["--large=1"], "--sweep": ["--sweep=1"], "--no-recording": ["--no-recording=1"],
        "--device": ["--device tpu"], "--profile-sizes": ["--profile-sizes 1K", "--profile-sizes 4"],
        "--genesis-python": ["--genesis-python {missing}", "--genesis-python {dir}", "--genesis-python {file}"],
        **{f"--no-{t}": [f"--no-{t}=1"] for t in (
            "peers", "schemes", "updates", "kernels", "materials", "integrators", "fused", "sync", "stages", "profile",
            "precision")},
    }),
    "pipelines.cfl_bound": ([], {
        "--dim": ["--dim 4", "--dim abc"], "--per-axis": ["--per-axis 0", "--per-axis abc"],
        "--nu": ["--nu nan", "--nu 0.5", "--nu abc"],
    }),
    "pipelines.granular": ([], {}),
    "pipelines.bench.gpu_kit": (["unpack"], {
        "--dir": ["--dir {missing}", "--dir {file}"], "--out": ["--out {file}"], "--quick": ["--quick=1"],
    }),
}
POSITIONAL = {  # bad positional arguments
    "pipelines.replay": ["{file}", "{missing}", "{dir}", "{run}/recording.timings.rrd"],
    "pipelines.export": ["{file}", "{missing}", "{dir}", "{run}/recording.timings.rrd"],  # (each without --format)
    "pipelines.report": ["{file}", "{missing}"],
    "pipelines.material_point": ["scene.resolution=8", "material.E=nan", "material=steel", "material.nope=1"],
    "pipelines.bench": ["no_such_case"],
    "pipelines.granular": ["{file}", "{missing}", "{dir}"],
    "pipelines.cfl_bound": ["extra", "scene=nope", "scene=water_bunny", "scene.resolution=abc"],
    "pipelines.bench.gpu_kit": ["nope", "session"],
}


@pytest.mark.parametrize("module", list(TOOLS))
def test_every_option_of_every_entry_point_refuses_bad_values_in_one_line(module, paths):
    before, table = TOOLS[module]
    listed = options_of(module)
    assert listed == set(table), f"options without bad values here: {listed - set(table)}"
    argvs = [[a.format(**paths) for a in before] + v.format(**paths).split() for vs in table.values() for v in vs]
    argvs += [[a.format(**paths)] for a in POSITIONAL[module]]
    wrong = {}
    for argv in argvs:
        code, err = call(module, argv)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        if code != 2 or len(lines) != 1 or not lines[0].startswith("error: ") or "Traceback" in err:
            wrong[" ".join(argv)] = f"exit {code}: {err.strip()[-300:]}"
    assert not wrong, "\n".join(f"{k}: {v}" for k, v in wrong.items())


# ------------------------------------------------------------------ a few through real processes
RUN_CASES = [
    ["scene=cantilever_2d", "scene.loads.0.select.center=[0.2,0.1]"],
    ["scene=cantilever_2d", "scene.regions.0.select.half_size=[0.001,0.001]"],
    ["scene.bodies.0.shape.radius=0.0005"],
    ["scene=yoyo", "scene.bodies.0.shape.parts.0.mesh=tests"],
    ["integrator=implicit", "integrator.cg_max=many"],
    ["+scale.no_such_key=1"],
    ["log.dJ=2"],
    ["scene=null"],
]


@pytest.mark.slow
def test_bad_input_in_real_processes_leaves_no_run_directory(tmp_path, paths):
    """The exit code, the one line and no run directory, through real
    processes: the command lines of pipelines.run in one process
    (tests/cli_batch.py), and one per other entry point."""
    import json

    runs = [args + [f"hydra.run.dir={tmp_path / str(i)}"] for i, args in enumerate(RUN_CASES)]
    (tmp_path / "in.json").write_text(json.dumps(runs))
    p = subprocess.run([sys.executable, str(ROOT / "tests" / "cli_batch.py"), str(tmp_path / "in.json"),
                        str(tmp_path / "out.json")], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    results = [(code, err) for code, err in json.loads((tmp_path / "out.json").read_text())]
    tools = [["pipelines.material_point", "--strain", "nan"], ["pipelines.replay", paths["run"], "--frames", paths["file"]],
             ["pipelines.report", paths["dir"], "--out", paths["file"]]]
    for argv in tools:
        q = subprocess.run([sys.executable, "-m", *argv], cwd=ROOT, capture_output=True, text=True, timeout=300)
        results.append((q.returncode, q.stderr))
    wrong = {}
    for i, (argv, (code, err)) in enumerate(zip(RUN_CASES + tools, results)):
        lines = [ln for ln in err.splitlines() if ln.strip()]
        if code != 2 or len(lines) != 1 or not lines[0].startswith("error: ") or (tmp_path / str(i)).exists():
            wrong[" ".join(argv)] = f"exit {code}: {err.strip()[-300:]}"
    assert not wrong, "\n".join(f"{k}: {v}" for k, v in wrong.items())
