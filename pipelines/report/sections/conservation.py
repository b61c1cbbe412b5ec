"""Conservation: the final drifts (conservation.csv) and the numerical drift
over time read from the recordings (conservation.png, momentum_net_drift.csv).

A recording holds the bodies' momentum P, their mass, the simulated time and,
per step, the impulse the walls, colliders and kinematic regions gave them
(``boundary_impulse_x/_y/_z`` [N s], mpm.stepping.status). The linear momentum's
drift is drawn for every run net of what acts from outside,
    P(t) - P(0) - sum M g dt - sum J_boundary
(:func:`net_momentum`), which leaves the numerical drift where nothing else
acts; loads, a manufactured solution's body force and open walls are not
netted and are named beside the run, and so is a recording without the
boundary impulse (made before it was recorded). The angular momentum about
the centre of mass is drawn for the runs on which nothing but gravity acts
(it exerts no torque about the centre of mass; the boundary's torque is not
recorded)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import cast

import numpy as np

from mpm.diagnostics import relative_drift

from ...recording.recordings import read
from ..common import absent, add_image, md_table, natural_key, pyplot, write_csv
from ..jobs import Job, config_value
from ..registry import section

MAX_RECORDINGS = 40  # recordings read for the conservation plot
IMPULSE = "boundary_impulse"  # the scalars of the boundary's impulse per step, per axis [N s]
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
    return common, cast(np.ndarray, relative_drift(Q[0], Q, scale))  # (Q an array: an array)


def _per_axis(scalars: dict, prefix: str) -> list[str]:
    return sorted(n for n in scalars if n == prefix or re.fullmatch(prefix + r"_[xyz]", n))


def _summed(series: tuple, steps: np.ndarray) -> np.ndarray:
    """The sum of a per-step series over the rows after ``steps[0]`` up to each of ``steps``."""
    s, v = (np.asarray(a) for a in series)
    order = np.argsort(s, kind="stable")
    s, total = s[order], np.concatenate([[0.0], np.cumsum(np.asarray(v, np.float64)[order])])
    at = total[np.searchsorted(s, steps, side="right")]
    return at - at[0]


def _steps_taken(scalars: dict, steps: np.ndarray, t: np.ndarray | None) -> np.ndarray | None:
    """The time [s] from each of ``steps`` to the next: the recorded step
    ``dt`` (float64) where the rows are one step apart, else the difference
    of the recorded times (whole nanoseconds); None without either."""
    out = None if t is None else np.diff(t)
    if "dt" in scalars:
        s, v = scalars["dt"]
        taken = dict(zip(np.asarray(s).tolist(), np.asarray(v, np.float64).tolist()))
        single = [k for k in range(1, len(steps)) if steps[k] == steps[k - 1] + 1 and int(steps[k]) in taken]
        if out is None and len(single) < len(steps) - 1:
            return None
        out = np.zeros(len(steps) - 1) if out is None else out
        for k in single:
            out[k - 1] = taken[int(steps[k])]
    return out


def net_momentum(rec, gravity) -> dict | None:
    """The linear momentum of a recording net of the external impulse it
    records: ``steps``, ``drift`` (|P - P0| / scale), ``net`` (|P - P0 - I_g
    - I_b| / scale, :func:`mpm.diagnostics.relative_drift`), the gravity
    impulse ``I_g`` (sum M g dt over the rows, mass and time as recorded) and
    the boundary impulse ``I_b`` (sum of its per-step scalars), and
    ``missing``: what could not be netted (the boundary impulse not
    recorded; gravity without the mass or the time). None without momentum
    scalars. ``gravity``: the scene's (None: unknown)."""
    scalars = rec.scalars
    names = _per_axis(scalars, "momentum")
    if not names:
        return None
    steps = np.sort(np.asarray(sorted(set.intersection(*(set(scalars[n][0].tolist()) for n in names))), np.int64))
    if not len(steps):
        return None
    P = np.stack([np.interp(steps, *scalars[n]) for n in names], axis=1)
    missing, I_g, I_b = [], np.zeros_like(P), np.zeros_like(P)
    g = None if gravity is None else np.asarray(gravity, np.float64)[:P.shape[1]]
    t = _time_axis(rec, steps)
    if g is None:
        missing.append("gravity unknown")
    elif np.any(g != 0.0):
        dt = _steps_taken(scalars, steps, t)
        if dt is None or "mass" not in scalars:
            missing.append("gravity (no mass or time recorded)")
        else:
            M = np.interp(steps, *scalars["mass"])
            I_g[1:] = np.cumsum((M[:-1] * dt)[:, None] * g[None, :], axis=0)
    axes = _per_axis(scalars, IMPULSE)
    if len(axes) == P.shape[1]:
        I_b = np.stack([_summed(scalars[a], steps) for a in axes], axis=1)
    else:
        missing.append("boundary impulse not recorded")
    scale_series = scalars.get("momentum_scale")
    scale = float(np.nanmax(scale_series[1])) if scale_series is not None and len(scale_series[1]) else 0.0
    if not scale > 0:
        scale = float(np.nanmax(np.linalg.norm(P, axis=1)))
    return {"steps": steps, "time": t, "drift": relative_drift(P[0], P, scale),
            "net": relative_drift(P[0], P - I_g - I_b, scale), "I_g": I_g[-1], "I_b": I_b[-1], "missing": missing}


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
    """conservation.csv (final drifts from metrics.json), conservation.png
    (drift over time from the recordings: the linear momentum's net of the
    recorded external impulse) and momentum_net_drift.csv (its final values)."""
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
                  "none, and no closed wall reached); elsewhere they include the external impulse, which "
                  "the drift over time below nets out.", ""]
        lines += md_table(["dir", "scene", "label", "cells", "status", "mass", "momentum",
                           "angular momentum", "external"], [r[:8] + r[-1:] for r in rows])
    if not with_rec:
        lines += ["No recording.rrd in the job directories: no drift over time.", ""]
        return lines
    series, failed = [], []
    for j in with_rec[:MAX_RECORDINGS]:
        try:
            path = j.data_file("recording.rrd")
            assert path is not None  # with_rec: jobs with one
            rec = read(path, particles=False)  # scalars only: frames can be GBs
        except Exception as exc:
            failed.append(f"{j.rel} ({type(exc).__name__})")
            continue
        forced = external_forces(j.config)
        gravity = config_value(j.config, "scene", "gravity") if isinstance(j.config, dict) else None
        p = net_momentum(rec, gravity)
        # gravity exerts no torque about the centre of mass; the boundary's torque is not recorded
        L = drift_series(rec.scalars, "angular_momentum") if set(forced) <= {"gravity"} else None
        if p is None and L is None:
            failed.append(f"{j.rel} (no momentum scalars)")
            continue
        left = [f for f in forced if f in ("loads", "body force", "open walls", "unknown config")]
        series.append((j, rec, p, L, left + (p["missing"] if p else [])))
    if series:
        _plot(series, out, style)
        write_csv(out / "momentum_net_drift.csv",
                  ["dir", "scene", "label", "resolution", "drift", "net_drift", "gravity_impulse",
                   "boundary_impulse", "not_netted"],
                  [[j.rel, j.scene, j.label, j.resolution, float(p["drift"][-1]), float(p["net"][-1]),
                    float(np.linalg.norm(p["I_g"])), float(np.linalg.norm(p["I_b"])), "; ".join(left)]
                   for j, _, p, _, left in series if p is not None])
        lines += [f"Relative drift over time read from {len(series)} recording(s), log scale floored at "
                  f"{DRIFT_FLOOR:g}, colours by method, one line per job. Linear momentum, every run: "
                  "|P(t) - P(0) - I_g(t) - I_b(t)| / |P(0)| (against the momentum's scale where P(0) is near "
                  "zero), net of the gravity impulse I_g = sum M g dt and of the impulse I_b the walls, "
                  "colliders and kinematic regions gave the bodies (recorded per step): what is left is the "
                  "numerical drift, except for what a line names in brackets (not netted: loads, a body force, "
                  "open walls, a recording without the boundary impulse). Final values: "
                  "[momentum_net_drift.csv](momentum_net_drift.csv). Angular momentum about the centre of "
                  "mass: the runs on which nothing but gravity acts (its torque about the centre of mass is "
                  "zero; a body that reaches a closed wall shows the wall's torque).", ""]
        add_image(lines, "conservation.png", "numerical momentum drift over time")
        bare = [f"{j.rel} ({', '.join(left)})" for j, _, p, _, left in series if p is not None and left]
        if bare:
            lines += ["Not netted in the linear momentum: " + ", ".join(bare) + ".", ""]
    if len(with_rec) > MAX_RECORDINGS:
        lines += [f"Only the first {MAX_RECORDINGS} of {len(with_rec)} recordings were read.", ""]
    if failed:
        lines += ["Recordings not plotted: " + ", ".join(failed) + ".", ""]
    return lines


def _plot(series: list, out: Path, style: dict) -> None:
    """conservation.png: per scene, the linear momentum's net drift and the angular momentum's drift."""
    plt = pyplot()
    drawn = [(rec, p["steps"]) for _, rec, p, _, _ in series if p] + [(rec, L[0]) for _, rec, _, L, _ in series if L]
    use_time = all(_time_axis(rec, steps) is not None for rec, steps in drawn)
    scenes = sorted({item[0].scene for item in series}, key=natural_key)
    fig, axes = plt.subplots(len(scenes), 2, figsize=(12, 4.5 * len(scenes)), squeeze=False)
    for r, scene in enumerate(scenes):
        for c, name in enumerate(("linear momentum", "angular momentum")):
            ax = axes[r][c]
            for j, rec, p, L, left in series:
                if j.scene != scene or (p if c == 0 else L) is None:
                    continue
                steps, values = (p["steps"], p["net"]) if c == 0 else L
                label = f"{j.label} · {j.resolution}" if j.resolution else j.label
                if c == 0 and left:
                    label += f" (not netted: {', '.join(left)})"
                ax.plot(_time_axis(rec, steps) if use_time else steps, np.maximum(values, DRIFT_FLOOR), lw=1,
                        ls="--" if c == 0 and left else "-", label=label,
                        color=style[j.label][0] if j.label in style else None)
            if not ax.lines:
                ax.text(0.5, 0.5, "no run to draw", transform=ax.transAxes, ha="center", color="0.4")
            ax.set_yscale("log")
            ax.set_xlabel("time [s]" if use_time else "step")
            ax.set_ylabel(f"relative {name} drift [-]")
            ax.set_title(f"{scene}: {name}, numerical drift\n" + (
                "net of the gravity and boundary impulse (dashed: not all netted)" if c == 0
                else "runs on which nothing but gravity acts"), fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
            if ax.lines and len(ax.lines) <= 20:
                ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(out / "conservation.png", dpi=120)
    plt.close(fig)
