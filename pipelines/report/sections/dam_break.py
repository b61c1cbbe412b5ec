"""The 2D dam break against the experiment of Martin & Moyce (1952).

J. C. Martin and W. J. Moyce, "An experimental study of the collapse of
liquid columns on a rigid horizontal plane", Phil. Trans. R. Soc. Lond. A
244 (882), 312-324 (1952), doi:10.1098/rsta.1952.0006: a water column of
width a and height n^2 a = 2a (a = 2.25 in) collapses along a dry floor; the
surge front's distance z from the back wall is given in the dimensionless
form Z = z / a against T = t sqrt(2 g / a). The points below are their
tabulated surge-front data for n^2 = 2, as reproduced in the free-surface
flow literature (e.g. Koshizuka & Oka 1996).

The simulated front is measured from the column's initial back face on
every logged frame, two ways: the largest particle x plus half a particle
spacing (any particle, detached spray included), and the same over the
water connected to the bulk only (:func:`connected_front`: particles
chained by gaps under two particle spacings to the column's back corner;
droplets thrown ahead of the surge do not count).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...recording import recordings
from ..common import absent, add_image, md_table, pyplot, write_csv
from ..jobs import Job
from ..registry import section

MARTIN_MOYCE_T = np.array([0.41, 0.84, 1.19, 1.43, 1.63, 1.83, 1.98, 2.20, 2.32, 2.51, 2.65, 2.83, 2.98,
                           3.11, 3.33])
MARTIN_MOYCE_Z = np.array([1.11, 1.22, 1.44, 1.67, 1.89, 2.11, 2.33, 2.56, 2.78, 3.00, 3.22, 3.44, 3.67,
                           3.89, 4.11])


def connected_front(x: np.ndarray, spacing: float, origin: np.ndarray) -> float:
    """The largest x [m] of the particles ``x`` connected to the one nearest
    ``origin`` (the column's back bottom corner): particles are binned into
    cells two spacings wide, and the occupied cells 8-connected to the
    origin's cell are grown from it by repeated dilation (NumPy only); a
    particle belongs when its cell does. Spray whose gap to the bulk exceeds
    about two spacings is left out."""
    h = 2.0 * spacing
    lo = x.min(axis=0)
    ij = np.floor((x - lo) / h).astype(np.int64)
    shape = tuple(ij.max(axis=0) + 3)
    occupied = np.zeros(shape, bool)
    occupied[ij[:, 0] + 1, ij[:, 1] + 1] = True
    seed = ij[np.argmin(((x - origin) ** 2).sum(axis=1))] + 1
    reached = np.zeros(shape, bool)
    reached[seed[0], seed[1]] = True
    while True:
        grown = reached.copy()
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                grown[1:-1, 1:-1] |= reached[1 + di:shape[0] - 1 + di, 1 + dj:shape[1] - 1 + dj]
        grown &= occupied
        if (grown == reached).all():
            break
        reached = grown
    inside = reached[ij[:, 0] + 1, ij[:, 1] + 1]
    return float(x[inside, 0].max())


def front(job: Job) -> tuple[np.ndarray, np.ndarray] | None:
    """(T, Z) of the job's surge front (any particle) from its recording, or None."""
    f = fronts(job)
    return None if f is None else f[:2]


def fronts(job: Job) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(T, Z of any particle, Z of the bulk, :func:`connected_front`) from
    the job's recording (read once), or None."""
    cfg = job.config or {}
    try:
        scene = cfg["scene"]
        shape = scene["bodies"][0]["shape"]
        center, half = np.asarray(shape["center"], float), np.asarray(shape["half_size"], float)
        g = abs(float(scene["gravity"][1]))
        ppc = int(scene["ppc"])
        dx = float(job.num("dx"))  # the run's (the saved config may hold the size's interpolation)
    except (KeyError, TypeError, IndexError, ValueError):
        return None
    path = job.path / "recording.rrd"
    if not path.is_file():
        return None
    rec = recordings.read(path)
    a = 2.0 * half[0]
    back = center[0] - half[0]
    spacing = dx / np.sqrt(ppc)
    corner = np.array([back, center[1] - half[1]])
    z = np.array([x[:, 0].max() for x in rec.positions]) + 0.5 * spacing - back
    z_bulk = np.array([connected_front(x, spacing, corner) for x in rec.positions]) + 0.5 * spacing - back
    return rec.times * np.sqrt(2.0 * g / a), z / a, z_bulk / a


def deviations(T: np.ndarray, Z: np.ndarray) -> tuple[int, float, float, float | None]:
    """(points, mean and largest relative deviation from Martin & Moyce at
    their times within the run, Z at T = 3)."""
    inside = MARTIN_MOYCE_T <= T.max()
    sim = np.interp(MARTIN_MOYCE_T[inside], T, Z)
    rel = (sim - MARTIN_MOYCE_Z[inside]) / MARTIN_MOYCE_Z[inside]
    return (int(inside.sum()), float(np.mean(rel)), float(np.max(np.abs(rel))),
            float(np.interp(3.0, T, Z)) if T.max() >= 3.0 else None)


@section(order=140)
def section_dam_break(jobs: list[Job], out: Path) -> list[str]:
    """dam_break.csv and dam_break.png: the surge front Z(T) against Martin & Moyce."""
    title = "Dam break against Martin & Moyce (1952)"
    have = [j for j in jobs if j.completed and j.scene == "dam_break_2d"]
    if not have:
        return []
    curves, rows = {}, []
    for j in sorted(have, key=lambda j: (j.resolution or 0, j.label)):
        f = fronts(j)
        if f is None or len(f[0]) < 2:
            continue
        T, Z, Z_bulk = f
        curves[(j.label, j.resolution)] = (T, Z_bulk)
        rows.append([j.label, j.resolution, j.rel, *deviations(T, Z), *deviations(T, Z_bulk)[1:]])
    if not rows:
        return absent(title, "no dam_break_2d job has a readable recording")
    write_csv(out / "dam_break.csv", ["label", "resolution", "dir", "points", "mean_relative_deviation",
                                      "max_relative_deviation", "Z_at_T3", "bulk_mean_relative_deviation",
                                      "bulk_max_relative_deviation", "bulk_Z_at_T3"], rows)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    ax.plot(MARTIN_MOYCE_T, MARTIN_MOYCE_Z, "ko", label="Martin & Moyce 1952 (n² = 2)")
    for (label, res), (T, Z) in curves.items():
        ax.plot(T, Z, label=f"{label} · {res} cells")
    ax.set_xlabel("T = t √(2g/a)")
    ax.set_ylabel("Z = z / a")
    ax.set_xlim(0, max(3.5, MARTIN_MOYCE_T.max() + 0.2))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "dam_break.png", dpi=120)
    plt.close(fig)
    lines = [f"## {title}", "",
             "Surge front Z = z/a against T = t √(2g/a) for the column of width a and height 2a, with "
             "Martin & Moyce's measurements; deviations are relative, at their measured times, for the "
             "front of any particle and of the water connected to the bulk (spray left out; the plot "
             "draws the latter) ([dam_break.csv](dam_break.csv)).", ""]
    add_image(lines, "dam_break.png", "dam-break surge front")
    lines += md_table(["label", "cells", "points", "mean deviation", "largest deviation", "Z at T = 3",
                       "bulk: mean deviation", "largest", "Z at T = 3"],
                      [[r[0], r[1], r[3], r[4], r[5], r[6], r[7], r[8], r[9]] for r in rows])
    return lines
