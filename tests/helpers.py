"""Shared test helpers: compose configs like the command line does, run the
command line."""

from __future__ import annotations

import functools
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

from hydra import compose, initialize_config_dir

from pipelines.config import schema
from pipelines.config.validate import resolve

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
EXAMPLES = ROOT / "examples"
DEVICE = os.environ.get("MPM_TEST_DEVICE", "cpu")  # set by conftest (pytest --device, default cpu)
# the papers' scenes (conf/scene/): each has a default and a paper size
PAPER_SCENES = {"snow_bunnies", "water_bunny", "bowl_fsi", "viscous_cup", "falling_bodies", "dam_break",
                "dam_break_water", "dam_break_2d", "sand_bodies", "bullet_tungsten", "pumpkins",
                "cookie_drop", "sandcastle", "hydrant"}
schema.register()


@functools.cache
def load_example(name: str):
    """An example as a module, loaded by path. Its folder goes on the path
    first, as when Python runs it as a script (the scripts share examples/_args.py)."""
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # (a dataclass resolves its annotations through it)
    spec.loader.exec_module(module)
    return module


def run_example(name: str, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    """``python examples/<name>.py args``. A script's own folder comes first
    on its path, not the working directory: PYTHONPATH names the checkout,
    so that the script imports this checkout's packages (as the tests do),
    not another installed copy."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py"), *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=env)


def group_options(group: str) -> list[str]:
    """The options of a config group: defined in code (material, scheme,
    integrator, kernel) or files in conf/<group>/."""
    return schema.options(group)


def compose_cfg(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="config", overrides=overrides)


def spec_for(overrides: list[str]):
    return resolve(compose_cfg(overrides))


def run_cli(args: list[str], cwd: Path, timeout: float = 600, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pipelines.run", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout, **kw)

