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

Published scaling (dry grains, quasi-2D channels), as tabulated by Lagree,
Staron & Popinet (2011, JFM 686):
  Lube et al. 2005:        (L_inf - L0)/L0 = 1.2 a (a < 1.8), 1.9 a^(2/3) (a > 2.8);
                           H_inf / L0 = a (a < 1.15), a^0.4 beyond;
  Lajeunesse et al. 2005:  (L_inf - L0)/L0 = 1.8 a (a < 3), 2.3 a^(2/3) (a > 3).
Between the two branches of a law both are given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


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
    return [1.2 * a] * (a < 2.8) + [1.9 * a ** (2 / 3)] * (a > 1.8)


def lajeunesse_runout(a: float) -> list[float]:
    return [1.8 * a] if a < 3 else [2.3 * a ** (2 / 3)]


def lube_height(a: float) -> float:
    """H_inf / L0 of Lube et al. 2005."""
    return a if a < 1.15 else a**0.4


def nearest(value: float, candidates: list[float]) -> float:
    """The candidate of a scaling law closest to ``value`` (relative)."""
    return min(candidates, key=lambda c: abs(value / c - 1))
