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
                  recording, in its run directory) and compare the two
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

import numpy as np

from . import recordings, regions
from ..run import provenance, runner


def rerun_executable() -> str:
    exe = Path(sys.executable).parent / "rerun"
    return str(exe) if exe.exists() else (shutil.which("rerun") or "rerun")


def open_viewer(path: Path, web: bool) -> int:
    if not web and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                        or sys.platform in ("darwin", "win32")):
        print("no display here: use --web to serve the web viewer, or --frames DIR", file=sys.stderr)
        return 2
    timings = recordings.timings_path(path)  # the wall-clock series, merged by the viewer
    cmd = [rerun_executable(), str(path)] + ([str(timings)] if timings.is_file() else []) \
        + (["--web-viewer"] if web else [])
    return subprocess.call(cmd)


def _domain(rec: recordings.Recording, positions) -> np.ndarray:
    """The domain's size [m] from the recorded config (else the particles' extent)."""
    import yaml

    text = (rec.properties.get("config:yaml") or [""])[0]
    try:
        return np.asarray(yaml.safe_load(text)["scene"]["domain"], float)
    except (TypeError, KeyError, ValueError, yaml.YAMLError):
        return np.concatenate(positions).max(axis=0)


def _colours(rec: recordings.Recording, k: int, color: str):
    """(RGB per particle, values or None) for frame ``k``: the body palette or a field."""
    if color == "body":
        if rec.colors is None:
            return None, None
        c = rec.colors  # RGBA packed as 0xRRGGBBAA
        if rec.index and rec.index[k] is not None:  # some particles were removed at open walls
            c = c[rec.index[k]]
        return np.stack([(c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255], axis=1) / 255.0, None
    values = rec.dJ[k] if color == "dJ" else rec.fields[k].get(color)
    if values is None:
        known = ["body"] + (["dJ"] if rec.dJ and rec.dJ[0] is not None else []) + sorted(rec.fields[k])
        raise ValueError(f"--color {color}: not in this recording; accepted: {', '.join(known)}")
    return None, values


def render_frames(rec: recordings.Recording, out: Path, every: int = 1, size: float = 6.0,
                  view: str = "xy", color: str = "body", elev: float = 20.0,
                  azim: float = -60.0) -> list[Path]:
    """One PNG per logged step (every ``every``-th) with a fixed camera that
    frames the domain, axes in metres and the colliders drawn. Particles are
    coloured by body, or by a per-particle field (``color``: dJ, or a plastic
    field such as plastic_strain) with a colour bar. 3D recordings are drawn
    in perspective from (``elev``, ``azim``) degrees, y up; ``view`` (xy, xz,
    zy) projects them onto a plane instead when it is not "3d"."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    L = _domain(rec, rec.positions)
    regs = regions.regions(rec)  # the kinematic regions, from the recorded config
    fields = [_colours(rec, k, color) for k in range(0, len(rec.positions), every)]
    vmin, vmax = _recorded_range(rec, color) or _value_range([v for _, v in fields if v is not None])
    unit = (rec.properties.get("color:unit") or [""])[0] if _recorded_range(rec, color) else ""
    written = []
    for n, k in enumerate(range(0, len(rec.positions), every)):
        x = rec.positions[k]
        rgb, val = fields[n]
        shift = _collider_shifts(rec, rec.steps[k])
        if rec.dim == 3 and view == "3d":
            fig = plt.figure(figsize=(size, size))
            ax = fig.add_subplot(projection="3d")
            _draw_3d(ax, rec, x, rgb, val, vmin, vmax, L, shift, elev, azim)
            regions.draw_3d(ax, regs, rec.times[k])
            mappable = ax.collections[0] if val is not None else None
        else:
            fig, ax = plt.subplots(figsize=(size, size))
            mappable = _draw_2d(ax, rec, x, rgb, val, vmin, vmax, L, view, shift)
            regions.draw_2d(ax, regs, rec.times[k], *(projection(view)["axes"] if rec.dim == 3 else (0, 1)))
        if mappable is not None:
            bar = fig.colorbar(mappable, ax=ax, shrink=0.7, label=f"{color}{unit and f' [{unit}]'} (grey: no value)")
            bar.ax.set_title(f"{vmin:.3g} to {vmax:.3g}", fontsize=7)
        _legend(ax, rec, regions.legend_handles(regs, rec.times[k]), bodies=mappable is None and rgb is not None)
        seen = f"\n{view}: seen from {projection(view)['seen']}" if rec.dim == 3 and view != "3d" else ""
        ax.set_title(f"t = {rec.times[k]:.4f} s (step {rec.steps[k]}){seen}")
        path = out / f"frame_{len(written):05d}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    if shutil.which("ffmpeg") and written:
        subprocess.run(["ffmpeg", "-y", "-loglevel", "error", "-framerate", "30", "-i",
                        str(out / "frame_%05d.png"), "-pix_fmt", "yuv420p", str(out / "video.mp4")],
                       check=False)
    return written


def _collider_shifts(rec: recordings.Recording, step: int) -> dict:
    out = {}
    for name, (steps, shifts) in (rec.collider_shift or {}).items():
        i = np.searchsorted(steps, step, side="right") - 1
        if i >= 0:
            out[name] = shifts[i][:rec.dim]
    return out


NO_VALUE = (0.6, 0.6, 0.6)  # a particle without a value of the field (another body's material)
COLLIDER_FACE, COLLIDER_EDGE = (0.55, 0.55, 0.62, 0.35), (0.35, 0.35, 0.4)


def _recorded_range(rec: recordings.Recording, color: str) -> tuple[float, float] | None:
    """The range the run fixed for ``color`` (recording property ``color``),
    if it coloured its particles by that field."""
    p = rec.properties
    if (p.get("color:field") or [None])[0] != color or not p.get("color:low") or not p.get("color:high"):
        return None
    return float(p["color:low"][0]), float(p["color:high"][0])


def _value_range(values: list) -> tuple[float, float]:
    """(low, high) of the finite values of every frame: one range for all
    frames; (0, 1) when there is none."""
    finite = [v[np.isfinite(v)] for v in values]
    finite = [v for v in finite if v.size]
    if not finite:
        return 0.0, 1.0
    lo, hi = min(float(v.min()) for v in finite), max(float(v.max()) for v in finite)
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def _paint(rgb, val, vmin, vmax) -> dict:
    """Scatter colour arguments: a field on a colour map (grey where it has
    no value), or fixed colours."""
    if val is not None:
        import matplotlib

        cmap = matplotlib.colormaps["viridis"].with_extremes(bad=NO_VALUE)
        return dict(c=val, cmap=cmap, vmin=vmin, vmax=vmax, plotnonfinite=True)
    return dict(c=rgb) if rgb is not None else {}


def body_names(rec: recordings.Recording) -> list[str]:
    """The bodies' names: recorded, else from the recorded config, else body0, body1, ..."""
    n = int(rec.body.max()) + 1 if rec.body is not None and len(rec.body) else 0
    names = list(rec.properties.get("bodies:names") or [])
    if len(names) != n:
        import yaml

        try:
            bodies = yaml.safe_load((rec.properties.get("config:yaml") or [""])[0])["scene"]["bodies"]
            names = [b.get("name") or f"body{i}" for i, b in enumerate(bodies)]
        except (TypeError, KeyError, AttributeError, yaml.YAMLError):
            names = []
    return names if len(names) == n else [f"body{i}" for i in range(n)]


def _legend(ax, rec, more: list, bodies: bool = True) -> None:
    """One entry per body in its colour (``bodies``: coloured by body), one
    per collider and the entries ``more`` (the kinematic regions)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from .rerun_sink import PALETTE

    handles = [Line2D([], [], ls="", marker="o", color=PALETTE[i % len(PALETTE)] / 255.0, label=name)
               for i, name in enumerate(body_names(rec))] if bodies else []
    handles += more
    handles += [Patch(facecolor=COLLIDER_FACE, edgecolor=COLLIDER_EDGE, label=f"collider {name}")
                for name in (rec.colliders or {})]
    if handles:
        ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.8)


def _marker_area(ax, rec, width: float, height: float) -> float:
    """Scatter marker area [pt²]: a particle's recorded diameter at the
    axes' scale (at least 1 pt² so that every particle shows)."""
    if not rec.radius:
        return 2.0
    box = ax.get_position()  # figure fraction
    w, h = ax.figure.get_size_inches() * 72.0 * (box.width, box.height)
    per_metre = min(w / width, h / height)  # equal aspect
    return max(1.0, (2.0 * rec.radius * per_metre) ** 2)


def _draw_3d(ax, rec, x, rgb, val, vmin, vmax, L, shift, elev, azim):
    """Perspective view, y up (matplotlib's z axis shows the scene's y)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    swap = [0, 2, 1]
    size = 0.5 * _marker_area(ax, rec, float(max(L)), float(max(L)))  # the perspective box is drawn smaller
    ax.scatter(x[:, 0], x[:, 2], x[:, 1], s=size, linewidths=0, depthshade=True, **_paint(rgb, val, vmin, vmax))
    for name, geo in (rec.colliders or {}).items():
        if isinstance(geo, tuple):
            v, f = geo
            v = v + shift.get(name, 0.0)
            ax.add_collection3d(Poly3DCollection(v[:, swap][f], facecolor=(0.6, 0.6, 0.65, 0.25),
                                                 edgecolor=(0.4, 0.4, 0.45, 0.15), linewidths=0.2))
    ax.set_xlim(0, L[0])
    ax.set_ylim(0, L[2])
    ax.set_zlim(0, L[1])
    ax.set_box_aspect((L[0], L[2], L[1]))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_zlabel("y [m]")
    ax.view_init(elev=elev, azim=azim)


# the projections of a 3D recording: (across, up the picture, up the picture is -axis, seen from), right-handed
# (across x up = towards the viewer), so that the particles nearest the viewer are drawn last
PROJECTIONS = {"xy": (0, 1, False, "the front (+z)"), "xz": (0, 2, True, "above (+y)"),
               "zy": (2, 1, False, "the left (-x)")}


def projection(view: str) -> dict:
    """How ``view`` (xy, xz, zy) draws a 3D recording: ``axes`` (across, up
    the picture), ``down`` (the second axis points down the picture),
    ``depth`` (the axis towards the viewer) and ``sign`` (+1: the viewer on
    its positive side), ``seen`` (from where, in words)."""
    a, b, down, seen = PROJECTIONS[view]
    depth = 3 - a - b
    e = np.eye(3)
    sign = float(np.cross(e[a], -e[b] if down else e[b])[depth])
    return {"axes": (a, b), "down": down, "depth": depth, "sign": sign, "seen": seen}


def _draw_2d(ax, rec, x, rgb, val, vmin, vmax, L, view, shift):
    """A 2D recording, or a 3D one projected onto ``view`` (:func:`projection`:
    far to near, the convention in the axis labels and the title)."""
    p = projection(view) if rec.dim == 3 else {"axes": (0, 1), "down": False, "depth": None}
    a, b = p["axes"]
    order = np.argsort(p["sign"] * x[:, p["depth"]], kind="stable") if p["depth"] is not None else slice(None)
    sc = ax.scatter(x[order, a], x[order, b], s=_marker_area(ax, rec, L[a], L[b]), linewidths=0,
                    **_paint(None if rgb is None else rgb[order], None if val is None else val[order],
                             vmin, vmax))
    for name, geo in (rec.colliders or {}).items():
        if isinstance(geo, list):  # 2D outlines
            for line in geo:
                line = line + shift.get(name, 0.0)
                ax.plot(line[:, 0], line[:, 1], color=COLLIDER_EDGE, linewidth=1.0)
        else:  # a 3D surface, projected: its triangles filled, those seen edge-on as lines
            from matplotlib.collections import LineCollection, PolyCollection

            v, f = geo
            tri = (v + shift.get(name, 0.0))[:, [a, b]][f]  # (triangles, 3, 2) [m]
            e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
            edge_on = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) <= 1e-9 * L[a] * L[b]
            ax.add_collection(PolyCollection(tri[~edge_on], facecolors=COLLIDER_FACE, edgecolors="none", zorder=0))
            if edge_on.any():  # a face along the depth axis (a wedge's or a plane's, seen from its edge)
                ax.add_collection(LineCollection(tri[edge_on][:, [0, 1, 2, 0]], colors=[COLLIDER_EDGE],
                                                 linewidths=1.5, zorder=0))
    ax.set_xlim(0, L[a])
    ax.set_ylim((L[b], 0) if p["down"] else (0, L[b]))
    ax.set_aspect("equal")
    ax.set_xlabel(f"{'xyz'[a]} [m]")
    ax.set_ylabel(f"{'xyz'[b]} [m]" + (" (down the picture)" if p["down"] else ""))
    return sc if val is not None else None


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
    run = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if run.returncode not in (0, 3):
        return {"match": False, "problems": [f"re-run failed ({run.returncode}): {run.stderr.strip()}"],
                "largest": {}, "notes": notes, "rerun_dir": str(tmp)}
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
    from ..config.arguments import Parser, finite, output_dir

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
