"""Stability maps (``+experiment=stability``): stable or unstable over the
time step, in multiples of the explicit CFL limit, and the stiffness, one map
per job (a scene, scheme, kernel, transfer and integrator).

A map job runs every point (E, k) of ``stability_map`` in its own process,
one after the other (the kernels compile once): the scene with every body's
Young's modulus (a fluid's bulk modulus) set to E, the fixed step

    dt = k dx / (c(E) + v0),

the explicit limit at CFL number 1 (c the body's P-wave speed at rest, v0
the fastest initial particle, bounded by |u| + |omega| r_max), for
``steps`` steps with the blow-up detection of mpm.stability on. A point is
stable when it completes its steps; otherwise it keeps its failure step,
criterion and reason (a point that fails with an error is kept as
``failed``). The job's metrics.json holds the whole map
(``stability_map``); each point's own metrics are ``points/<name>/point.json``.
A point is reproduced by the job's config (``.hydra``) with every body's
stiffness set to E, ``run.dt`` = the point's ``dt`` and ``run.steps``.

The report (:func:`section_stability`) draws per scene one heat map per
combination, the failure step as colour, and tabulates the largest stable
multiple k per combination and stiffness.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

import mpm

from ..run.runner import execute, write_metrics
from ..recording.sinks import Sink
from ..config.validate import MapSpec

MAP_KEY = "stability_map"
# the letter after a failure step in the heat maps
CRITERION_LETTERS = {"energy": "e", "speed": "s", "inversion": "i", "nonfinite": "n", "outside": "o",
                     "dt_collapse": "d", "newton": "N"}
LEGEND = ("'ok': stable; otherwise the failure step and its criterion: e energy growth, s particle speed, "
          "i inversion, n non-finite value, o particles outside the domain, d time-step collapse, "
          "N Newton solve failed")


def with_stiffness(material, E: float):
    """``material`` with its stiffness set: E for solids, K for fluids."""
    names = {f.name for f in dataclasses.fields(material)}
    if "E" not in names and "K" not in names:
        raise ValueError(f"material {material.name!r} has neither E nor K: a stability map cannot set its stiffness")
    key = "E" if "E" in names else "K"
    return dataclasses.replace(material, **{key: float(E)})


def initial_speed(scene) -> float:
    """An upper bound of the fastest initial particle [m/s]: |u| + |omega| r_max
    per body (r_max the farthest corner of the shape's bounds)."""
    out = 0.0
    for b in scene.bodies:
        u = float(np.linalg.norm(b.velocity)) if b.velocity is not None else 0.0
        if b.angular_velocity is not None:
            lo, hi = (np.asarray(v, float) for v in b.shape.bounds())
            c = 0.5 * (lo + hi)
            u += float(np.linalg.norm(b.angular_velocity)) * float(np.linalg.norm(hi - c))
        out = max(out, u)
    return out


def cfl_limit(scene) -> float:
    """dx / (c + v0) [s]: the explicit step limit at CFL number 1
    (mpm.cfl_dt), c the fastest body's wave speed at rest."""
    c = max(b.material.wave_speed() for b in scene.bodies)
    return mpm.cfl_dt(scene.dx, c, initial_speed(scene), 1.0)


def point_name(E: float, k: float) -> str:
    return f"E{E:g}_k{k:g}"


def point_spec(spec, E: float, k: float, steps: int):
    """The run of one map point (mpm scene with stiffness E, fixed step k
    times the CFL limit, ``steps`` steps, no particles logged)."""
    scene = dataclasses.replace(spec.scene, bodies=[dataclasses.replace(b, material=with_stiffness(b.material, E))
                                                    for b in spec.scene.bodies])
    run = dataclasses.replace(spec.run, steps=steps, duration=None, dt=k * cfl_limit(scene))
    log = dataclasses.replace(spec.log, every=0, scalars=False, progress=False)
    return dataclasses.replace(spec, scene=scene, run=run, log=log)


def run_map(spec, points: MapSpec, out_dir: Path, identity: dict | None = None) -> dict:
    """Run every point of the map; the job's metrics (status completed
    unless interrupted) with the map under ``stability_map``."""
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    rows = []
    status = "completed"
    for E in points.E:
        for k in points.dt_cfl:
            ps = point_spec(spec, E, k, points.steps)
            pdir = out_dir / "points" / point_name(E, k)
            try:
                m = execute(ps, pdir, sink=Sink())
            except Exception as e:  # noqa: BLE001 - one failed point must not lose the map
                m = {"status": "failed", "reason": f"{type(e).__name__}: {e}"}
            if (pdir / "metrics.json").is_file():
                (pdir / "metrics.json").replace(pdir / "point.json")  # not a job of the sweep
            rows.append({"E": E, "k": k, "dt": ps.run.dt, "status": m["status"], "steps": m.get("steps"),
                         "unstable_step": m.get("unstable_step"), "criterion": m.get("unstable_criterion"),
                         "body": m.get("unstable_body"), "reason": m.get("reason"),
                         "wall_time_s": m.get("wall_time_s"), "newton_mean": (m.get("implicit") or {}).get("newton_mean")})
            if m["status"] == "interrupted":
                status = "interrupted"
                break
        if status == "interrupted":
            break
    stable = [r for r in rows if r["status"] == "completed"]
    metrics = {
        "status": status, "reason": "" if status == "completed" else "interrupted",
        "steps": sum(int(r["steps"] or 0) for r in rows), "sim_time": 0.0,
        "scene": spec.scene_name, "scheme": spec.scheme.name, "kernel": spec.kernel.name,
        "transfer": spec.transfer, "integrator": spec.integrator.name, "precision": spec.run.precision,
        "resolution": spec.scene.resolution, "dx": spec.scene.dx,
        MAP_KEY: {"E": list(points.E), "dt_cfl": list(points.dt_cfl), "steps": points.steps,
                  "points": rows, "stable": len(stable)},
        "wall_time_s": time.perf_counter() - t0, **(identity or {}),
    }
    write_metrics(out_dir / "metrics.json", metrics)
    return metrics


def largest_stable(rows: list[dict], E: float) -> float | None:
    """The largest k at stiffness E below which every point is stable (None:
    the smallest k already fails)."""
    best = None
    for r in sorted((r for r in rows if r["E"] == E), key=lambda r: r["k"]):
        if r["status"] != "completed":
            break
        best = r["k"]
    return best


# ---------------------------------------------------------------------- report
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

    from ..report import _pyplot

    plt = _pyplot()
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


def section_stability(jobs: list, out: Path) -> list[str]:
    """Stability maps: stability.csv, one heat-map image per scene and the
    table of the largest stable step multiple per combination and stiffness."""
    from ..report import _absent, _fmt, _md_table, _write_csv

    title = "Stability maps: the largest stable time step"
    have = [j for j in jobs if isinstance(j.metrics.get(MAP_KEY), dict)]
    if not have:
        return _absent(title, "no job of a stability-map sweep (+experiment=stability)")
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
            table.append([_combo_name(combo)] + [("<" + _fmt(min(m["dt_cfl"])) if b is None else _fmt(b))
                                                 if E in m["E"] else "" for b, E in zip(best, Es)])
            for r in m["points"]:
                csv_rows.append([scene, *combo, r["E"], r["k"], r["dt"], r["status"], r.get("steps"),
                                 r.get("unstable_step"), r.get("criterion"), r.get("body"), r.get("reason"),
                                 r.get("wall_time_s")])
        lines += _md_table(["scheme · kernel · transfer · integrator"] + [f"E = {E:.0e} Pa" for E in Es], table)
        lines += [""]
    _write_csv(out / "stability.csv", ["scene", "integrator", "scheme", "kernel", "transfer", "E", "k", "dt",
                                       "status", "steps", "unstable_step", "criterion", "body", "reason",
                                       "wall_time_s"], csv_rows)
    return lines


EXTREME_KEY = "extreme"  # the suite's config group (conf/extreme/)


def section_extreme(jobs: list, out: Path) -> list[str]:
    """The extreme-case suite: per case and scheme the outcome against the
    expectation written in the case's file (extreme.csv)."""
    from ..report import _absent, _fmt, _md_table, _num, _write_csv

    title = "Extreme cases"
    have = [j for j in jobs if EXTREME_KEY in j.overrides]
    if not have:
        return _absent(title, "no job of the extreme-case suite (+experiment=extreme)")
    lines = [f"## {title}", "",
             "Per case (conf/extreme/) and scheme: the outcome (unstable: the criterion and step), "
             "steps, simulated time, the energy change relative to the energy scale (the largest "
             "kinetic plus elastic energy, mpm.stability), the largest energy growth beyond the "
             "boundaries' work in the same unit, and the fraction of broken neighbour pairs "
             "([extreme.csv](extreme.csv)).", ""]
    headers = ["case", "scheme", "status", "steps", "time [s]", "energy change", "growth max",
               "fracture", "run time [s]"]
    rows, expected = [], {}
    for j in sorted(have, key=lambda j: (j.overrides[EXTREME_KEY], j.scheme)):
        case = j.overrides[EXTREME_KEY]
        exp = (j.config or {}).get("expected")
        if exp:
            expected[case] = str(exp)
        m = j.metrics
        status = j.status
        if status == "unstable":
            status = f"unstable ({m.get('unstable_criterion')}, step {m.get('unstable_step')})"
        elif status in ("failed", "invalid"):
            status = f"{status}: {str(m.get('reason'))[:80]}"
        det = m.get("detect") or {}
        scale = _num(det.get("energy_scale"))
        e0, e1 = _num(m.get("energy_initial")), _num(m.get("energy_final"))
        change = (e1 - e0) / scale if None not in (e0, e1, scale) and scale > 0 else None
        frac = m.get("fracture")
        frac = frac.get("total") if isinstance(frac, dict) else frac
        rows.append([case, j.scheme, status, m.get("steps"), _fmt(m.get("sim_time")), _fmt(change, 3),
                     _fmt(det.get("energy_growth_max"), 3), _fmt(frac, 3), _fmt(m.get("wall_time_s"), 3)])
    lines += _md_table(headers, rows) + [""]
    if expected:
        lines += ["Expected outcomes (from the case files):", ""]
        lines += [f"- `{case}`: {text}" for case, text in sorted(expected.items())] + [""]
    _write_csv(out / "extreme.csv", headers + ["expected"],
               [r + [expected.get(r[0], "")] for r in rows])
    return lines



def write_stability_md(out: Path, map_lines: list[str], extreme_lines: list[str]) -> None:
    """stability.md: the maps, their table and the suite (when the sweep has them)."""
    body = [ln for part in (map_lines, extreme_lines) if part and not part[2].startswith("Not available")
            for ln in part]
    if body:
        (out / "stability.md").write_text("\n".join(["# Stability", ""] + body).rstrip() + "\n")
