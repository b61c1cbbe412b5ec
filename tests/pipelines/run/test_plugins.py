"""The command line with materials and kernels defined outside ``mpm``
(pipelines.config.plugins, docs/extending.md): a dotted path runs, is
recorded and reproduced; ``MPM_PLUGINS`` makes registered names options, in
a sweep's worker processes too; every problem is one line naming the key,
with exit code 2, before anything is compiled."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import ROOT, run_cli
from pipelines.config import plugins
from pipelines.config.fields import ConfigError

SMALL = ["scene.resolution=16", "run.steps=3", "log.progress=false"]
MODULES = {  # written into a folder on PYTHONPATH
    "bad_models.py": """
import dataclasses

from examples.my_models import MY_QUADRATIC, MyNeoHookean


@dataclasses.dataclass
class Clash(MyNeoHookean):
    name = "neo_hookean"


@dataclasses.dataclass
class TooMany(MyNeoHookean):
    name = "too_many"

    def packed(self):
        return (1.0,) * 9


CLASH_KERNEL = dataclasses.replace(MY_QUADRATIC, name="cubic")
NOT_A_KERNEL = 3
""",
    "broken_models.py": "raise RuntimeError('boom')\n",
    "missing_dependency.py": "import nosuch_dependency\n",
    "decorated_clash.py": """
import dataclasses

from examples.my_models import MyNeoHookean
from mpm.materials import register_material


@register_material
@dataclasses.dataclass
class Again(MyNeoHookean):
    name = "fixed_corotated"
""",
    "plain_models.py": """
import dataclasses

from examples.my_models import MyNeoHookean


@dataclasses.dataclass
class PlainNeo(MyNeoHookean):  # not registered by its module: the dotted path registers it
    name = "plain_neo"
""",
}
ACCEPTED_MATERIAL = "accepted: a registered material (fixed_corotated, neo_hookean, "
# (arguments, the start of the one stderr line after "error: "; None: the command succeeds)
CASES = [  # in one process, in this order: the first before any model is registered
    (["material=nosuch"], "material=nosuch: unknown option; accepted: fixed_corotated, fluid, nacc, neo_hookean, "
                          "sand, snow, viscoplastic, viscous, von_mises, or the dotted path of an mpm.Material "
                          "subclass (package.module.Class)"),
    (["material=examples.nosuch.Model"],
     f"material: examples.nosuch.Model: no module named 'examples.nosuch'; {ACCEPTED_MATERIAL}"),
    (["material=examples.my_models.Nope"], "material: examples.my_models.Nope: module examples.my_models has no "
                                           f"Nope; {ACCEPTED_MATERIAL}"),
    (["material=examples.my_models.MY_QUADRATIC"], "material: examples.my_models.MY_QUADRATIC: a Kernel, not an "
                                                   f"mpm.Material subclass; {ACCEPTED_MATERIAL}"),
    (["kernel=examples.my_models.MyNeoHookean"], "kernel: examples.my_models.MyNeoHookean: the class MyNeoHookean, "
                                                 "not an mpm.Kernel; accepted: a registered kernel (linear, "),
    (["material=bad_models.Clash"], "material: bad_models.Clash: name 'neo_hookean' is taken by "
                                    "mpm.materials.neo_hookean.NeoHookean; accepted: a name not in"),
    (["material=bad_models.TooMany"], "material: bad_models.TooMany: packed() gives 9 values; accepted: at most "
                                      "N_MATERIAL_PARAMS = 8"),
    (["kernel=bad_models.CLASH_KERNEL"], "kernel: bad_models.CLASH_KERNEL: name 'cubic' is taken by "
                                         "mpm.kernels.cubic.CUBIC; accepted: a name not in"),
    (["kernel=bad_models.NOT_A_KERNEL"], "kernel: bad_models.NOT_A_KERNEL: an int, not an mpm.Kernel"),
    (["material=broken_models.Model"], "material: broken_models.Model: importing broken_models failed "
                                       "(RuntimeError: boom); accepted:"),
    (["material=missing_dependency.Model"], "material: missing_dependency.Model: importing missing_dependency "
                                            "failed: No module named 'nosuch_dependency'; accepted:"),
    (["material=decorated_clash.Again"], "material: decorated_clash.Again: importing decorated_clash failed "
                                         "(ValueError: material decorated_clash.Again: name 'fixed_corotated' is "
                                         "taken by mpm.materials.fixed_corotated.FixedCorotated"),
    (["-m", "material=examples.nosuch.Model,neo_hookean"], "material: examples.nosuch.Model: no module named"),
    (["material=examples.my_models.MyNeoHookean", "material.E=-1"], "material.E: -1.0 out of range; accepted: 0.0 < E"),
    (["kernel=examples.my_models.MY_QUADRATIC", "run.plan=true"], None),  # a dotted kernel: nothing compiled
]


def _write_modules(folder):
    folder.mkdir()
    for name, text in MODULES.items():
        (folder / name).write_text(text)
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), os.environ.get("PYTHONPATH", "")])}


def test_bad_plugins_are_one_line_and_exit_2(tmp_path):
    """Each case through pipelines.run's main as from a fresh process, all
    in one process (tests/cli_batch.py), the modules importable from
    PYTHONPATH: exit code 2, one stderr line, no traceback, no run or sweep
    directory left."""
    env = _write_modules(tmp_path / "modules")
    argv = [args + [f"hydra.run.dir={tmp_path / str(i)}", f"hydra.sweep.dir={tmp_path / str(i)}"]
            for i, (args, _) in enumerate(CASES)]
    (tmp_path / "in.json").write_text(json.dumps(argv))
    p = subprocess.run([sys.executable, str(ROOT / "tests" / "cli_batch.py"), str(tmp_path / "in.json"),
                        str(tmp_path / "out.json")], cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, p.stderr
    wrong = []
    for i, ((args, message), (code, stderr)) in enumerate(zip(CASES, json.loads((tmp_path / "out.json").read_text()))):
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        if message is None:
            ok = code == 0 and "error" not in stderr
        else:
            ok = (code == 2 and len(lines) == 1 and lines[0].startswith(f"error: {message}")
                  and not (tmp_path / str(i)).exists())
        if not ok:
            wrong.append(f"{' '.join(args)}: exit {code}: {stderr}")
    assert not wrong, "\n".join(wrong)


def test_a_plugin_module_that_does_not_import_is_one_line():
    with pytest.raises(ConfigError) as e:
        plugins.load_env({"MPM_PLUGINS": "json, nosuch_module"})
    assert str(e.value) == ("MPM_PLUGINS: nosuch_module: no module named 'nosuch_module'; accepted: a "
                            "comma-separated list of modules, importable from the working directory or PYTHONPATH, "
                            "that register materials or kernels")


def test_a_dotted_material_runs_is_recorded_and_reproduced(tmp_path):
    """``material=examples.my_models.MyNeoHookean``: a short run completes;
    the overrides and the group choices keep the dotted path, metrics.json
    and the recording say where the model came from, the resolved config
    holds its keys; replay --reproduce re-runs it to the same bits."""
    from pipelines import replay
    from pipelines.recording import recordings

    run = tmp_path / "run"
    p = run_cli(["material=examples.my_models.MyNeoHookean", "material.E=2e5", *SMALL, f"hydra.run.dir={run}"],
                cwd=ROOT, timeout=600)
    assert p.returncode == 0, p.stderr
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "completed" and metrics["steps"] == 3
    assert metrics["plugins"] == {"material my_neo_hookean": "examples.my_models.MyNeoHookean"}
    props = recordings.read(run / "recording.rrd").properties
    assert "material=examples.my_models.MyNeoHookean" in props["config:choices"]
    assert "material=examples.my_models.MyNeoHookean" in props["config:overrides"]
    assert props["provenance:plugins"] == ["material my_neo_hookean = examples.my_models.MyNeoHookean"]
    assert "model: my_neo_hookean" in props["config:yaml"][0] and "E: 200000.0" in props["config:yaml"][0]
    again = replay.reproduce(run / "recording.rrd", workdir=tmp_path)
    assert again["match"], again


def test_registered_names_from_mpm_plugins():
    """With MPM_PLUGINS naming the example, its names are options of the
    groups; the plan builds the scene and compiles nothing."""
    env = {**os.environ, "MPM_PLUGINS": "examples.my_models"}
    p = run_cli(["material=my_neo_hookean", "kernel=my_quadratic", "run.plan=true"], cwd=ROOT, timeout=300, env=env)
    assert p.returncode == 0, p.stderr
    assert "my_quadratic kernel" in p.stdout.splitlines()[0] and "note:" not in p.stderr
    # in a process of its own (the registries are per process): the names compose into the plugin's own
    # class and kernel, recorded as the user's
    code = ("import sys; sys.path[:0] = ['tests', '.']\n"
            "from helpers import spec_for\n"
            "from pipelines.config import plugins, schema\n"
            "assert plugins.load_env() == ['examples.my_models']\n"
            "schema.register()\n"
            "spec = spec_for(['material=my_neo_hookean', 'kernel=my_quadratic'])\n"
            "example = sys.modules['examples.my_models']\n"
            "assert type(spec.scene.bodies[0].material) is example.MyNeoHookean\n"
            "assert spec.kernel is example.MY_QUADRATIC\n"
            "print(sorted(plugins.origins(spec.scene, spec.kernel).items()))\n")
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip().splitlines()[-1] == str(sorted({
        "material my_neo_hookean": "examples.my_models.MyNeoHookean",
        "kernel my_quadratic": "examples.my_models.MY_QUADRATIC"}.items()))


@pytest.mark.slow
@pytest.mark.bitwise
def test_a_sweep_runs_plugins_in_its_worker_processes(tmp_path):
    """A two-job sweep on the joblib launcher (each job in a worker
    process): one job names a model registered by MPM_PLUGINS, the other a
    dotted path to a class its module does not register; both complete, with
    the same bits (the second subclasses the first)."""
    env = _write_modules(tmp_path / "modules")
    env["MPM_PLUGINS"] = "examples.my_models"
    sweep = tmp_path / "sweep"
    p = run_cli(["-m", "material=my_neo_hookean,plain_models.PlainNeo", *SMALL, "log.every=0",
                 f"hydra.sweep.dir={sweep}"], cwd=ROOT, timeout=600, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    jobs = [sweep / "0", sweep / "1"]
    metrics = [json.loads((j / "metrics.json").read_text()) for j in jobs]
    assert [m["status"] for m in metrics] == ["completed", "completed"]
    assert metrics[1]["plugins"] == {"material plain_neo": "plain_models.PlainNeo"}
    a, b = (np.load(j / "final_state.npz") for j in jobs)
    assert all(np.array_equal(a[k], b[k]) for k in ("x", "v"))
