"""``python -m pipelines.kills``: runs killed with SIGKILL at random moments and
resumed, against the run that was never stopped, bit for bit.

For each configuration (:data:`CONFIGS`: the three schemes, A-ULMPM with
updates, the implicit integrator, friction between bodies, a plastic
material, a ramped load, the FLIP transfer; small scenes on the CPU) it runs
the job once uninterrupted (no checkpoints), then again in another directory
with a checkpoint every ``--every`` simulated seconds, killing the process
with SIGKILL after a random wall time (seeded; uniform over 1.5 times the
uninterrupted run's wall time: start-up, steps, checkpoint writes and the
run's end alike; every ``--aim``-th kill then waits for a checkpoint write
to begin, stops the process while its temporary file is there, and kills
it) and starting the same command again (``run.resume=null``: from the
newest checkpoint, or from the start where there is none yet), ``--kills``
times; the last one runs to its end (a run that ends before its kill is a
trial done: the next starts anew in another directory). A kill that leaves
a checkpoint's temporary file landed inside a write. Then each
trial's final state
(``final_state.npz``), every scalar series of the recording, its particle
frames and its configuration-update events are compared bit for bit
(pipelines.recording.recordings.compare). A table per configuration, and
``kills.json`` in ``--out``.

    python -m pipelines.kills                      # 8 configurations, 20 kills each
    python -m pipelines.kills --only empm,flip --kills 5
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .recording import recordings
from .run import checkpoints

SMALL = ["log.every=25", "log.progress=false"]
"""what every configuration shares: a particle frame every 25 steps"""
BALL = ["scene.resolution=32"]  # the 2D ball on a coarse grid: about 1,200 particles
CONFIGS = {
    "empm": [*BALL, "scheme=empm", "run.steps=1500"],
    "tlmpm": [*BALL, "scheme=tlmpm", "run.steps=1500"],
    "aulmpm": [*BALL, "scheme=aulmpm", "scheme.epsilon=0.01", "scheme.eta=0.01", "run.steps=1500"],
    "implicit": [*BALL, "integrator=implicit", "run.dt=2e-3", "run.steps=150"],
    "friction": ["scene=incline_2d", "run.steps=800"],
    "plastic": [*BALL, "material=von_mises", "run.steps=1500"],
    "ramped_load": ["scene=cantilever_2d", "scene.size=coarse", "run.steps=800"],
    "flip": [*BALL, "kernel.transfer=flip", "run.steps=1500"],
}
"""name -> overrides (with :data:`SMALL`) of each configuration the experiment kills"""


def launch(args: list[str], run_dir: Path) -> subprocess.Popen:
    """``python -m pipelines.run`` in its own process, its output to ``<run_dir>.log``."""
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    log = open(run_dir.with_name(run_dir.name + ".log"), "a")
    return subprocess.Popen([sys.executable, "-m", "pipelines.run", *args, f"hydra.run.dir={run_dir}"],
                            stdout=log, stderr=log)


def status(run_dir: Path) -> str:
    try:
        return json.loads((run_dir / "metrics.json").read_text()).get("status", "")
    except (OSError, ValueError):
        return ""


def whole(name: str, out: Path) -> tuple[Path, float]:
    """The uninterrupted run of ``name`` (no checkpoints) and its wall time [s]."""
    run_dir = out / name / "whole"
    t0 = time.monotonic()
    proc = launch([*SMALL, *CONFIGS[name], "run.checkpoint_every=0"], run_dir)
    if proc.wait() != 0 or status(run_dir) != "completed":
        raise RuntimeError(f"{name}: the uninterrupted run did not complete (exit {proc.returncode}); "
                           f"see {run_dir}.log")
    return run_dir, time.monotonic() - t0


def _wait_for_write(proc: subprocess.Popen, folder: Path, limit: float) -> None:
    """Until a checkpoint write is under way (its temporary file in ``folder``): the process is then
    stopped (SIGSTOP) with the file still there, for the kill to land inside the write; or until the
    process ends, or ``limit`` [s] passes."""
    end = time.monotonic() + limit
    while proc.poll() is None and time.monotonic() < end:
        if any(folder.glob(".ckpt-*.tmp")):
            proc.send_signal(signal.SIGSTOP)
            if any(folder.glob(".ckpt-*.tmp")):
                return
            proc.send_signal(signal.SIGCONT)  # the write ended meanwhile: the next one
        time.sleep(0.0005)


def killed(name: str, out: Path, kills: int, every: float, window: float, rng: np.random.Generator,
           aim: int) -> tuple[dict, list[Path]]:
    """``kills`` SIGKILLs at uniform random moments in ``window`` [s] after each start (every ``aim``-th
    one then waits for a checkpoint write to begin and lands inside it), each run continued until it
    ends; a run that ends before its kill is a trial done, and the next starts anew in another
    directory. The counts, and the trials' directories."""
    args = [*SMALL, *CONFIGS[name], f"run.checkpoint_every={every}", "run.resume=null"]
    counts: dict = {"kills": 0, "in_write": 0, "aimed": 0, "before_a_checkpoint": 0, "starts": 0}
    trials = [out / name / "killed-0"]
    while True:
        run_dir = trials[-1]
        proc = launch(args, run_dir)
        counts["starts"] += 1
        if counts["kills"] >= kills:
            proc.wait()
            if status(run_dir) != "completed":
                raise RuntimeError(f"{name}: {run_dir} did not complete (exit {proc.returncode}); see {run_dir}.log")
            return counts, trials
        folder = run_dir / checkpoints.DIR
        try:
            proc.wait(timeout=float(rng.uniform(0.0, window)))
        except subprocess.TimeoutExpired:
            aimed = aim > 0 and counts["kills"] % aim == aim - 1
            if aimed:
                _wait_for_write(proc, folder, window)
            if proc.poll() is None:
                proc.send_signal(signal.SIGKILL)
                proc.wait()
                counts["kills"] += 1
                counts["aimed"] += aimed
                counts["in_write"] += any(folder.glob(".ckpt-*.tmp"))
                counts["before_a_checkpoint"] += not checkpoints.listed(folder)
                continue
        if status(run_dir) != "completed":
            raise RuntimeError(f"{name}: {run_dir} ended {status(run_dir)!r} (exit {proc.returncode}); "
                               f"see {run_dir}.log")
        trials.append(out / name / f"killed-{len(trials)}")


def compare(a: Path, b: Path) -> dict:
    """Bit for bit: the final states, the recordings' scalar series and frames, the update events."""
    fa, fb = np.load(a / "final_state.npz"), np.load(b / "final_state.npz")
    final = fa.files == fb.files and all(np.array_equal(fa[k], fb[k]) for k in fa.files)
    ra, rb = recordings.read(a / "recording.rrd"), recordings.read(b / "recording.rrd")
    same = recordings.compare(ra, rb)
    scalars = set(ra.scalars) == set(rb.scalars) and not any(p.startswith("scalar") for p in same["problems"]) \
        and not any(k.startswith("scalar:") for k in same["largest"])
    frames = len(ra.positions) == len(rb.positions) and "positions" not in same["largest"] and \
        not any(p.startswith(("logged", "particle")) for p in same["problems"])
    events = np.array_equal(ra.update_steps, rb.update_steps)
    return {"final_state": bool(final), "scalars": bool(scalars), "series": len(ra.scalars),
            "rows": int(len(ra.clock[0])), "frames": bool(frames), "update_events": bool(events),
            "updates": int(len(ra.update_steps)), "one_file": sorted(p.name for p in b.glob("*.rrd")) ==
            ["recording.rrd", "recording.timings.rrd"]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m pipelines.kills", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--only", default=",".join(CONFIGS), help=f"configurations, comma-separated: {', '.join(CONFIGS)}")
    p.add_argument("--kills", type=int, default=20, help="SIGKILLs per configuration")
    p.add_argument("--every", type=float, default=0.005, help="run.checkpoint_every [s of simulated time]")
    p.add_argument("--aim", type=int, default=4, help="every N-th kill waits for a checkpoint write to begin "
                                                       "(0: none)")
    p.add_argument("--seed", type=int, default=0, help="the kill moments' random seed")
    p.add_argument("--out", type=Path, default=Path("outputs/kills"), help="where the runs go")
    a = p.parse_args(argv)
    names = [n for n in a.only.split(",") if n]
    unknown = [n for n in names if n not in CONFIGS]
    if unknown or a.kills < 0 or a.every <= 0 or a.aim < 0:
        print(f"error: --only {','.join(unknown)} unknown; accepted: {', '.join(CONFIGS)}" if unknown else
              "error: --kills >= 0, --every > 0 and --aim >= 0", file=sys.stderr)
        return 2
    rng = np.random.default_rng(a.seed)
    rows, ok = {}, True
    print("config        kills  aimed  in a write  before a ckpt  starts  trials  final  scalars (series, rows)  "
          "frames  updates  one file  wall [s]")
    for name in names:
        t0 = time.monotonic()
        ref, wall = whole(name, a.out)
        counts, trials = killed(name, a.out, a.kills, a.every, 1.5 * wall, rng, a.aim)
        found = [compare(ref, t) for t in trials]
        same = {k: all(f[k] for f in found) if isinstance(found[0][k], bool) else found[0][k] for k in found[0]}
        counts["trials"] = len(trials)
        passed = all(same[k] for k in ("final_state", "scalars", "frames", "update_events", "one_file"))
        ok &= passed
        rows[name] = {**counts, **same, "bit_for_bit": passed, "wall_s": time.monotonic() - t0}
        word = {k: "same" if same.get(k) else "DIFFER" for k in ("final_state", "scalars", "frames", "update_events")}
        print(f"{name:<13} {counts['kills']:>5}  {counts['aimed']:>5}  {counts['in_write']:>10}  "
              f"{counts['before_a_checkpoint']:>13}  {counts['starts']:>6}  {counts['trials']:>6}  "
              f"{word['final_state']:>5}  {word['scalars']:>7} ({same.get('series', 0)}, "
              f"{same.get('rows', 0)})  {word['frames']:>6}  {word['update_events']:>4} ({same.get('updates', 0)})"
              f"  {'yes' if same.get('one_file') else 'no':>8}  {rows[name]['wall_s']:8.1f}", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "kills.json").write_text(json.dumps({"every": a.every, "seed": a.seed, "configs": rows}, indent=2))
    print(f"{'all bit for bit' if ok else 'NOT all bit for bit'}; {a.out / 'kills.json'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
