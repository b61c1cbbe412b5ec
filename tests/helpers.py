"""Shared test helpers: compose configs like the command line does, run the
command line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from hydra import compose, initialize_config_dir

from pipelines.config import schema
from pipelines.config.validate import resolve

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
DEVICE = os.environ.get("MPM_TEST_DEVICE", "cpu")  # set by conftest (pytest --device, default cpu)
# the papers' scenes (conf/scene/): each has a default and a paper size
PAPER_SCENES = {"snow_bunnies", "water_bunny", "bowl_fsi", "viscous_cup", "falling_bodies", "dam_break",
                "dam_break_water", "dam_break_2d", "sand_bodies", "bullet_tungsten", "pumpkins",
                "cookie_drop", "sandcastle", "hydrant"}
schema.register()


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

