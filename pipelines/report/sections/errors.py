"""Error against run time: error_vs_time.png and pareto.csv, the Pareto front
per scene."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from ..common import absent, add_image, md_table, natural_key, pareto_front, positive, pyplot, write_csv
from ..jobs import Job, job_error
from ..registry import section


def _run_time(j: Job) -> float | None:
    """Wall seconds spent stepping (compile and logging excluded)."""
    return j.num("loop_time_s")


@section(order=20)
def section_errors(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """error_vs_time.png and pareto.csv: error against run time, Pareto front per scene."""
    title = "Error against run time"
    have = [j for j in jobs if j.completed and positive(_run_time(j))
            and (positive(j.error_displacement) or positive(j.error_velocity))]
    if not have:
        why = ("no completed job has both a run time and an error: analytic errors need a scene with an "
               "analytic solution, self-convergence errors a final_state.npz with the same initial "
               "particles (X0) as the finest job of the method, e.g. a fixed scene.particle_resolution")
        return absent(title, why)
    kinds = Counter(j.error_kind for j in have)
    lines = [f"## {title}", "",
             "Displacement error [m] (left) and velocity error [m/s] (right) at the end of the run "
             "against the wall time spent stepping [s], log-log; points of one method are joined in "
             "order of resolution, the dashed step line is the Pareto front (no other job is both "
             "faster and more accurate). Errors: "
             + ", ".join(f"{n} {'analytic' if k == 'analytic' else 'self-convergence'}"
                         for k, n in sorted(kinds.items()))
             + " (self-convergence: RMS difference to the finest job of the same method, "
               "reference in [runs.csv](runs.csv)).", ""]
    plt = pyplot()
    scenes = sorted({j.scene for j in have})
    quantities = ("displacement", "velocity")
    fig, axes = plt.subplots(len(scenes), 2, figsize=(11, 4.2 * len(scenes)), squeeze=False)
    pareto_rows = []
    for r, scene in enumerate(scenes):
        members = [j for j in have if j.scene == scene]
        for c, q in enumerate(quantities):
            ax = axes[r][c]
            pts = [j for j in members if positive(job_error(j, q))]
            for label in sorted({j.label for j in pts}, key=natural_key):
                js = sorted((j for j in pts if j.label == label), key=lambda j: j.resolution or 0)
                colour, marker = style[label]
                ax.plot([_run_time(j) for j in js], [job_error(j, q) for j in js], marker=marker,
                        color=colour, label=label)
            if pts:
                t = np.array([_run_time(j) for j in pts])
                e = np.array([job_error(j, q) for j in pts])
                front = pareto_front(t, e)
                order = np.argsort(t[front])
                ax.plot(t[front][order], e[front][order], "k--", drawstyle="steps-post", lw=1,
                        label="Pareto front")
                for i in np.flatnonzero(front)[order]:
                    j = pts[i]
                    pareto_rows.append([scene, q, j.rel, j.label, j.resolution, _run_time(j), e[i],
                                        j.error_kind])
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("run time [s]")
            ax.set_ylabel(f"{q} error [{'m' if q == 'displacement' else 'm/s'}]")
            ax.set_title(f"{scene}: {q}")
            ax.grid(True, which="both", alpha=0.3)
            if pts:
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "error_vs_time.png", dpi=120)
    plt.close(fig)
    write_csv(out / "pareto.csv", ["scene", "quantity", "dir", "label", "resolution", "loop_time_s",
                                   "error", "error_kind"], pareto_rows)
    add_image(lines, "error_vs_time.png", "error against run time")
    lines += ["Errors of the completed jobs:", ""]
    lines += md_table(["dir", "scene", "label", "cells", "kind", "run time [s]", "displacement [m]",
                       "velocity [m/s]"],
                      [[j.rel, j.scene, j.label, j.resolution, j.error_kind, _run_time(j),
                        j.error_displacement, j.error_velocity] for j in have])
    lines += ["Pareto front ([pareto.csv](pareto.csv)), fastest first:", ""]
    lines += md_table(["scene", "error", "dir", "label", "cells", "run time [s]", "error value"],
                      [[r[0], r[1], r[2], r[3], r[4], r[5], r[6]] for r in pareto_rows])
    return lines
