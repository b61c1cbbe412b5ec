"""Conservation: the final drifts (conservation.csv) and the numerical drift
over time read from the recordings (conservation.png).

A recording holds the bodies' momentum but not the impulse the walls give
them, so a change of momentum is drift only where nothing acts from outside:
the plot keeps the runs without gravity, colliders, kinematic regions, loads,
a body force or open walls (:func:`external_forces`), and says so."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from mpm.diagnostics import relative_drift

from ...recording.recordings import read
from ..common import absent, add_image, md_table, natural_key, pyplot, write_csv
from ..jobs import Job, config_value
from ..registry import section

MAX_RECORDINGS = 40  # recordings read for the conservation plot
DRIFT_FLOOR = 1e-17  # smallest drift drawn on the log axis


def _time_axis(rec, steps: np.ndarray) -> np.ndarray | None:
    """Simulated time [s] at ``steps``: the scalar rows' times (or a
    sim_time scalar), else interpolated from the particle frames' times; None
    if none covers the steps."""
    for s, t in (rec.clock, rec.scalars.get("sim_time", ((), ()))):
        s = np.asarray(s)
        if len(s) and set(steps.tolist()) <= set(s.tolist()):
            order = np.argsort(s)
            return np.interp(steps, s[order], np.asarray(t)[order])
    fs, ft = np.asarray(rec.steps, dtype=np.float64), np.asarray(rec.times, dtype=np.float64)
    if len(fs) >= 2 and len(steps) and steps.min() >= fs.min() and steps.max() <= fs.max():
        order = np.argsort(fs)
        return np.interp(steps, fs[order], ft[order])
    return None


def drift_series(scalars: dict, prefix: str) -> tuple[np.ndarray, np.ndarray] | None:
    """(steps, |Q(t) - Q(0)| / scale) for Q the vector of scalars named
    ``prefix`` or ``prefix_x/_y/_z``, relative to |Q(0)|, or to the largest
    ``prefix_scale`` seen (the largest |Q| if absent) when |Q(0)| is near zero
    (mpm.diagnostics.relative_drift)."""
    names = [n for n in scalars if (n == prefix or re.fullmatch(prefix + r"_[xyz]", n))]
    if not names:
        return None
    common = None
    for n in names:
        s = scalars[n][0]
        common = s if common is None else np.intersect1d(common, s)
    if common is None or len(common) == 0:
        return None
    common = np.sort(common)
    Q = np.stack([np.interp(common, *scalars[n]) for n in sorted(names)], axis=1)
    scale_series = scalars.get(f"{prefix}_scale")
    scale = float(np.nanmax(scale_series[1])) if scale_series is not None and len(scale_series[1]) else 0.0
    if not scale > 0:
        scale = float(np.nanmax(np.linalg.norm(Q, axis=1)))
    return common, relative_drift(Q[0], Q, scale)


def external_forces(config: dict | None) -> list[str]:
    """What acts on the bodies from outside, read from a job's composed
    config: gravity, colliders, kinematic regions, loads, a manufactured
    solution's body force, open walls (mass and momentum leave); ["unknown
    config"] without one. The domain's closed walls act only where a body
    reaches them, which the recording does not say."""
    if not isinstance(config, dict):
        return ["unknown config"]
    out = []
    if any(float(g) != 0.0 for g in config_value(config, "scene", "gravity") or ()):
        out.append("gravity")
    for key, name in (("colliders", "colliders"), ("regions", "kinematic regions"), ("loads", "loads")):
        if config_value(config, "scene", key):
            out.append(name)
    solution = config_value(config, "scene", "solution")
    if isinstance(solution, dict):
        from mpm.analytic import SOLUTIONS

        kind = SOLUTIONS.get(str(solution.get("type")))
        if kind is None or kind.has_body_force:
            out.append("body force")
    if "open" in (config_value(config, "scene", "walls") or ()):
        out.append("open walls")
    return out


@section(order=60)
def section_conservation(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """conservation.csv (final drifts from metrics.json) and conservation.png
    (drift over time from the recordings)."""
    title = "Conservation"
    keys = ("mass_drift", "momentum_drift", "angular_momentum_drift")
    have = [j for j in jobs if any(j.num(k) is not None for k in keys)]
    with_rec = [j for j in jobs if j.data_file("recording.rrd") is not None]
    if not have and not with_rec:
        return absent(title, "no job reports drifts or has a recording")
    lines = [f"## {title}", ""]
    if have:
        rows = [[j.rel, j.scene, j.label, j.resolution, j.status] + [j.num(k) for k in keys]
                + [j.num("energy_initial"), j.num("energy_final"),
                   ", ".join(external_forces(j.config)) or "none"] for j in have]
        write_csv(out / "conservation.csv", ["dir", "scene", "label", "resolution", "status"] + list(keys)
                  + ["energy_initial", "energy_final", "external"], rows)
        lines += ["Relative changes between the first and the last measurement: mass, linear momentum "
                  "and angular momentum about the centre of mass, against the first value (against the "
                  "quantity's scale where it starts near zero) ([conservation.csv](conservation.csv)). "
                  "They are numerical drift only where nothing acts from outside (column *external*: "
                  "none); elsewhere they include the external impulse, and every run includes the "
                  "impulse of any closed wall its bodies reach (not recorded).", ""]
        lines += md_table(["dir", "scene", "label", "cells", "status", "mass", "momentum",
                           "angular momentum", "external"], [r[:8] + r[-1:] for r in rows])
    if not with_rec:
        lines += ["No recording.rrd in the job directories: no drift over time.", ""]
        return lines
    forced = {j.rel: external_forces(j.config) for j in with_rec}
    free = [j for j in with_rec if not forced[j.rel]]
    left_out = [f"{j.rel} ({', '.join(forced[j.rel])})" for j in with_rec if forced[j.rel]]
    read_list = free[:MAX_RECORDINGS]
    series, failed = [], []
    for j in read_list:
        try:
            rec = read(j.data_file("recording.rrd"), particles=False)  # scalars only: frames can be GBs
        except Exception as exc:
            failed.append(f"{j.rel} ({type(exc).__name__})")
            continue
        p = drift_series(rec.scalars, "momentum")
        L = drift_series(rec.scalars, "angular_momentum")
        if p is None and L is None:
            failed.append(f"{j.rel} (no momentum scalars)")
            continue
        series.append((j, rec, p, L))
    if series:
        use_time = all(_time_axis(rec, s[0]) is not None
                       for _, rec, p, L in series for s in (p, L) if s is not None)
        plt = pyplot()
        scenes = sorted({item[0].scene for item in series}, key=natural_key)
        fig, axes = plt.subplots(len(scenes), 2, figsize=(12, 4.5 * len(scenes)), squeeze=False)
        for r, scene in enumerate(scenes):
            for c, (name, idx) in enumerate((("linear momentum", 2), ("angular momentum", 3))):
                ax = axes[r][c]
                for item in series:
                    j, rec, s = item[0], item[1], item[idx]
                    if s is None or j.scene != scene:
                        continue
                    x = _time_axis(rec, s[0]) if use_time else s[0]
                    colour = style[j.label][0]
                    ax.plot(x, np.maximum(s[1], DRIFT_FLOOR), color=colour, lw=1,
                            label=f"{j.label} · {j.resolution}" if j.resolution else j.label)
                ax.set_yscale("log")
                ax.set_xlabel("time [s]" if use_time else "step")
                ax.set_ylabel(f"relative {name} drift [-]")
                ax.set_title(f"{scene}: numerical drift of the {name}")
                ax.grid(True, which="both", alpha=0.3)
                if ax.lines and len(ax.lines) <= 20:
                    ax.legend(fontsize=6)
        fig.tight_layout()
        fig.savefig(out / "conservation.png", dpi=120)
        plt.close(fig)
        lines += [f"Relative drift over {'time [s]' if use_time else 'steps'} read from {len(series)} "
                  "recording(s): |Q(t) - Q(0)| / |Q(0)| for the linear momentum P and the angular momentum L "
                  "about the centre of mass (against the quantity's scale where Q(0) is near zero: "
                  f"two spheres colliding head-on), log scale floored at {DRIFT_FLOOR:g}; colours by method, "
                  "one line per job. Only runs on which nothing acts from outside are drawn: the recording "
                  "holds no impulse of the walls, colliders or kinematic regions, so a change of momentum "
                  "elsewhere mixes that impulse with the drift; a body that reaches a closed wall shows the "
                  "wall's impulse here too.", ""]
        add_image(lines, "conservation.png", "numerical momentum drift over time")
    if left_out:
        lines += ["No drift plotted for the runs with external forces (their impulse is not recorded): "
                  + ", ".join(left_out) + ".", ""]
    if len(free) > MAX_RECORDINGS:
        lines += [f"Only the first {MAX_RECORDINGS} of {len(free)} recordings were read.", ""]
    if failed:
        lines += ["Recordings not plotted: " + ", ".join(failed) + ".", ""]
    return lines
