"""Convergence: error against grid spacing with the fitted orders
(convergence.png, convergence.csv)."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import cast

import numpy as np

from ..common import absent, add_image, md_table, positive, pyplot, write_csv
from ..jobs import Job, job_error
from ..registry import section


def fit_slope(h, e) -> tuple[float, float]:
    """Least-squares line log10(e) = slope * log10(h) + intercept over the
    points with h > 0 and e > 0; returns (slope, intercept). Raises ValueError
    with fewer than two distinct h."""
    h, e = np.asarray(h, dtype=np.float64), np.asarray(e, dtype=np.float64)
    ok = np.isfinite(h) & np.isfinite(e) & (h > 0) & (e > 0)
    if np.unique(h[ok]).size < 2:
        raise ValueError("a slope needs errors at two or more distinct spacings")
    slope, intercept = np.polyfit(np.log10(h[ok]), np.log10(e[ok]), 1)
    return float(slope), float(intercept)


@section(order=30)
def section_convergence(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """convergence.png and convergence.csv: error against dx with fitted orders."""
    title = "Convergence"
    have = [j for j in jobs if j.completed and positive(j.dx)
            and (positive(j.error_displacement) or positive(j.error_velocity))]
    if not have:
        return absent(title, "no completed job has an error and a grid spacing (see the section above)")
    groups: dict[tuple, list[Job]] = defaultdict(list)
    for j in have:
        groups[(j.scene, j.label)].append(j)
    quantities = ("displacement", "velocity")
    fits: dict[tuple, dict] = {}
    rows = []
    for key, members in sorted(groups.items()):
        row = [key[0], key[1], "/".join(sorted({j.error_kind for j in members}))]
        for q in quantities:
            pts = [(j.dx, job_error(j, q)) for j in members if positive(job_error(j, q))]
            h, e = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
            try:
                slope, intercept = fit_slope(h, e)
                fits[(key, q)] = {"h": h, "slope": slope, "intercept": intercept}
            except ValueError:
                slope = intercept = None
            row += [len(pts), slope, intercept]
        rows.append(row)
    write_csv(out / "convergence.csv",
              ["scene", "label", "error_kind", "n_displacement", "slope_displacement",
               "intercept_displacement", "n_velocity", "slope_velocity", "intercept_velocity"], rows)
    if not fits:
        lines = absent(title, "no method has errors at two or more grid spacings")
        lines.insert(-1, "The points are in [convergence.csv](convergence.csv).")
        return lines
    plt = pyplot()
    scenes = sorted({k[0] for k in groups})
    fig, axes = plt.subplots(len(scenes), 2, figsize=(11, 4.2 * len(scenes)), squeeze=False)
    for r, scene in enumerate(scenes):
        for c, q in enumerate(quantities):
            ax = axes[r][c]
            for (sc, label), members in sorted(groups.items()):
                if sc != scene:
                    continue
                js = sorted((j for j in members if positive(job_error(j, q))),
                            key=lambda j: cast(float, j.dx))  # (have: a positive dx)
                if not js:
                    continue
                colour, marker = style[label]
                fit = fits.get(((sc, label), q))
                name = label if fit is None else f"{label} (order {fit['slope']:.2f})"
                ax.plot([j.dx for j in js], [job_error(j, q) for j in js], marker, color=colour, label=name)
                if fit is not None:
                    h = np.geomspace(fit["h"].min(), fit["h"].max(), 20)
                    ax.plot(h, 10 ** fit["intercept"] * h ** fit["slope"], "-", color=colour, lw=1)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("dx [m]")
            ax.set_ylabel(f"{q} error [{'m' if q == 'displacement' else 'm/s'}]")
            ax.set_title(f"{scene}: {q}")
            ax.grid(True, which="both", alpha=0.3)
            if ax.lines:
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "convergence.png", dpi=120)
    plt.close(fig)
    lines = [f"## {title}", "",
             "Displacement and velocity errors against the grid spacing dx [m], log-log, per method "
             "with the least-squares line through log10(error) against log10(dx); its slope is the "
             "observed order of convergence ([convergence.csv](convergence.csv)).", ""]
    add_image(lines, "convergence.png", "error against grid spacing")
    lines += md_table(["scene", "label", "error", "points", "order (displacement)", "order (velocity)"],
                      [[r[0], r[1], r[2], max(r[3], r[6]), r[4], r[7]] for r in rows])
    return lines
