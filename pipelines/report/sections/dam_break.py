"""The 2D dam break against the experiment of Martin & Moyce (1952).

J. C. Martin and W. J. Moyce, "An experimental study of the collapse of
liquid columns on a rigid horizontal plane", Phil. Trans. R. Soc. Lond. A
244 (882), 312-324 (1952), doi:10.1098/rsta.1952.0006: a water column of
width a and height n^2 a = 2a (a = 2.25 in) collapses along a dry floor.
Their tables give the times at which fixed quarter-inch stations were
reached (every Z below is k/9, every H k/18), in two dimensionless forms:

* Table 2, the surge front's distance z from the back wall, Z = z / a,
  against T = n t sqrt(g / a) = t sqrt(2 g / a);
* Table 6, the residual column height h at the back wall, H = h / (n^2 a),
  against tau = t sqrt(g / a) (not T: read against T their first points
  would fall faster than free fall allows, H >= 1 - tau^2 / 4).

Both as transcribed in the Ocellaris code's ``scripts/plot_dam_break.py``
(TormodLandet/Ocellaris), whose front table also agrees within 0.05 in T with
the digitised Figure 3 of PySPH's ``pysph/examples/db_exp_data.py``. The
published numerical solution set beside them is the MPS front of Koshizuka
& Oka (1996, Nucl. Sci. Eng. 123, 421-434) for the same column, as
digitised in that PySPH file (``ko_mps_data``); it leads the experiment by
0.19-0.31 in T at equal Z, as simulations of this experiment usually do in
its first instants (its diaphragm's removal is not part of any simulation).

The simulated front is measured from the column's initial back face on
every logged frame, two ways: the largest particle x plus half a particle
spacing (any particle, detached spray included), and the same over the
water connected to the bulk only (:func:`connected_front`: particles
chained by gaps under two particle spacings to the column's back corner;
droplets thrown ahead of the surge do not count). The column's height is
the largest particle y within two particle spacings of the back wall plus
half a spacing, above the floor. The lead over the experiment is also
given as a time: the mean of T_sim(Z) - T_exp(Z) over the experiment's
stations the run reaches (negative: the simulation is early).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...recording import recordings
from ..common import absent, add_image, md_table, natural_key, pyplot, write_csv
from ..jobs import Job
from ..registry import section

MARTIN_MOYCE_T = np.array([0.41, 0.84, 1.19, 1.43, 1.63, 1.83, 1.98, 2.20, 2.32, 2.51, 2.65, 2.83, 2.98,
                           3.11, 3.33])
MARTIN_MOYCE_Z = np.array([1.11, 1.22, 1.44, 1.67, 1.89, 2.11, 2.33, 2.56, 2.78, 3.00, 3.22, 3.44, 3.67,
                           3.89, 4.11])
# Table 6: H = h / (2a) against tau = t sqrt(g / a)
MARTIN_MOYCE_TAU = np.array([0.56, 0.77, 0.93, 1.08, 1.28, 1.46, 1.66, 1.84, 2.00, 2.21, 2.45, 2.70, 3.06,
                             3.44, 4.20, 5.25, 7.40])
MARTIN_MOYCE_H = np.array([0.94, 0.89, 0.83, 0.78, 0.72, 0.67, 0.61, 0.56, 0.50, 0.44, 0.39, 0.33, 0.28,
                           0.22, 0.17, 0.11, 0.06])
# Koshizuka & Oka (1996), MPS: Z against T = t sqrt(2 g / a)
MPS_T = np.array([0.000, 0.227, 0.416, 0.591, 0.778, 0.958, 1.095, 1.226, 1.381, 1.536, 1.684, 1.858, 2.043,
                  2.278, 2.451, 2.604, 2.752, 2.943])
MPS_Z = np.array([1.002, 1.019, 1.091, 1.205, 1.351, 1.512, 1.637, 1.771, 1.931, 2.100, 2.268, 2.480, 2.707,
                  3.004, 3.251, 3.481, 3.700, 3.997])


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


def fronts(job: Job) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """(T, Z of any particle, Z of the bulk (:func:`connected_front`), H
    the column's height over 2a) from the job's recording (read once), or
    None. H's time is tau = T / sqrt(2)."""
    cfg = job.config or {}
    try:
        scene = cfg["scene"]
        shape = scene["bodies"][0]["shape"]
        center, half = np.asarray(shape["center"], float), np.asarray(shape["half_size"], float)
        g = abs(float(scene["gravity"][1]))
        ppc = int(scene["ppc"])
        dx = job.num("dx")  # the run's (the saved config may hold the size's interpolation)
    except (KeyError, TypeError, IndexError, ValueError):
        return None
    if dx is None:
        return None
    path = job.path / "recording.rrd"
    if not path.is_file():
        return None
    rec = recordings.read(path)
    a = 2.0 * half[0]
    back, floor = center[0] - half[0], center[1] - half[1]
    spacing = dx / np.sqrt(ppc)
    corner = np.array([back, floor])
    z = np.array([x[:, 0].max() for x in rec.positions]) + 0.5 * spacing - back
    z_bulk = np.array([connected_front(x, spacing, corner) for x in rec.positions]) + 0.5 * spacing - back
    h = np.array([column_height(x, back, spacing) for x in rec.positions]) + 0.5 * spacing - floor
    return rec.times * np.sqrt(2.0 * g / a), z / a, z_bulk / a, h / (2.0 * a)


def column_height(x: np.ndarray, back: float, spacing: float) -> float:
    """The largest y [m] of the particles ``x`` within two spacings of the
    back wall at ``back`` (NaN when none is)."""
    near = x[:, 0] < back + 2.0 * spacing
    return float(x[near, 1].max()) if near.any() else float("nan")


def deviations(T: np.ndarray, Z: np.ndarray) -> tuple[int, float, float, float | None]:
    """(points, mean and largest relative deviation from Martin & Moyce at
    their times within the run, Z at T = 3)."""
    inside = MARTIN_MOYCE_T <= T.max()
    sim = np.interp(MARTIN_MOYCE_T[inside], T, Z)
    rel = (sim - MARTIN_MOYCE_Z[inside]) / MARTIN_MOYCE_Z[inside]
    return (int(inside.sum()), float(np.mean(rel)), float(np.max(np.abs(rel))),
            float(np.interp(3.0, T, Z)) if T.max() >= 3.0 else None)


def time_lead(T: np.ndarray, Z: np.ndarray, T_ref: np.ndarray, Z_ref: np.ndarray) -> float | None:
    """Mean of T(Z) - T_ref(Z) [-] over the reference's stations Z_ref that
    the curve (T, Z) reaches (its first arrival there; Z made monotone by its
    running maximum), None if it reaches none: negative when it is early."""
    Zm = np.maximum.accumulate(Z)
    reached = (Z_ref <= Zm.max()) & (Z_ref >= Zm[0])
    if not reached.any():
        return None
    first = []
    for z in Z_ref[reached]:  # the first frame at or past z, interpolated from the one before
        k = int(np.argmax(Zm >= z))
        if k == 0 or Zm[k] == Zm[k - 1]:
            first.append(T[k])
        else:
            first.append(T[k - 1] + (z - Zm[k - 1]) / (Zm[k] - Zm[k - 1]) * (T[k] - T[k - 1]))
    return float(np.mean(np.array(first) - T_ref[reached]))


def height_deviation(tau: np.ndarray, H: np.ndarray) -> tuple[int, float | None]:
    """(points, mean of H_sim - H_exp at Table 6's times within the run)."""
    ok = np.isfinite(H)
    inside = MARTIN_MOYCE_TAU <= tau[ok].max() if ok.any() else np.zeros(len(MARTIN_MOYCE_TAU), bool)
    if not inside.any():
        return 0, None
    sim = np.interp(MARTIN_MOYCE_TAU[inside], tau[ok], H[ok])
    return int(inside.sum()), float(np.mean(sim - MARTIN_MOYCE_H[inside]))


@section(order=140)
def section_dam_break(jobs: list[Job], out: Path) -> list[str]:
    """dam_break.csv and dam_break.png: the surge front Z(T) against Martin & Moyce."""
    title = "Dam break against Martin & Moyce (1952)"
    have = [j for j in jobs if j.completed and j.scene == "dam_break_2d"]
    if not have:
        return []
    curves, rows = {}, []
    for j in sorted(have, key=lambda j: (j.resolution or 0, natural_key(j.label))):
        f = fronts(j)
        if f is None or len(f[0]) < 2:
            continue
        T, Z, Z_bulk, H = f
        curves[(j.label, j.resolution)] = (T, Z_bulk, H)
        rows.append([j.label, j.resolution, j.rel, *deviations(T, Z), *deviations(T, Z_bulk)[1:],
                     time_lead(T, Z_bulk, MARTIN_MOYCE_T, MARTIN_MOYCE_Z), time_lead(T, Z_bulk, MPS_T, MPS_Z),
                     *height_deviation(T / np.sqrt(2.0), H)])
    if not rows:
        return absent(title, "no dam_break_2d job has a readable recording")
    write_csv(out / "dam_break.csv", ["label", "resolution", "dir", "points", "mean_relative_deviation",
                                      "max_relative_deviation", "Z_at_T3", "bulk_mean_relative_deviation",
                                      "bulk_max_relative_deviation", "bulk_Z_at_T3", "lead_T_experiment",
                                      "lead_T_mps", "height_points", "height_mean_deviation"], rows)
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
    ax.plot(MARTIN_MOYCE_T, MARTIN_MOYCE_Z, "ko", label="Martin & Moyce 1952 (n² = 2), Table 2")
    ax.plot(MPS_T, MPS_Z, "k--", lw=1, label="Koshizuka & Oka 1996, MPS")
    bx.plot(MARTIN_MOYCE_TAU, MARTIN_MOYCE_H, "ko", label="Martin & Moyce 1952 (n² = 2), Table 6")
    for (label, res), (T, Z, H) in curves.items():
        line, = ax.plot(T, Z, label=f"{label} · {res} cells")
        bx.plot(T / np.sqrt(2.0), H, color=line.get_color(), label=f"{label} · {res} cells")
    ax.set_xlabel("T = t √(2g/a) [-]")
    ax.set_ylabel("surge front Z = z / a [-]")
    ax.set_xlim(0, max(3.5, MARTIN_MOYCE_T.max() + 0.2))
    ax.set_ylim(0.8, 5.0)
    ax.set_title("surge front")
    bx.set_xlabel("τ = t √(g/a) [-]")
    bx.set_ylabel("column height H = h / (2a) [-]")
    bx.set_xlim(0, max(3.0, min(MARTIN_MOYCE_TAU.max(), max(T.max() for T, _, _ in curves.values()) / np.sqrt(2.0))))
    bx.set_title("residual column height at the back wall")
    for axis in (ax, bx):
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "dam_break.png", dpi=120)
    plt.close(fig)
    lines = [f"## {title}", "",
             "Surge front Z = z/a against T = t √(2g/a) for the column of width a and height 2a, with "
             "Martin & Moyce's measurements (Table 2) and Koshizuka & Oka's MPS solution; deviations are "
             "relative, at the measured times, for the front of any particle and of the water connected to "
             "the bulk (spray left out; the plot draws the latter); the lead is the mean of T_sim(Z) - T_ref(Z) "
             "at the reference's stations (negative: early). Column height H = h/(2a) at the back wall "
             "against τ = t √(g/a) with their Table 6: mean H_sim - H_exp ([dam_break.csv](dam_break.csv)).", ""]
    add_image(lines, "dam_break.png", "dam-break surge front and column height")
    lines += md_table(["label", "cells", "points", "mean deviation", "largest deviation", "Z at T = 3",
                       "bulk: mean deviation", "largest", "Z at T = 3", "lead in T vs experiment",
                       "vs MPS", "height: points", "mean H deviation"],
                      [[r[0], r[1], *r[3:]] for r in rows])
    return lines
