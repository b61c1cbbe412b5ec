"""Shared test helpers: compose configs like the command line does, read
recordings back."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir

from pipelines import schema
from pipelines.validate import resolve

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
schema.register()


def group_options(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF / group).glob("*.yaml"))


def compose_cfg(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="config", overrides=overrides)


def spec_for(overrides: list[str]):
    return resolve(compose_cfg(overrides))


def run_cli(args: list[str], cwd: Path, timeout: float = 600, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pipelines.run", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout, **kw)


def read_recording(path: Path):
    """(particles dataframe indexed by step, scalar dict name -> (steps, values), store)."""
    from rerun.chunk import RrdReader

    store = RrdReader(str(path)).store()
    data = store.stream().collect()
    particles = data.reader(index="step", contents="/particles").to_pandas()
    scalars_df = data.reader(index="step", contents="/scalars/**").to_pandas()
    scalars = {}
    for col in scalars_df.columns:
        if col.startswith("/scalars/"):
            name = col.split("/")[2].split(":")[0]
            s = scalars_df[["step", col]].dropna()
            scalars[name] = (s["step"].to_numpy(), np.array([v[0] for v in s[col]]))
    props = data.reader(index=None, contents="/__properties/**").to_pandas()
    return particles, scalars, props
