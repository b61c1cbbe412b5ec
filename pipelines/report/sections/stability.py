"""Stability maps (``+experiment=stability``, :mod:`pipelines.run.stability_map`):
per scene one heat map per combination (a scheme, kernel, transfer and
integrator), the failure step as colour, and the largest stable step
multiple k per combination and stiffness (stability.csv, stability.md)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...run.stability_map import MAP_KEY
from ..common import absent, fmt, md_table, pyplot, write_csv
from ..registry import section

# the letter after a failure step in the heat maps
CRITERION_LETTERS = {"energy": "e", "speed": "s", "inversion": "i", "nonfinite": "n", "outside": "o",
                     "dt_collapse": "d", "newton": "N"}
LEGEND = ("'ok': stable; otherwise the failure step and its criterion: e energy growth, s particle speed, "
          "i inversion, n non-finite value, o particles outside the domain, d time-step collapse, "
          "N Newton solve failed")


def largest_stable(rows: list[dict], E: float) -> float | None:
    """The largest k at stiffness E below which every point is stable (None:
    the smallest k already fails)."""
    best = None
    for r in sorted((r for r in rows if r["E"] == E), key=lambda r: r["k"]):
        if r["status"] != "completed":
            break
        best = r["k"]
    return best


def _combo(j) -> tuple[str, str, str, str]:
    return (j.integrator, j.scheme, j.kernel, j.transfer)


def _combo_name(c: tuple[str, str, str, str]) -> str:
    integrator, scheme, kernel, transfer = c
    return f"{scheme} · {kernel} · {transfer} · {integrator}"


def heat_maps(path: Path, scene: str, maps: list[tuple[tuple, dict]]) -> None:
    """One panel per combination: rows the stiffness E, columns the step
    multiple k; stable points blank with an 'ok', unstable ones coloured by
    their failure step (log scale) with the step and the criterion's initial."""
    from matplotlib.colors import LogNorm

    plt = pyplot()
    n = len(maps)
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.6 * rows + 0.4), squeeze=False,
                             constrained_layout=True)
    steps_max = max(m["steps"] for _, m in maps)
    norm = LogNorm(vmin=1, vmax=max(steps_max, 2))
    image = None
    for ax, (combo, m) in zip(axes.flat, maps):
        Es, ks = sorted(m["E"]), sorted(m["dt_cfl"])
        grid = np.full((len(Es), len(ks)), np.nan)
        text = {}
        for r in m["points"]:
            if r["E"] not in Es or r["k"] not in ks:
                continue
            i, jk = Es.index(r["E"]), ks.index(r["k"])
            if r["status"] == "completed":
                text[i, jk] = "ok"
            else:
                step = r.get("unstable_step") or 0
                grid[i, jk] = max(step, 1)
                text[i, jk] = f"{step}{CRITERION_LETTERS.get(r.get('criterion'), '?')}"
        image = ax.imshow(grid, origin="lower", aspect="auto", cmap="magma", norm=norm)
        for (i, jk), s in text.items():
            ax.text(jk, i, s, ha="center", va="center", fontsize=6,
                    color="black" if s == "ok" else "white")
        ax.set_xticks(range(len(ks)), [f"{k:g}" for k in ks], fontsize=6)
        ax.set_yticks(range(len(Es)), [f"{E:.0e}" for E in Es], fontsize=6)
        ax.set_title(_combo_name(combo), fontsize=7)
        ax.set_xlabel("dt / CFL limit", fontsize=6)
        ax.set_ylabel("E [Pa]", fontsize=6)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.6, label="failure step")
    fig.suptitle(scene, fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


@section(order=160, document="stability.md")
def section_stability(jobs: list, out: Path) -> list[str]:
    """Stability maps: stability.csv, one heat-map image per scene and the
    table of the largest stable step multiple per combination and stiffness."""
    title = "Stability maps: the largest stable time step"
    have = [j for j in jobs if isinstance(j.metrics.get(MAP_KEY), dict)]
    if not have:
        return absent(title, "no job of a stability-map sweep (+experiment=stability)")
    lines = [f"## {title}", "",
             "Each point runs a fixed number of steps at dt = k dx / (c + v0) (k times the explicit "
             "CFL limit at CFL number 1, c the P-wave speed at rest for stiffness E, v0 the fastest "
             "initial particle) with the blow-up detection on; stable = all steps completed. "
             "Points: [stability.csv](stability.csv).", ""]
    csv_rows = []
    for scene in sorted({j.scene for j in have}):
        members = sorted((j for j in have if j.scene == scene), key=lambda j: _combo(j))
        maps = [(_combo(j), j.metrics[MAP_KEY]) for j in members]
        Es = sorted({E for _, m in maps for E in m["E"]})
        steps = sorted({m["steps"] for _, m in maps})
        name = f"stability_{scene}.png"
        heat_maps(out / name, scene, maps)
        lines += [f"### {scene} ({', '.join(str(s) for s in steps)} steps per point)", "",
                  f"![stability maps of {scene}]({name})", "", LEGEND + ".", "",
                  "Largest stable k (every smaller k of the map stable too; '<' the smallest k "
                  "failed already):", ""]
        table = []
        for combo, m in maps:
            best = [largest_stable(m["points"], E) for E in Es]
            table.append([_combo_name(combo)] + [("<" + fmt(min(m["dt_cfl"])) if b is None else fmt(b))
                                                 if E in m["E"] else "" for b, E in zip(best, Es)])
            for r in m["points"]:
                csv_rows.append([scene, *combo, r["E"], r["k"], r["dt"], r["status"], r.get("steps"),
                                 r.get("unstable_step"), r.get("criterion"), r.get("body"), r.get("reason"),
                                 r.get("wall_time_s")])
        lines += md_table(["scheme · kernel · transfer · integrator"] + [f"E = {E:.0e} Pa" for E in Es], table)
        lines += [""]
    write_csv(out / "stability.csv", ["scene", "integrator", "scheme", "kernel", "transfer", "E", "k", "dt",
                                      "status", "steps", "unstable_step", "criterion", "body", "reason",
                                      "wall_time_s"], csv_rows)
    return lines
