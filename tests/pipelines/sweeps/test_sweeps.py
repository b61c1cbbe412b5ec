"""Hydra multirun sweeps: launchers, one directory per job, skipping finished
jobs by config hash, the report at the end of the sweep, the named experiments."""

import json
import os

import pytest

from helpers import ROOT, compose_cfg, group_options, run_cli
from omegaconf import OmegaConf
from pipelines.run import provenance

TINY = ["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=3", "log.every=0"]
REPORT_FILES = ["report.md", "runs.csv", "speed.csv", "speed.png", "fracture.csv", "fracture.png",
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


@pytest.mark.parametrize("name", group_options("experiment"))
@pytest.mark.parametrize("scale", ["default", "paper"])
def test_named_experiments_compose(name, scale):
    """Every experiment composes with both scales; its sweep parameters and
    settings resolve (the sweep itself is an experiment, not a test)."""
    from hydra import compose, initialize_config_dir

    from helpers import CONF

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"+experiment={name}", f"scale={scale}"],
                      return_hydra_config=True)
    params = OmegaConf.to_container(cfg.hydra.sweeper.params, resolve=True)
    assert params and all(isinstance(v, str) and v for v in params.values())
    assert cfg.hydra.sweep.dir == f"multirun/{name}/{scale}"
    from pipelines.config.validate import resolve

    cfg_job = compose_cfg([f"+experiment={name}", f"scale={scale}"])
    resolve(cfg_job)  # the experiment's own settings are valid


@pytest.mark.parametrize("name", group_options("experiment"))
def test_experiment_globs_pick_every_option_of_the_group(name):
    """``glob(...)`` sweeps pick up every option Hydra finds for the group (a
    new kernel in mpm.KERNELS joins the experiments), and Hydra finds exactly
    the options the definition names: the solver's registries for the groups
    defined in code, the files for the others."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    cfg = OmegaConf.load(ROOT / "conf" / "experiment" / f"{name}.yaml")
    params = OmegaConf.to_container(cfg.hydra.sweeper.params, resolve=False)
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        loader = GlobalHydra.instance().config_loader()
        for key, value in params.items():
            if not str(value).startswith("glob("):
                continue
            group = key.lstrip("+")
            found = sorted(loader.get_group_options(group))
            assert found == group_options(group)
            override = OverridesParser.create().parse_override(f"{key}={value}")
            assert sorted(override.value().filter(found)) == group_options(group)


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


@pytest.mark.parametrize("name", group_options("experiment"))
@pytest.mark.parametrize("launcher", ["basic", "joblib", "submitit_local", "submitit_slurm", "ray"])
def test_named_experiments_compose_with_every_launcher(name, launcher):
    """An experiment must not set options of one launcher (they fail to compose
    with the others)."""
    from hydra import compose, initialize_config_dir

    from helpers import CONF

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"+experiment={name}", f"hydra/launcher={launcher}"],
                      return_hydra_config=True)
    assert cfg.hydra.sweep.dir == f"multirun/{name}/default"
