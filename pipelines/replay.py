"""Replay a recording: ``python -m pipelines.replay <recording.rrd | run dir>``.

  (no option)     open it in the Rerun viewer (needs a display)
  --web           serve it to a browser with Rerun's web viewer
  --frames DIR    render the particles to PNG frames without a display (and
                  DIR/video.mp4 where ffmpeg is installed): a fixed camera on
                  the domain (y up, axes in metres), the simulated time on
                  each frame, colliders and kinematic regions (outlined,
                  dashed while inactive) drawn in every view, every body drawn,
                  coloured by body with a legend or (--color speed, dJ,
                  plastic_strain, ...) by a field on a colour bar whose range
                  is the run's (the recorded log.color) or else fixed for the
                  frames (grey: no value, e.g. a body without
                  plastic strain); 3D in perspective (--view 3d, --elev,
                  --azim) or projected (--view xy|xz|zy: xy seen from the
                  front (+z), xz from above (+y, z down the picture), zy
                  from the left (-x); the nearest particles drawn last)
  --reproduce     re-run the recorded configuration (its command-line
                  overrides, with the recorded MPM_PLUGINS modules, from the
                  working directory; into a fresh directory reproduce-* beside the
                  recording, in its run directory, removed if the re-run
                  fails) and compare the two
                  recordings: bit for bit on the CPU, else the largest
                  deviation per quantity; exit code 0 on a match, 1 otherwise
  --repair        a run killed without warning (SIGKILL, power loss) leaves
                  its recording without footer: every option above still
                  reads it; --repair rewrites it (and its timings file) with
                  one (``rerun rrd migrate``, the originals kept as
                  *.backup.rrd) and marks the run's metrics.json ``killed``

The recording carries how it was made (recording properties: overrides,
resolved config, git commit, packages); --reproduce warns when the code has
changed since.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from .recording import recordings
from .recording.display import open_viewer, render_frames
from .run import provenance, runner


def reproduce(path: Path, workdir: Path | None = None) -> dict:
    """Re-run the recorded overrides and compare the recordings; the re-run
    lands in ``workdir`` (default: beside the recording, in its run
    directory: ``reproduce-*``)."""
    rec = recordings.read(path)
    overrides = [o for o in rec.properties.get("config:overrides", []) if o]
    recorded_commit = (rec.properties.get("provenance:git_commit") or ["unknown"])[0]
    now = provenance.git_state()
    notes = []
    if recorded_commit != now["git_commit"]:
        notes.append(f"recorded with commit {recorded_commit}, now at {now['git_commit']}")
    if (rec.properties.get("provenance:git_dirty") or [False])[0] or now["git_dirty"]:
        notes.append("uncommitted changes (then or now): a mismatch may come from them")
    tmp = Path(tempfile.mkdtemp(prefix="reproduce-", dir=workdir if workdir is not None else Path(path).parent))
    cmd = [sys.executable, "-m", "pipelines.run", *overrides, f"hydra.run.dir={tmp}"]
    modules = [m for m in rec.properties.get("provenance:mpm_plugins", []) if m]
    env = {**os.environ, "MPM_PLUGINS": ",".join(modules)} if modules else None  # the models they registered
    try:
        run = subprocess.run(cmd, capture_output=True, text=True, env=env)
    except BaseException:  # Ctrl-C while it runs: nothing left behind
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if run.returncode not in (0, 3) or not (tmp / "recording.rrd").is_file():
        shutil.rmtree(tmp, ignore_errors=True)  # a failed re-run leaves no reproduce-* folder
        return {"match": False, "problems": [f"re-run failed ({run.returncode}): {run.stderr.strip()}"],
                "largest": {}, "notes": notes, "rerun_dir": "(removed: the re-run failed)"}
    result = recordings.compare(rec, recordings.read(tmp / "recording.rrd"))
    result.update(notes=notes, rerun_dir=str(tmp), overrides=overrides)
    return result


def repair(path: Path) -> list[str]:
    """Repair the recording and its timings file; a metrics.json still
    ``running`` becomes ``killed`` at the last recorded step.
    Returns what was done, a line each."""
    done = []
    for f in (path, recordings.timings_path(path)):
        if f.is_file():
            backup = recordings.repair(f)
            done.append(f"{f}: repaired (original: {backup})" if backup else f"{f}: complete, left as it is")
    metrics = path.parent / "metrics.json"
    m = json.loads(metrics.read_text()) if metrics.is_file() else {}
    if m.get("status") == "running":  # its process is gone (or this is run while it still runs: don't)
        rec = recordings.read(path)
        steps, t = rec.end
        m.update(status="killed", steps=steps, sim_time=t,
                 reason=f"the process ended without warning (SIGKILL, power loss) after step {steps} "
                        f"(t = {t:.6g} s), the last one in the recording")
        runner.write_metrics(metrics, m)
        done.append(f"{metrics}: status killed after step {steps}")
    return done


def main(argv=None) -> int:
    from .config.arguments import Parser, finite, output_dir

    p = Parser(prog="python -m pipelines.replay", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path)
    p.add_argument("--web", action="store_true", help="serve the web viewer")
    p.add_argument("--frames", type=Path, default=None, help="render PNG frames into this directory")
    p.add_argument("--every", type=int, default=1, help="with --frames: every N-th logged step")
    p.add_argument("--view", default="3d", choices=["3d", "xy", "xz", "zy"],
                   help="3D recordings: perspective (3d) or a projection: xy (seen from +z), xz (from above, "
                        "z down the picture), zy (from -x)")
    p.add_argument("--color", default="body",
                   help="body, dJ, or a per-particle field of the recording (e.g. speed, plastic_strain)")
    p.add_argument("--elev", type=float, default=20.0, help="3d view: camera elevation [deg]")
    p.add_argument("--azim", type=float, default=-60.0, help="3d view: camera azimuth [deg]")
    p.add_argument("--reproduce", action="store_true", help="re-run and compare")
    p.add_argument("--repair", action="store_true", help="add the footer a killed run could not write")
    args = p.parse_args(argv)
    if args.every < 1:
        print(f"error: --every: {args.every}; accepted: an integer >= 1 (every N-th logged step)", file=sys.stderr)
        return 2
    problem = output_dir("--frames", args.frames) or finite("--elev", args.elev) or finite("--azim", args.azim)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    if args.recording.is_dir():
        args.recording = args.recording / "recording.rrd"
    if not args.recording.is_file():
        print(f"error: recording: {args.recording}: no such file; accepted: a run directory or its recording.rrd",
              file=sys.stderr)
        return 2
    if args.recording.name.endswith(".timings.rrd"):
        print(f"error: recording: {args.recording} holds a run's wall-clock timings, not its particles; accepted: "
              f"the run's recording (python -m pipelines.replay {args.recording.parent})", file=sys.stderr)
        return 2
    try:
        complete = recordings.is_complete(args.recording)
    except (RuntimeError, OSError, ValueError) as e:
        print(f"error: recording: {args.recording}: not a readable Rerun recording "
              f"({str(e).splitlines()[0] if str(e) else type(e).__name__})", file=sys.stderr)
        return 2
    if args.repair:
        for line in repair(args.recording):
            print(line)
        return 0
    if not complete:
        print(f"note: {args.recording} has no footer: its run was killed before closing it; it is read "
              f"all the same. To repair it: python -m pipelines.replay {args.recording} --repair",
              file=sys.stderr)
    if args.reproduce:
        r = reproduce(args.recording)
        for n in r.get("notes", []):
            print(f"note: {n}")
        if r["match"]:
            c = r["checked"]
            print(f"match: {c['particle_frames']} particle frames and {c['scalars']} scalar series "
                  f"identical bit for bit ({r['rerun_dir']})")
            return 0
        print(f"no match ({r['rerun_dir']}):")
        for prob in r["problems"]:
            print(f"  {prob}")
        for k, v in sorted(r["largest"].items()):
            print(f"  largest deviation of {k}: {v:.3g}")
        return 1
    if args.frames is not None:
        try:
            frames = render_frames(recordings.read(args.recording), args.frames, args.every, view=args.view,
                                   color=args.color, elev=args.elev, azim=args.azim)
        except ValueError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        video = args.frames / "video.mp4"
        print(f"{len(frames)} frames in {args.frames}" + (f", {video}" if video.exists() else
                                                           " (no ffmpeg: no video)"))
        return 0
    return open_viewer(args.recording, args.web)


if __name__ == "__main__":
    sys.exit(main())
