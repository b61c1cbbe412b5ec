"""Runs per hour of a local sweep: the bench's ``sweep`` table
(``python -m pipelines.bench --only sweep``).

A Warp CPU run steps on one core, so a machine with N cores runs N jobs of a
sweep side by side (the default launcher, ``conf/hydra/launcher/cores.yaml``,
starts one worker per core). The table times the same sweep of 2N identical
jobs (the 2D elastic ball, ``seed`` swept, logging off, the sweep report
left out) as whole ``python -m pipelines.run -m`` commands, once with one
worker and once with N: wall time, runs per hour and their ratio. The jobs'
kernels come from the cache (a warm-up job compiles them first).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from ..config.schema import usable_cores

CASE = ["scene=elastic_ball_2d", "scene.resolution=64", "run.duration=0.5", "log.every=0", "log.scalars=false",
        "log.progress=false", "~hydra.callbacks.report"]


def _sweep(workdir: Path, jobs: int, workers: int) -> float:
    """Wall time [s] of one sweep of ``jobs`` jobs on ``workers`` workers."""
    cmd = [sys.executable, "-m", "pipelines.run", "-m", *CASE, "seed=" + ",".join(map(str, range(jobs))),
           f"hydra.launcher.n_jobs={workers}", f"hydra.sweep.dir={workdir / f'sweep_{workers}'}"]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {r.returncode}: {r.stderr[-1000:]}")
    return wall


def bench_sweep(workdir: Path, cores: int | None = None) -> list[dict]:
    """The sweep of 2N jobs with 1 and N workers (N: the usable cores)."""
    n = cores or usable_cores()
    jobs = 2 * n
    _sweep(workdir / "warm", 1, 1)  # compiles (or loads) the kernels
    rows = []
    for workers in sorted({1, n}):
        wall = _sweep(workdir, jobs, workers)
        rows.append({"cores": n, "jobs": jobs, "workers": workers, "wall_s": wall, "runs_per_hour": 3600 * jobs / wall})
    for r in rows:
        r["vs_one"] = r["runs_per_hour"] / rows[0]["runs_per_hour"]
    return rows


def print_sweep(rows: list[dict]) -> None:
    print(f"\nsweep: {rows[0]['jobs']} jobs of the 2D ball (64^2, 0.5 s, logging off) on {rows[0]['cores']} "
          f"usable cores, whole `python -m pipelines.run -m` commands")
    print(f"{'workers':>7} {'wall s':>7} {'runs/hour':>9} {'vs 1 worker':>11}")
    for r in rows:
        print(f"{r['workers']:>7} {r['wall_s']:>7.1f} {r['runs_per_hour']:>9.0f} {r['vs_one']:>10.2f}x")
