"""The checkpoint table of ``python -m pipelines.bench`` (``--only checkpoint``):
what a checkpoint costs and how soon a resumed run steps again, on the
default scene (the 2D ball, ``python -m pipelines.run``) and on the 3D ball
at over 100K particles, each run as ``pipelines.run`` runs it (its own
process, the default logging).

A run writes a checkpoint after every step (``run.checkpoint_every`` below
one step): the mean write's wall time and the file's size, against the
median step. At the default interval (``run.checkpoint_every=null``: every
:data:`pipelines.run.checkpoints.AUTO_WALL_S` s of wall time, at least
:data:`pipelines.run.checkpoints.AUTO_COST` writes' time) the writes take
``write / interval`` of the run. The run is then left as a kill leaves it
(``metrics.json`` "running") and continued from its newest checkpoint
(``run.resume=true``, one step left): the resumed process's wall time less
its compilation (the kernel cache's load: run it warm) and its step is its
start-up, against a fresh one-step run's."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from ..run import checkpoints

CASES = {
    "ball_2d (default)": ([], 20),
    "ball_3d (100K+)": (["scene=elastic_ball_3d", "scene.resolution=74"], 6),
}
"""name -> (overrides, steps)"""


def _run(args: list[str], run_dir: Path) -> tuple[dict, float]:
    """``python -m pipelines.run`` in a process: its metrics and wall time [s]."""
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "pipelines.run", *args, "log.progress=false", f"hydra.run.dir={run_dir}"],
                       capture_output=True, text=True)
    wall = time.monotonic() - t0
    if p.returncode != 0:
        raise RuntimeError(f"pipelines.run {' '.join(args)} exited {p.returncode}: {p.stderr.strip()[-300:]}")
    return json.loads((run_dir / "metrics.json").read_text()), wall


def bench_checkpoint(workdir: Path) -> list[dict]:
    rows = []
    for case, (over, steps) in CASES.items():
        tag = case.split()[0]
        fresh, fresh_wall = _run([*over, "run.steps=1", "run.checkpoint_every=0"], workdir / f"ckpt_{tag}_fresh")
        run_dir = workdir / f"ckpt_{tag}"
        m, _ = _run([*over, f"run.steps={steps}", "run.checkpoint_every=1e-9"], run_dir)
        write, step = m["checkpoint_write_s"], m["step_time_ms"] * 1e-3
        (run_dir / "metrics.json").write_text(json.dumps({**m, "status": "running"}))  # as a kill leaves it
        r, wall = _run([*over, f"run.steps={steps}", "run.checkpoint_every=1e-9", "run.resume=true"], run_dir)
        interval = max(checkpoints.AUTO_WALL_S, checkpoints.AUTO_COST * write)
        rows.append({"case": case, "particles": m["particles"], "step_ms": step * 1e3, "write_s": write,
                     "bytes": m["checkpoint_bytes"], "writes_per_step": write / step, "interval_s": interval,
                     "fraction": write / interval, "resume_s": r.get("resume_s"),
                     "resumed_wall_s": wall, "resumed_compile_s": r["resume_compile_s"],
                     "resumed_startup_s": wall - r["resume_compile_s"] - step,
                     "fresh_startup_s": fresh_wall - fresh["compile_time_s"] - step,
                     "resumed_at": r.get("resumed_at")})
    return rows


def print_checkpoint(rows: list[dict]) -> None:
    print("\ncheckpoints: one write after every step (mean), the default interval's share of the run, and a "
          "resumed process's start-up beyond compilation (one step left) against a fresh one-step run's")
    print(f"{'case':<18} {'particles':>9} {'ms/step':>8} {'write s':>8} {'MB':>6} {'steps':>6} {'interval s':>10} "
          f"{'share':>7} {'restore s':>9} {'resumed s':>9} {'compile s':>9} {'start-up s':>10} {'fresh s':>8}")
    for r in rows:
        print(f"{r['case']:<18} {r['particles']:>9,} {r['step_ms']:>8.2f} {r['write_s']:>8.3f} "
              f"{r['bytes'] / 1e6:>6.1f} {r['writes_per_step']:>6.1f} {r['interval_s']:>10.0f} "
              f"{100 * r['fraction']:>6.3f}% {r['resume_s'] or 0.0:>9.3f} {r['resumed_wall_s']:>9.2f} "
              f"{r['resumed_compile_s']:>9.2f} {r['resumed_startup_s']:>10.2f} {r['fresh_startup_s']:>8.2f}")
    print("steps: a write's time in steps; share: write / interval at run.checkpoint_every=null; start-up: the "
          "process's wall time less its compilation (cache load) and its step, joining the recording included")
