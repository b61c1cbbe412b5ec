"""Stability maps (``+experiment=stability``): stable or unstable over the
time step, in multiples of the explicit CFL limit, and the stiffness, one map
per job (a scene, scheme, kernel, transfer and integrator).

A map job runs every point (E, k) of ``stability_map`` in its own process,
one after the other (the kernels compile once): the scene with every body's
Young's modulus (a fluid's bulk modulus) set to E, the fixed step

    dt = k dx / (c(E) + v0),

the explicit limit at CFL number 1 (c the body's P-wave speed at rest, v0
the fastest initial particle, bounded by |u| + |omega| r_max), for
``steps`` steps with the blow-up detection of mpm.stepping.detection on. A point is
stable when it completes its steps; otherwise it keeps its failure step,
criterion and reason (a point that fails with an error is kept as
``failed``). The job's metrics.json holds the whole map
(``stability_map``); each point's own metrics are ``points/<name>/point.json``.
A point is reproduced by the job's config (``.hydra``) with every body's
stiffness set to E, ``run.dt`` = the point's ``dt`` and ``run.steps``.

The report (:mod:`pipelines.report.sections.stability`) draws per scene one
heat map per combination, the failure step as colour, and tabulates the
largest stable multiple k per combination and stiffness.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

import mpm

from .runner import execute, write_metrics
from ..recording.sinks import Sink
from ..config.validate import MapSpec

MAP_KEY = "stability_map"


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
                m: dict = execute(ps, pdir, sink=Sink())
            except Exception as e:  # noqa: BLE001 - one failed point must not lose the map
                m = {"status": "failed", "reason": f"{type(e).__name__}: {e}"}
            if (pdir / "metrics.json").is_file():
                (pdir / "metrics.json").replace(pdir / "point.json")  # not a job of the sweep
            rows.append({"E": E, "k": k, "dt": ps.run.dt, "status": m["status"], "steps": m.get("steps"),
                         "unstable_step": m.get("unstable_step"), "criterion": m.get("unstable_criterion"),
                         "body": m.get("unstable_body"), "reason": m.get("reason"),
                         "wall_time_s": m.get("wall_time_s"),
                         "newton_mean": (m.get("implicit") or {}).get("newton_mean")})
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
