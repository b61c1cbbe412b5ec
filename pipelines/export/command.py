"""Export a run's recorded particle frames:
``python -m pipelines.export <run dir> --format vtk|usd [--every N] [--out DIR]``.

  --format vtk    particles_000000.vtp, ... (one PolyData per frame: points,
                  a vertex cell each, every logged channel as point data)
                  and particles.pvd, the collection with each frame's
                  simulated time [s] that ParaView opens as one time series;
                  walls.vtp and collider_<name>.vtp (a series with its own
                  .pvd for a moving collider). Needs the vtk package:
                  pip install -e ".[export]"
  --format usd    stage.usdc: UsdGeom.Points with time-sampled points and a
                  primvar per channel, the walls and colliders as meshes (2D:
                  curves); metres, y up, time code / timeCodesPerSecond =
                  simulated time [s]
  --every N       every N-th logged frame, from the first (default 1: all)
  --out DIR       where the files go (default: <run dir>/export/<format>/)

The channels are those the run logged: dJ, the plastic fields of plastic
bodies, speed (with log.color=speed or log.channels=[speed]), the body of
each particle and, when the run removed particles at open walls, their
numbers (index) in every frame. 2D runs are exported in the plane z = 0.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..config.arguments import Parser, output_dir
from ..recording import recordings
from ..run.progress import Progress
from . import frames

FORMATS = ("vtk", "usd")
PACKAGES = {"vtk": ("vtk", 'pip install -e ".[export]"'), "usd": ("usd-core", "pip install -e .")}


def _writer(fmt: str):
    """The format's ``write(run, out, progress)``; ImportError when its package is missing."""
    if fmt == "vtk":
        from . import vtk_series

        return vtk_series.write
    from . import usd_stage

    return usd_stage.write


def _problem(args) -> str | None:
    """Why the arguments cannot be exported (None: they can), in one line."""
    if args.every < 1:
        return f"--every: {args.every}; accepted: an integer >= 1 (every N-th logged frame)"
    if not args.run_dir.exists():
        return f"run dir: {args.run_dir}: no such directory; accepted: a run directory of python -m pipelines.run"
    if args.run_dir.name.endswith(".timings.rrd"):
        return (f"run dir: {args.run_dir} holds a run's wall-clock timings, not its particles; accepted: "
                f"the run directory ({args.run_dir.parent})")
    if not args.run_dir.is_dir() and args.run_dir.suffix != ".rrd":
        return f"run dir: {args.run_dir} is a file; accepted: a run directory of python -m pipelines.run"
    if not frames.recording_path(args.run_dir).is_file():
        return (f"run dir: {args.run_dir}: no recording.rrd in it; accepted: a run directory of "
                f"python -m pipelines.run that logged particles")
    return output_dir("--out", args.out)


def main(argv=None) -> int:
    p = Parser(prog="python -m pipelines.export", description=__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir", type=Path, help="a run directory (or its recording.rrd)")
    p.add_argument("--format", required=True, choices=FORMATS, help="vtk (ParaView) or usd")
    p.add_argument("--every", type=int, default=1, help="every N-th logged frame")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: <run dir>/export/<format>/)")
    args = p.parse_args(argv)
    folder = args.run_dir.parent if args.run_dir.suffix == ".rrd" else args.run_dir
    args.out = args.out if args.out is not None else folder / "export" / args.format
    write, problem = None, _problem(args)
    if problem is None:
        try:
            write = _writer(args.format)
        except ImportError:
            package, install = PACKAGES[args.format]
            problem = f"--format {args.format}: the {package} package is not installed; accepted: {install}"
    if problem or write is None:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    start = time.perf_counter()
    path = frames.recording_path(args.run_dir)
    try:
        run = frames.read(path, args.every)
    except (RuntimeError, OSError, ValueError) as e:
        print(f"error: run dir: {path}: not a readable Rerun recording "
              f"({str(e).splitlines()[0] if str(e) else type(e).__name__})", file=sys.stderr)
        return 2
    if not run.frames:
        print(f"error: run dir: {path} has no particle frames (the run logged none: log.every=0); accepted: "
              f"a run that logged particles", file=sys.stderr)
        return 2
    if not recordings.is_complete(path):
        print(f"note: {path} has no footer (its run was killed); its frames are exported all the same",
              file=sys.stderr)
    progress = Progress(len(run.frames), None, unit="frame")
    try:
        written = write(run, args.out, progress)
    finally:
        progress.close()
    n = max(len(f.positions) for f in run.frames)
    print(f"{len(run.frames)} frames of {n} particles ({', '.join(sorted(run.frames[0].channels)) or 'no channels'})"
          f" to {args.out}: {len(written)} file{'s' * (len(written) != 1)} in {time.perf_counter() - start:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
