"""Replay a recording: ``python -m pipelines.replay <recording.rrd>``.

  (no option)     open it in the Rerun viewer (needs a display)
  --web           serve it to a browser with Rerun's web viewer
  --frames DIR    render the particles to PNG frames without a display (and
                  DIR/video.mp4 where ffmpeg is installed)
  --reproduce     re-run the recorded configuration (its command-line
                  overrides, into a fresh directory) and compare the two
                  recordings: bit for bit on the CPU, else the largest
                  deviation per quantity; exit code 0 on a match, 1 otherwise

The recording carries how it was made (recording properties: overrides,
resolved config, git commit, packages); --reproduce warns when the code has
changed since.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from . import provenance, recordings


def rerun_executable() -> str:
    exe = Path(sys.executable).parent / "rerun"
    return str(exe) if exe.exists() else (shutil.which("rerun") or "rerun")


def open_viewer(path: Path, web: bool) -> int:
    if not web and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                        or sys.platform in ("darwin", "win32")):
        print("no display here: use --web to serve the web viewer, or --frames DIR", file=sys.stderr)
        return 2
    cmd = [rerun_executable(), str(path)] + (["--web-viewer"] if web else [])
    return subprocess.call(cmd)


def render_frames(rec: recordings.Recording, out: Path, every: int = 1, size: float = 6.0,
                  view: str = "xy") -> list[Path]:
    """One PNG per logged step (every ``every``-th), particles coloured by
    body; 3D recordings are projected onto the ``view`` plane (back to front)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    axes = {"x": 0, "y": 1, "z": 2}
    a, b = axes[view[0]], axes[view[1]]
    depth = ({0, 1, 2} - {a, b}).pop() if rec.dim == 3 else None
    all_x = np.concatenate(rec.positions)
    lo, hi = all_x.min(axis=0), all_x.max(axis=0)
    pad = 0.05 * np.max(hi - lo)
    if rec.colors is not None:  # RGBA packed as 0xRRGGBBAA
        c = rec.colors
        rgb = np.stack([(c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255], axis=1) / 255.0
    else:
        rgb = None
    written = []
    for k in range(0, len(rec.positions), every):
        x = rec.positions[k]
        order = np.argsort(x[:, depth]) if depth is not None else slice(None)
        fig, ax = plt.subplots(figsize=(size, size))
        ax.scatter(x[order, a], x[order, b], s=2.0, c=None if rgb is None else rgb[order],
                   linewidths=0)
        ax.set_xlim(lo[a] - pad, hi[a] + pad)
        ax.set_ylim(lo[b] - pad, hi[b] + pad)
        ax.set_aspect("equal")
        ax.set_title(f"step {rec.steps[k]}, t = {rec.times[k]:.4f} s")
        path = out / f"frame_{len(written):05d}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    if shutil.which("ffmpeg") and written:
        subprocess.run(["ffmpeg", "-y", "-loglevel", "error", "-framerate", "30", "-i",
                        str(out / "frame_%05d.png"), "-pix_fmt", "yuv420p", str(out / "video.mp4")],
                       check=False)
    return written


def reproduce(path: Path, workdir: Path | None = None) -> dict:
    """Re-run the recorded overrides and compare the recordings."""
    rec = recordings.read(path)
    overrides = [o for o in rec.properties.get("config:overrides", []) if o]
    recorded_commit = (rec.properties.get("provenance:git_commit") or ["unknown"])[0]
    now = provenance.git_state()
    notes = []
    if recorded_commit != now["git_commit"]:
        notes.append(f"recorded with commit {recorded_commit}, now at {now['git_commit']}")
    if (rec.properties.get("provenance:git_dirty") or [False])[0] or now["git_dirty"]:
        notes.append("uncommitted changes (then or now): a mismatch may come from them")
    tmp = Path(tempfile.mkdtemp(prefix="reproduce-", dir=workdir))
    cmd = [sys.executable, "-m", "pipelines.run", *overrides, f"hydra.run.dir={tmp}"]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode not in (0, 3):
        return {"match": False, "problems": [f"re-run failed ({run.returncode}): {run.stderr.strip()}"],
                "largest": {}, "notes": notes, "rerun_dir": str(tmp)}
    result = recordings.compare(rec, recordings.read(tmp / "recording.rrd"))
    result.update(notes=notes, rerun_dir=str(tmp), overrides=overrides)
    return result


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path)
    p.add_argument("--web", action="store_true", help="serve the web viewer")
    p.add_argument("--frames", type=Path, default=None, help="render PNG frames into this directory")
    p.add_argument("--every", type=int, default=1, help="with --frames: every N-th logged step")
    p.add_argument("--view", default="xy", choices=["xy", "xz", "zy"], help="3D projection plane")
    p.add_argument("--reproduce", action="store_true", help="re-run and compare")
    args = p.parse_args(argv)
    if not args.recording.is_file():
        print(f"error: recording: {args.recording}: no such file", file=sys.stderr)
        return 2
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
        frames = render_frames(recordings.read(args.recording), args.frames, args.every, view=args.view)
        video = args.frames / "video.mp4"
        print(f"{len(frames)} frames in {args.frames}" + (f", {video}" if video.exists() else
                                                           " (no ffmpeg: no video)"))
        return 0
    return open_viewer(args.recording, args.web)


if __name__ == "__main__":
    sys.exit(main())
