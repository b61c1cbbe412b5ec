"""Granular column collapse: the deposit's geometry and the published scaling.

A column of width L0 and height H0 = a L0 stands against a back wall on a
rough floor and collapses. Measured from a run's final particle positions
(``final_state.npz``), with the particle spacing h (the extent of a particle
is half a spacing beyond its centre):

* run-out (L_inf - L0) / L0, L_inf the deposit's front: the 99.9th
  percentile of x (a few grains that bounce ahead are not the deposit);
* final height H_inf / L0: the 99.9th percentile of the height above the floor;
* final slope angle: a straight line fitted to the deposit's surface (the
  highest particle per column of width 2 h) between 20 % and 80 % of its
  length, in degrees.

Published scaling (dry grains, quasi-2D channels; secondary sources: Lagree,
Staron & Popinet 2011, JFM 686, and K. Kumar's thesis, Cambridge 2015):
  run-out, Lube et al. 2005 (the same law quoted for Lajeunesse et al.'s
  channel): (L_inf - L0)/L0 = 1.2 a (a < 1.8), 1.9 a^(2/3) (a > 2.8), both
  branches given in the transition;
  run-out as Lagree et al. tabulate Lajeunesse et al. 2005: 1.8 a (a < 3),
  2.3 a^(2/3) (a > 3);
  final height: H_inf / L0 = a^(1/3) for a > 0.7 (Lajeunesse et al. 2005, 2D),
  a^0.4 for a > 1.15 (Lube et al. 2005, as tabulated by Lagree et al.).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..common import absent, md_table, natural_key, write_csv
from ..registry import section


@dataclass
class Deposit:
    aspect: float  # a = H0 / L0 of the initial column
    L0: float  # [m] initial width
    runout: float  # (L_inf - L0) / L0
    height: float  # H_inf / L0
    slope_deg: float  # final surface angle [deg]


def spacing(X0: np.ndarray, axis: int = 0) -> float:
    """Particle spacing h of a lattice-sampled body [m]."""
    u = np.unique(np.round(X0[:, axis], 12))
    return float(np.min(np.diff(u))) if len(u) > 1 else 0.0


def deposit(x: np.ndarray, X0: np.ndarray) -> Deposit:
    """The deposit of a column that started as the particles ``X0`` (n, 2)
    against a wall at its low-x side, resting on the floor at its low y."""
    h = spacing(X0)
    wall = X0[:, 0].min() - h / 2
    floor = X0[:, 1].min() - h / 2
    L0 = X0[:, 0].max() + h / 2 - wall
    H0 = X0[:, 1].max() + h / 2 - floor
    front = np.quantile(x[:, 0], 0.999) + h / 2 - wall
    top = np.quantile(x[:, 1], 0.999) + h / 2 - floor
    # surface: the highest particle per column of width 2 h
    edges = np.arange(wall, wall + front + 2 * h, 2 * h)
    idx = np.digitize(x[:, 0], edges) - 1
    cols = np.unique(idx[(idx >= 0) & (idx < len(edges) - 1)])
    xs = np.array([0.5 * (edges[c] + edges[c + 1]) - wall for c in cols])
    ys = np.array([x[idx == c, 1].max() + h / 2 - floor for c in cols])
    keep = (xs > 0.2 * front) & (xs < 0.8 * front)
    slope = -np.polyfit(xs[keep], ys[keep], 1)[0] if keep.sum() >= 2 else math.nan
    return Deposit(aspect=H0 / L0, L0=L0, runout=(front - L0) / L0, height=top / L0,
                   slope_deg=math.degrees(math.atan(slope)))


def lube_runout(a: float) -> list[float]:
    """(L_inf - L0) / L0 of Lube et al. 2005 (both branches in the transition)."""
    out = []
    if a < 2.8:
        out.append(1.2 * a)
    if a > 1.8:
        out.append(1.9 * a ** (2 / 3))
    return out


def lajeunesse_runout(a: float) -> list[float]:
    return [1.8 * a] if a < 3 else [2.3 * a ** (2 / 3)]


def lube_height(a: float) -> float:
    """H_inf / L0 of Lube et al. 2005."""
    return a if a < 1.15 else a**0.4


def lajeunesse_height(a: float) -> float:
    """H_inf / L0 of Lajeunesse et al. 2005 (2D)."""
    return a if a < 0.7 else a ** (1 / 3)


def nearest(value: float, candidates: list[float]) -> float:
    """The candidate of a scaling law closest to ``value`` (relative)."""
    return min(candidates, key=lambda c: abs(value / c - 1))


DEPOSIT_HEADERS = ["a", "runout", "Lube", "Lagree (Lajeunesse)", "height", "Lajeunesse height",
                   "Lube height", "slope deg"]


def deposit_row(d: Deposit) -> list:
    """A deposit beside the published scaling (DEPOSIT_HEADERS)."""
    return [round(d.aspect, 2), d.runout, nearest(d.runout, lube_runout(d.aspect)),
            lajeunesse_runout(d.aspect)[0], d.height, lajeunesse_height(d.aspect),
            lube_height(d.aspect), d.slope_deg]


def main(argv: list[str] | None = None) -> int:
    """python -m pipelines.granular <run dir> ...: the deposit of finished runs."""
    import sys
    from pathlib import Path

    from ...config.arguments import Parser

    parser = Parser(prog="python -m pipelines.granular", description=main.__doc__)
    parser.add_argument("runs", nargs="+", type=Path, help="run directories (with final_state.npz)")
    args = parser.parse_args(argv)
    rows = []
    for run in args.runs:
        path = run / "final_state.npz" if run.is_dir() else run
        try:
            with np.load(path) as f:
                rows.append((deposit(f["x"].astype(float), f["X0"].astype(float)), run))
        except (OSError, ValueError, KeyError, EOFError) as e:
            why = "no final_state.npz" if not path.is_file() else f"not a run's final state ({type(e).__name__})"
            print(f"error: runs: {run}: {why}; accepted: the directories of finished column-collapse runs",
                  file=sys.stderr)
            return 2
    print(" ".join(f"{h:>10}" for h in DEPOSIT_HEADERS) + "  run")
    for d, run in rows:
        print(" ".join(f"{v:>10.3f}" for v in deposit_row(d)) + f"  {run}")
    return 0


@section(order=80)
def section_granular(jobs: list, out) -> list[str]:
    """Report section: the deposit of every column-collapse job (scenes
    ``column_collapse*``) against the published scaling (granular.csv)."""
    title = "Granular column collapse"
    have = [j for j in jobs if j.scene.startswith("column_collapse")]
    if not have:
        return absent(title, "no column-collapse job")
    rows = []
    for j in sorted(have, key=lambda j: (j.scene, natural_key(j.label))):
        s = j.final_state()
        if s is None or j.status not in ("completed", "unstable"):
            rows.append([j.scene, j.label, j.status, None, None, None, None, None, None, None, None])
            continue
        d = deposit(s["x"].astype(float), s["X0"].astype(float))
        rows.append([j.scene, j.label, j.status, *deposit_row(d), j.num("updates_per_1e4_steps")])
    headers = ["scene", "label", "status", *DEPOSIT_HEADERS, "updates per 1e4"]
    write_csv(out / "granular.csv", headers, rows)
    lines = [f"## {title}", "",
             "Deposit of each column at the end of the run ([granular.csv](granular.csv)): run-out "
             "(L_inf - L0) / L0, final height H_inf / L0 and surface slope (pipelines.granular), with "
             "the published scaling (pipelines.granular; Lube et al. 2005: the branch nearest the "
             "result where a lies between the branches). An unstable run's deposit is where its "
             "particles were when it stopped.", ""]
    return lines + md_table(headers, rows)


if __name__ == "__main__":
    raise SystemExit(main())
