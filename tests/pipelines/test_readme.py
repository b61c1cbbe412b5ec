"""The README's example command lines keep working: each ``python -m`` and
``python examples/`` line of its code blocks is checked, the cheap ones run
for a few steps (or on a tiny run), the costly ones composed and validated
the way ``pipelines.run`` validates before a run (every job of a sweep's
first values, a named experiment with its sweep's first point). An example
added to the README without a check here fails the test."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from helpers import CONF, ROOT, run_cli
from pipelines.config.validate import validate

README = ROOT / "README.md"


def readme_commands() -> list[str]:
    """The command lines of the README's code blocks (comments left out)."""
    text = README.read_text()
    out = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.splitlines():
            cmd = line.split("  #")[0].strip()
            for part in cmd.split("&&"):
                part = part.strip()
                if part.startswith(("python -m pipelines", "python examples/")):
                    out.append(part)
    return out


def sweep_points(args: list[str]) -> list[list[str]]:
    """The overrides of the job of a sweep's first values (each comma list of
    the command line, and of a named experiment's sweeper, at its first
    value; a glob at the config's own option)."""
    fixed = [a for a in args if a not in ("-m", "--multirun")]
    jobs = [a for a in fixed if "," not in a]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="config", overrides=jobs, return_hydra_config=True)
    params = cfg.hydra.sweeper.get("params")
    params = OmegaConf.to_container(params, resolve=True) if params is not None else {}
    values = {a.split("=", 1)[0]: a.split("=", 1)[1].split(",") for a in fixed if "," in a}
    values.update({k: str(v).split(",") for k, v in params.items() if not str(v).startswith("glob(")})
    return [jobs + [f"{k}={v[0]}" for k, v in values.items()]]


def validates(args: list[str]) -> None:
    """Each job of the command line composes and passes pipelines.run's checks."""
    for job in sweep_points(args):
        with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
            cfg = compose(config_name="config", overrides=job)
        validate(cfg, job)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A finished run of the default scene, a few steps (the replay, export
    and granular examples' input)."""
    run = tmp_path_factory.mktemp("readme") / "run"
    p = run_cli(["scene.resolution=24", "run.steps=6", "log.every=3", "log.progress=false",
                 f"hydra.run.dir={run}"], cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    return run


def tool(argv: list[str], cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *argv], cwd=cwd, capture_output=True, text=True, timeout=300)


def check(cmd: str, tiny_run, tmp_path) -> None:
    """Run or validate one README command line."""
    argv = shlex.split(cmd.replace("<run dir>", "RUN_DIR"))[1:]
    if argv[:2] == ["-m", "pipelines.run"]:
        args = argv[2:]
        validates(args)
        if not args:  # the first run of a fresh machine: for a few steps
            p = run_cli(["run.steps=3", "log.progress=false", f"hydra.run.dir={tmp_path / 'run'}"], cwd=ROOT)
            assert p.returncode == 0 and "completed: 3 steps" in p.stderr, p.stderr
        return
    if argv[:2] == ["-m", "pipelines.replay"]:
        argv = [str(tiny_run) if a == "RUN_DIR" else str(tmp_path / a) if a == "frames/" else a for a in argv]
        p = tool(argv, ROOT)
        assert p.returncode == 0 and list((tmp_path / "frames").glob("frame_*.png")), p.stderr
        return
    if argv[:2] == ["-m", "pipelines.export"]:
        fmt = argv[argv.index("--format") + 1]
        argv = [str(tiny_run) if a == "RUN_DIR" else a for a in argv]
        p = tool([*argv, "--out", str(tmp_path / fmt)], ROOT)
        written = {"vtk": "particles.pvd", "usd": "stage.usdc"}[fmt]
        assert p.returncode == 0 and (tmp_path / fmt / written).is_file(), p.stderr
        return
    if argv[:2] == ["-m", "pipelines.report"]:  # a sweep of two tiny jobs; the report is written at its end
        sweep = tmp_path / "sweep"
        p = run_cli(["-m", "material.E=5e4,1e5", "scene.resolution=16", "run.steps=2", "log.every=0",
                     "hydra/launcher=basic", f"hydra.sweep.dir={sweep}"], cwd=ROOT, timeout=300)
        assert p.returncode == 0, p.stderr
        q = tool([*argv[:2], str(sweep), "--out", str(tmp_path / "report")], ROOT)
        assert q.returncode == 0 and (tmp_path / "report" / "report.md").is_file(), q.stderr
        return
    if argv[:2] == ["-m", "pipelines.material_point"]:
        p = tool([*argv, "--steps", "20", "--out", str(tmp_path / "mp.png")], ROOT)
        assert p.returncode == 0 and (tmp_path / "mp.csv").is_file(), p.stderr
        return
    if argv[:2] == ["-m", "pipelines.granular"]:
        p = tool([*argv[:2], str(tiny_run)], ROOT)
        assert p.returncode == 0 and str(tiny_run) in p.stdout, p.stderr
        return
    if argv[:2] == ["-m", "pipelines.cfl_bound"]:
        p = tool(argv, ROOT)
        assert p.returncode == 0 and "| quadratic |" in p.stdout, p.stderr
        return
    if argv[:2] == ["-m", "pipelines.kills"]:  # minutes: tests/pipelines/test_kills.py runs it; its options exist
        p = tool([*argv[:2], "--help"], ROOT)
        assert p.returncode == 0 and all(a in p.stdout for a in argv if a.startswith("--")), p.stdout
        return
    if argv[:2] == ["-m", "pipelines.bench"] or argv[0].startswith("examples/"):
        # a benchmark takes minutes and the examples run in tests/mpm/test_examples.py: their options exist
        p = tool([*(argv[:2] if argv[0] == "-m" else argv[:1]), "--help"], ROOT)
        options = [a.split("=")[0] for a in argv if a.startswith("--")]
        assert p.returncode == 0 and all(o in p.stdout for o in options), p.stdout
        if "--only" in argv:
            from pipelines.bench.__main__ import TABLES

            assert set(argv[argv.index("--only") + 1].split(",")) <= set(TABLES)
        return
    raise AssertionError(f"no check for the README's command line {cmd!r}: add one to {__file__}")


def test_the_readme_has_examples_of_every_command():
    cmds = readme_commands()
    for entry in ("pipelines.run", "pipelines.replay", "pipelines.export", "pipelines.report", "pipelines.bench",
                  "pipelines.material_point", "pipelines.granular", "pipelines.cfl_bound", "pipelines.kills",
                  "examples/"):
        assert any(entry in c for c in cmds), entry


@pytest.mark.slow
@pytest.mark.parametrize("cmd", readme_commands())
def test_the_readme_examples_work(cmd, tiny_run, tmp_path):
    check(cmd, tiny_run, tmp_path)
