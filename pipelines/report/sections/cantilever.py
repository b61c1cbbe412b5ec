"""The cantilever under a tip load (``+experiment=cantilever``,
conf/scene/cantilever_2d.yaml): per scheme and kernel, the static tip
deflection at each grid against beam theory (mpm.beams), its error, and the
observed order of convergence between successive grids (cantilever.csv); a
large deflection against the elastica."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

from mpm.beams import cantilever_tip, elastica_tip, plane_moduli

from ..common import absent, fmt, md_table, write_csv
from ..jobs import Job, config_value
from ..registry import section

SCENE = "cantilever_2d"
SMALL = 0.3  # P L^2 / (E' I) below this: the small-deflection references


def geometry(job: Job) -> dict | None:
    """The beam of a cantilever job from its composed config: free length L
    [m] (the tip to the clamp region's edge), height H [m], E [Pa], nu, the
    tip force P [N/m] (metrics: the load's total at factor 1) and the
    measured static deflection and shortening [m] (the load point's
    time-mean over the hold; None without a hold); None when the beam's
    figures are missing."""
    body = config_value(job.config, "scene", "bodies")
    regions = config_value(job.config, "scene", "regions")
    loads = job.metrics.get("loads") or []
    if not body or not regions or not loads:
        return None
    shape, clamp = body[0].get("shape") or {}, (regions[0].get("select") or {})
    material = body[0].get("material") or {}
    try:
        tip = float(shape["center"][0]) + float(shape["half_size"][0])
        edge = float(clamp["center"][0]) + float(clamp["half_size"][0])
        H = 2.0 * float(shape["half_size"][1])
        E, nu = float(material["E"]), float(material.get("nu", 0.0))
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    u = loads[0].get("displacement_hold_mean")
    return {"L": tip - edge, "H": H, "E": E, "nu": nu, "P": -float(loads[0]["total_force"][1]),
            "deflection": None if u is None else -float(u[1]), "shortening": None if u is None else -float(u[0])}


def _order(coarse: float | None, fine: float | None, ratio: float) -> float | None:
    """log(|e_coarse| / |e_fine|) / log(ratio), the observed order between two grids."""
    if coarse is None or fine is None or coarse == 0.0 or fine == 0.0:
        return None
    return math.log(abs(coarse) / abs(fine)) / math.log(ratio)


@section(order=66)
def section_cantilever(jobs: list[Job], out: Path) -> list[str]:
    """cantilever.csv: static tip deflection, error against beam theory and
    observed order per scheme, kernel and grid."""
    title = "Cantilever under a tip load: deflection against beam theory"
    have = [j for j in jobs if j.scene == SCENE]
    if not have:
        return absent(title, f"no {SCENE} job (+experiment=cantilever)")
    groups = defaultdict(list)
    large = []
    for j in have:
        g = geometry(j)
        if g is not None:
            Ep, _ = plane_moduli(g["E"], g["nu"])
            g["alpha"] = g["P"] * g["L"] ** 2 / (Ep * g["H"] ** 3 / 12.0)
            (groups[(j.scheme, j.kernel, j.transfer)] if g["alpha"] < SMALL else large).append((j, g))
        else:
            groups[(j.scheme, j.kernel, j.transfer)].append((j, None))
    headers = ["scheme", "kernel", "transfer", "cells across", "status", "deflection [mm]",
               "vs 2D elasticity [%]", "vs Euler-Bernoulli [%]", "order"]
    rows = []
    for key in sorted(groups):
        previous = None  # (cells, error) of the next coarser grid
        for j, g in sorted(groups[key], key=lambda jg: jg[0].dx or 0.0, reverse=True):
            cells = g["H"] / j.dx if g is not None and j.dx else None
            if g is None or not j.completed or g["deflection"] is None:
                rows.append([*key, fmt(cells, 3), j.status, "", "", "", ""])
                continue
            ref = cantilever_tip(g["P"], g["L"], g["H"], g["E"], g["nu"])
            err = g["deflection"] / ref["elasticity"] - 1.0
            # (a grid without a spacing, dx missing from its metrics and config, has no order)
            order = (_order(previous[1], err, cells / previous[0])
                     if previous and cells is not None and previous[0] is not None else None)
            rows.append([*key, fmt(cells, 3), j.status, fmt(1e3 * g["deflection"], 4), fmt(100 * err, 3),
                         fmt(100 * (g["deflection"] / ref["euler_bernoulli"] - 1.0), 3), fmt(order, 2)])
            previous = (cells, err)
    write_csv(out / "cantilever.csv", headers, rows)
    lines = [f"## {title}", "",
             "The static tip deflection (the time-mean of the load point's displacement over the hold, "
             "float64) of a cantilever of free length L under a tip shear force P, against 2D elasticity, "
             "P L^3 / (3 E' I) + (4 + 5 nu') P L / (2 E' H), and Euler-Bernoulli, P L^3 / (3 E' I) "
             "(mpm.beams; plane strain), per grid (cells across the beam's height H); order: the observed "
             "order of the error against elasticity between a grid and the next coarser one "
             "([cantilever.csv](cantilever.csv)).", ""] + md_table(headers, rows)
    if large:
        lh = ["scheme", "kernel", "transfer", "cells across", "P L^2 / (E' I)", "status", "deflection / L",
              "elastica", "shortening / L", "elastica "]
        lrows = []
        for j, g in sorted(large, key=lambda jg: (jg[0].scheme, jg[0].kernel, jg[0].dx or 0.0)):
            dv, dh = elastica_tip(g["alpha"])
            if g["deflection"] is None or not j.completed:
                g["deflection"] = g["shortening"] = math.nan
            lrows.append([j.scheme, j.kernel, j.transfer, fmt(g["H"] / j.dx if j.dx else None, 3),
                          fmt(g["alpha"], 3), j.status, fmt(g["deflection"] / g["L"], 4), fmt(dv, 4),
                          fmt(g["shortening"] / g["L"], 4), fmt(dh, 4)])
        lines += ["Large deflection against the elastica under a dead tip load (Bisshopp & Drucker 1945; "
                  "mpm.beams.elastica_tip, inextensible and without shear):", ""] + md_table(lh, lrows)
    return lines
