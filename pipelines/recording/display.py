"""Show a recording: open it in the Rerun viewer (:func:`open_viewer`, with
its wall-clock timings file) or render its particles to PNG frames without a
display (:func:`render_frames`); the command ``python -m pipelines.replay``
(:mod:`pipelines.replay`) calls them."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from . import colours, recordings, regions


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
    try:
        return np.asarray(recordings.scene_config(rec)["domain"], float)
    except (TypeError, KeyError, ValueError):
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

    L = _domain(rec, rec.positions)
    regs = regions.regions(rec)  # the kinematic regions, from the recorded config
    fields = [_colours(rec, k, color) for k in range(0, len(rec.positions), every)]  # (an unknown colour: here)
    vmin, vmax = _recorded_range(rec, color) or colours.values_range(color, [v for _, v in fields])
    out.mkdir(parents=True, exist_ok=True)  # (only once the frames can be drawn)
    unit = colours.UNITS.get(color, "")
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
    """Per moving collider, its pose at ``step``: a function that moves its
    recorded geometry (points, (n, dim)) there (translated; turned first
    where it turns: R q + shift)."""
    out = {}
    turns = rec.collider_turn or {}
    for name, (steps, shifts) in (rec.collider_shift or {}).items():
        i = np.searchsorted(steps, step, side="right") - 1
        if i < 0:
            continue
        shift = shifts[i][:rec.dim]
        R = None
        if name in turns:
            at, mats = turns[name]
            j = np.searchsorted(at, step, side="right") - 1
            R = mats[j][:rec.dim, :rec.dim] if j >= 0 else None
        out[name] = _mover(shift, R)
    return out


def _mover(shift: np.ndarray, R: np.ndarray | None):
    if R is None:
        return lambda v: v + shift
    return lambda v: v @ R.T + shift


def _still(v):
    return v


NO_VALUE = (0.6, 0.6, 0.6)  # a particle without a value of the field (another body's material)
COLLIDER_FACE, COLLIDER_EDGE = (0.55, 0.55, 0.62, 0.35), (0.35, 0.35, 0.4)


def _recorded_range(rec: recordings.Recording, color: str) -> tuple[float, float] | None:
    """The range the run coloured ``color`` with in the viewer (recording
    property ``color``, or ``channels`` for a field of log.channels), if it
    did: the frames use the same."""
    p = rec.properties
    if (p.get("color:field") or [None])[0] == color and p.get("color:low") and p.get("color:high"):
        lo, hi = float(p["color:low"][0]), float(p["color:high"][0])
    elif color in (p.get("channels:names") or []):
        k = list(p["channels:names"]).index(color)
        lo, hi = float(p["channels:low"][k]), float(p["channels:high"][k])
    else:
        return None
    return (lo, hi) if np.isfinite(lo) and np.isfinite(hi) else None


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
        try:
            bodies = recordings.scene_config(rec)["bodies"]
            names = [b.get("name") or f"body{i}" for i, b in enumerate(bodies)]
        except (TypeError, KeyError, AttributeError):
            names = []
    return names if len(names) == n else [f"body{i}" for i in range(n)]


def _legend(ax, rec, more: list, bodies: bool = True) -> None:
    """One entry per body in its colour (``bodies``: coloured by body), one
    per collider and the entries ``more`` (the kinematic regions)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from .colours import PALETTE

    handles = [Line2D([], [], ls="", marker="o", color=PALETTE[i % len(PALETTE)] / 255.0, label=name)
               for i, name in enumerate(body_names(rec))] if bodies else []
    handles += more
    handles += [Patch(facecolor=COLLIDER_FACE, edgecolor=COLLIDER_EDGE,
                      label=f"rigid body {name[6:]}" if name.startswith("rigid/") else f"collider {name}")
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
            v = shift.get(name, _still)(v)
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
                line = shift.get(name, _still)(line)
                ax.plot(line[:, 0], line[:, 1], color=COLLIDER_EDGE, linewidth=1.0)
        else:  # a 3D surface, projected: its triangles filled, those seen edge-on as lines
            from matplotlib.collections import LineCollection, PolyCollection

            v, f = geo
            tri = shift.get(name, _still)(v)[:, [a, b]][f]  # (triangles, 3, 2) [m]
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
