"""Hydra multirun sweeps: launchers, one directory per job, skipping finished
jobs by config hash, the report at the end of the sweep, the named experiments."""

import json
import os
import re

import pytest

from helpers import ROOT, compose_cfg, group_options, run_cli
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf
from pipelines.run import provenance

TINY = ["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=3", "log.every=0"]
# (fracture.png only when some job tore a pair apart: three steps tear none)
REPORT_FILES = ["report.md", "runs.csv", "speed.csv", "speed.png", "fracture.csv",
                "update_cost.csv", "conservation.csv", "conservation.png"]


def _jobs(sweep):
    return sorted(p.parent for p in sweep.glob("*/metrics.json"))


def _sweep(tmp_path, launcher, extra=(), kernels="quadratic,linear"):
    sweep = tmp_path / launcher
    args = ["-m", f"hydra/launcher={launcher}", "scheme=empm,tlmpm", f"kernel={kernels}", *TINY,
            f"hydra.sweep.dir={sweep}", *extra]
    env = {**os.environ, "RAY_DEDUP_LOGS": "0"}  # Ray would fold the workers' identical lines
    p = run_cli(args, cwd=ROOT, timeout=900, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    return sweep, p


@pytest.mark.slow
@pytest.mark.parametrize("launcher", ["joblib", "ray"])
def test_tiny_sweep_runs_every_job_reports_and_skips_on_rerun(tmp_path, launcher):
    sweep, _ = _sweep(tmp_path, launcher)
    jobs = _jobs(sweep)
    assert len(jobs) == 4
    metrics = [json.loads((j / "metrics.json").read_text()) for j in jobs]
    assert {(m["scheme"], m["kernel"]) for m in metrics} == {
        (s, k) for s in ("empm", "tlmpm") for k in ("quadratic", "linear")}
    assert all(m["status"] == "completed" and m["steps"] == 3 for m in metrics)
    assert all((j / "recording.rrd").stat().st_size > 0 and (j / "final_state.npz").exists() for j in jobs)
    assert len({m["config_hash"] for m in metrics}) == 4
    for f in REPORT_FILES:  # written by the end-of-multirun callback
        assert (sweep / f).stat().st_size > 0, f
    rows = (sweep / "runs.csv").read_text().splitlines()
    assert len(rows) == 5 and "tlmpm · linear · mls" in (sweep / "report.md").read_text()
    if launcher == "ray":  # skipping on a rerun happens inside the job (pipelines.run): joblib covers it
        return

    stamps = {j: (j / "metrics.json").stat().st_mtime_ns for j in jobs}
    _, p = _sweep(tmp_path, launcher)  # the same sweep again: every job is skipped
    assert p.stderr.count("already holds this config's completed run") == 4, p.stderr[-3000:]
    assert _jobs(sweep) == jobs
    assert all((j / "metrics.json").stat().st_mtime_ns == stamps[j] for j in jobs)


@pytest.mark.slow
def test_forced_rerun_and_changed_config_run_again(tmp_path):
    sweep, _ = _sweep(tmp_path, "basic", kernels="quadratic")
    jobs = _jobs(sweep)
    assert len(jobs) == 2
    stamps = {j: (j / "metrics.json").stat().st_mtime_ns for j in jobs}
    _, p = _sweep(tmp_path, "basic", ["run.force=true"], kernels="quadratic")
    assert "skipped" not in p.stderr
    assert all((j / "metrics.json").stat().st_mtime_ns > stamps[j] for j in jobs)
    _, p = _sweep(tmp_path, "basic", ["run.steps=4"], kernels="quadratic")
    assert "skipped" not in p.stderr and len(_jobs(sweep)) == 2  # same job numbers, new results
    assert all(json.loads((j / "metrics.json").read_text())["steps"] == 4 for j in _jobs(sweep))


def test_config_hash_follows_the_computation_not_the_presentation():
    def h(overrides):
        cfg = OmegaConf.to_container(compose_cfg(overrides), resolve=True)
        return provenance.config_hash(cfg, "code")

    base = h([])
    assert h(["log.progress=false", "run.force=true", "scale=paper"]) == base
    assert h(["material.E=2e5"]) != base and h(["seed=1"]) != base
    assert provenance.config_hash(OmegaConf.to_container(compose_cfg([]), resolve=True), "other") != base
    assert len(provenance.code_hash()) == 16


def _compose(overrides, hydra=True):
    from hydra import compose, initialize_config_dir

    from helpers import CONF

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="config", overrides=overrides, return_hydra_config=hydra)


def _plain(path) -> dict:
    """A config file as plain data, nothing composed or interpolated."""
    return OmegaConf.to_container(OmegaConf.load(path), resolve=False)


SCALE_REF = re.compile(r"\$\{scale\.(\w+)(\.\$\{scene\.name\})?\}")


def _scale_references(node, path=()):
    """(path, text) of every string in an experiment file that reads the scale group."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _scale_references(v, path + (k,))
    elif isinstance(node, str) and SCALE_REF.search(node):
        yield path, node


def _at(cfg, path):
    for key in path:
        cfg = cfg[key]
    return OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else cfg


def _sweep_values(key: str, value: str) -> list[str]:
    """The values a sweep parameter takes, as Hydra's sweeper expands them
    (a glob over the group's options in conf/)."""
    override = OverridesParser.create().parse_override(f"{key}={value}")
    if type(override.value()).__name__ == "Glob":
        return override.value().filter(group_options(key.lstrip("+")))
    if override.is_sweep_override():
        return list(override.sweep_string_iterator())
    return [override.get_value_element_as_str()]


@pytest.mark.parametrize("name", group_options("experiment"))
@pytest.mark.parametrize("scale", ["default", "paper"])
def test_named_experiments_compose(name, scale):
    """Every experiment composes with both scales into the sizes of that
    scale: each value its file reads from the scale group
    (``${scale.key}``, conf/scale/<scale>.yaml read as plain data) is that
    scale's, in the sweep parameters, the sweep directory and the job's
    settings; every sweep parameter expands to at least one value, each
    option of a config group an option the definition names; and the first
    job of the sweep resolves (the sweep itself is an experiment, not a test)."""
    from pipelines.config.validate import resolve

    cfg = _compose([f"+experiment={name}", f"scale={scale}"])
    sizes = _plain(ROOT / "conf" / "scale" / f"{scale}.yaml")
    assert cfg.scale.name == scale and cfg.hydra.sweep.dir == f"multirun/{name}/{scale}"
    references = list(_scale_references(_plain(ROOT / "conf" / "experiment" / f"{name}.yaml")))
    assert references  # at least the sweep directory's ${scale.name}
    for path, text in references:
        def value(m):
            v = sizes[m.group(1)]
            return v[cfg.scene.name] if m.group(2) else v

        whole = SCALE_REF.fullmatch(text)
        expected = value(whole) if whole else SCALE_REF.sub(lambda m: str(value(m)), text)
        got = _at(cfg, path)
        if path[:3] == ("hydra", "sweeper", "params"):  # the sweeper reads its parameters as text
            got, expected = str(got), str(expected)
        assert got == expected, (path, text)
    params = OmegaConf.to_container(cfg.hydra.sweeper.params, resolve=True)
    first = []
    for key, value in params.items():
        values = _sweep_values(key, str(value))
        assert values, key
        options = group_options(key.lstrip("+"))
        if options:  # a config group: only its options
            assert set(values) <= set(options), key
        first.append(f"{key}={values[0]}")
    resolve(_compose([f"+experiment={name}", f"scale={scale}", *first], hydra=False))


GLOBS = [(name, key) for name in group_options("experiment")
         for key, value in _plain(ROOT / "conf" / "experiment" / f"{name}.yaml")["hydra"]["sweeper"]["params"].items()
         if str(value).startswith("glob(")]


@pytest.mark.parametrize("name,key", GLOBS, ids=[f"{n}-{k}" for n, k in GLOBS])
def test_experiment_globs_pick_every_option_of_the_group(name, key):
    """``glob(...)`` sweeps pick up every option Hydra finds for the group (a
    new kernel in mpm.KERNELS joins the experiments), and Hydra finds exactly
    the options the definition names: the solver's registries for the groups
    defined in code, the files for the others."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    value = _plain(ROOT / "conf" / "experiment" / f"{name}.yaml")["hydra"]["sweeper"]["params"][key]
    group = key.lstrip("+")
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        found = sorted(GlobalHydra.instance().config_loader().get_group_options(group))
    assert found == group_options(group) and found
    override = OverridesParser.create().parse_override(f"{key}={value}")
    assert sorted(override.value().filter(found)) == group_options(group)


def test_every_experiment_with_a_glob_is_checked():
    assert len({n for n, _ in GLOBS}) == 10 and len(GLOBS) == 13


@pytest.mark.slow
def test_changed_parameter_list_never_mixes_results(tmp_path):
    """Job numbers shift when a value is inserted: each directory must end up
    with its own job's result (only a job's own directory can be skipped)."""
    sweep = tmp_path / "s"
    base = ["-m", "hydra/launcher=basic", "scene=rotating_plate_2d", "scene.resolution=16", "log.every=0",
            f"hydra.sweep.dir={sweep}"]
    p = run_cli(base + ["run.steps=2,3"], cwd=ROOT)
    assert p.returncode == 0, p.stderr[-2000:]
    p = run_cli(base + ["run.steps=2,4,3"], cwd=ROOT)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stderr.count("already holds this config's") == 1  # job 0 only
    steps = {j.name: json.loads((j / "metrics.json").read_text())["steps"] for j in _jobs(sweep)}
    assert steps == {"0": 2, "1": 4, "2": 3}


@pytest.mark.slow
def test_invalid_job_in_a_sweep_says_why_the_others_run_and_the_sweep_fails(tmp_path):
    sweep = tmp_path / "s"
    p = run_cli(["-m", "scene=rotating_plate_2d", "scene.resolution=16", "run.steps=2", "log.every=0",
                 "run.cfl=0.5,2", f"hydra.sweep.dir={sweep}"], cwd=ROOT)  # joblib workers
    assert "error: run.cfl: 2.0 out of range" in p.stderr, p.stderr[-2000:]
    status = {j.name: json.loads((j / "metrics.json").read_text())["status"] for j in _jobs(sweep)}
    assert status == {"0": "completed", "1": "invalid"}
    # the sweep exits with its worst job's code and says what happened and where the report is
    assert p.returncode == 2
    assert f"sweep {sweep}: 1 completed, 1 invalid; report: {sweep / 'report.md'}" in p.stderr


LAUNCHERS = {"cores": "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher",
             "basic": "hydra._internal.core_plugins.basic_launcher.BasicLauncher",
             "joblib": "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher",
             "submitit_local": "hydra_plugins.hydra_submitit_launcher.submitit_launcher.LocalLauncher",
             "submitit_slurm": "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher",
             "ray": "hydra_plugins.hydra_ray_launcher.ray_launcher.RayLauncher"}


@pytest.mark.parametrize("name", group_options("experiment"))
def test_named_experiments_compose_with_every_launcher(name):
    """An experiment must not set options of one launcher (they fail to compose
    with the others): with every launcher it composes, the launcher is that
    one, and the jobs, the sweep parameters and the sweep directory are
    those of the default launcher."""
    def job(cfg):
        return OmegaConf.to_container(OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"]), resolve=True)

    base = _compose([f"+experiment={name}"])
    for launcher, target in LAUNCHERS.items():
        cfg = _compose([f"+experiment={name}", f"hydra/launcher={launcher}"])
        assert cfg.hydra.launcher._target_ == target
        assert cfg.hydra.sweep.dir == base.hydra.sweep.dir == f"multirun/{name}/default"
        assert cfg.hydra.sweeper.params == base.hydra.sweeper.params
        assert job(cfg) == job(base), launcher


def test_the_default_launcher_runs_one_worker_per_core():
    """The default launcher is joblib with one worker per usable core (the
    process's CPU affinity; a Warp CPU run steps on one core), and a count
    given on the command line replaces it."""
    import os

    from pipelines.config.schema import usable_cores

    cfg = _compose([])
    assert cfg.hydra.launcher._target_ == LAUNCHERS["joblib"]
    assert cfg.hydra.launcher.n_jobs == usable_cores() == len(os.sched_getaffinity(0))
    assert _compose(["hydra.launcher.n_jobs=1"]).hydra.launcher.n_jobs == 1
