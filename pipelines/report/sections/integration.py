"""Explicit against implicit time integration: error against run time on a
stiff body (``+experiment=implicit_stiff``, points ``conf/stiff/``).

Every point runs the same scene, grid and particles to the same end time;
the error of a point is the RMS distance of its particles to those of the
point ``reference`` (a fine explicit run), positions [m] and velocities
[m/s]. The report tabulates steps, run time, Newton and CG iterations and
the errors, draws the position error against the wall time spent stepping
with its Pareto front, and names, for the explicit point's error and looser
targets, the cheapest point that reaches each.
"""

from __future__ import annotations

import numpy as np

from ..common import absent, md_table, pareto_front, pyplot, write_csv
from ..registry import section

POINT_KEY = "stiff"  # the sweep's config group (conf/stiff/)
REFERENCE_POINT = "reference"
EXPLICIT_POINT = "explicit"


def rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=1))))


def cheapest(points: list[tuple[str, float, float]], target: float) -> tuple[str, float, float] | None:
    """The fastest (name, run time, error) with error <= target, or None."""
    ok = [p for p in points if p[2] <= target]
    return min(ok, key=lambda p: p[1]) if ok else None


@section(order=150)
def section_integration(jobs: list, out) -> list[str]:
    """Report section of a stiff-integration sweep (override +stiff):
    integration.csv and integration.png."""
    title = "Explicit against implicit: error against run time"
    have = [j for j in jobs if POINT_KEY in j.overrides]
    if not have:
        return absent(title, "no job of a stiff-integration sweep (+stiff=...)")
    lines = [f"## {title}", "",
             f"RMS particle position and velocity error against the point `{REFERENCE_POINT}` (fine "
             "explicit) at the same end time, against the wall time spent stepping "
             "([integration.csv](integration.csv)).", ""]
    headers = ["scene", "point", "integrator", "status", "steps", "dt [s]", "ms/step", "run time [s]",
               "Newton / step", "CG / Newton", "position error [m]", "velocity error [m/s]"]
    rows, plots, notes = [], {}, []
    for scene in sorted({j.scene for j in have}):
        members = [j for j in have if j.scene == scene]
        refs = [j for j in members if j.overrides[POINT_KEY] == REFERENCE_POINT and j.completed]
        ref = refs[0].final_state() if refs else None
        pts = []
        for j in sorted(members, key=lambda j: j.overrides[POINT_KEY]):
            point = j.overrides[POINT_KEY]
            s = j.final_state() if j.completed else None
            ex = ev = None
            if s is not None and ref is not None and point != REFERENCE_POINT \
                    and s["x"].shape == ref["x"].shape \
                    and abs(s["time"] - ref["time"]) <= 1e-9 * max(1.0, ref["time"]):
                ex, ev = rms(s["x"], ref["x"]), rms(s["v"], ref["v"])
            implicit = j.metrics.get("implicit") or {}
            rows.append([scene, point, j.metrics.get("integrator") or "", j.status, j.num("steps"),
                         j.num("dt"), j.num("step_time_ms"), j.num("loop_time_s"),
                         implicit.get("newton_mean"), implicit.get("cg_per_newton"), ex, ev])
            if ex is not None and j.num("loop_time_s"):
                pts.append((point, float(j.num("loop_time_s")), ex))
        if not refs:
            notes.append(f"{scene}: no completed `{REFERENCE_POINT}` job, no errors.")
            continue
        plots[scene] = pts
        explicit = next((p for p in pts if p[0] == EXPLICIT_POINT), None)
        if explicit is not None:
            for factor in (1.0, 10.0, 100.0):
                target = factor * explicit[2]
                best = cheapest(pts, target)
                what = (f"`{best[0]}` in {best[1]:.3g} s ({explicit[1] / best[1]:.2g}x the explicit "
                        f"point's {explicit[1]:.3g} s)" if best else "no point")
                notes.append(f"{scene}: position error <= {target:.2g} m "
                             f"({factor:g}x the explicit point's): fastest {what}.")
    write_csv(out / "integration.csv", headers, rows)
    lines += md_table(headers, rows)
    for text in notes:
        lines += [text, ""]
    plots = {k: v for k, v in plots.items() if v}
    if plots:
        plt = pyplot()
        fig, axes = plt.subplots(1, len(plots), figsize=(6.5 * len(plots), 5), squeeze=False)
        for ax, (scene, pts) in zip(axes[0], sorted(plots.items())):
            t = np.array([p[1] for p in pts])
            e = np.array([p[2] for p in pts])
            front = pareto_front(t, e)
            order = np.argsort(t[front])
            ax.plot(t[front][order], e[front][order], "k--", lw=1, drawstyle="steps-post",
                    label="Pareto front")
            for name, ti, ei in pts:
                explicit = name.startswith("explicit")
                ax.plot(ti, ei, "s" if explicit else "o", color="tab:red" if explicit else "tab:blue", ms=7)
                ax.annotate(name, (ti, ei), fontsize=7, xytext=(3, 3), textcoords="offset points")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("run time [s] (stepping)")
            ax.set_ylabel("RMS position error against the reference [m]")
            ax.set_title(f"{scene}: explicit (square), implicit (circle)")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "integration.png", dpi=120)
        plt.close(fig)
        lines += ["![position error against run time](integration.png)", ""]
    return lines
