"""Runs: runs.csv (every job) and the jobs that did not complete."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from ..common import as_int, md_table, write_csv
from ..jobs import Job
from ..registry import section


RUN_COLUMNS = ["dir", "label", "scene", "scheme", "kernel", "transfer", "integrator", "resolution", "dx", "particles",
               "status", "reason", "steps", "sim_time", "step_time_ms", "particle_steps_per_s",
               "loop_time_s", "wall_time_s", "compile_time_s", "error_kind", "error_reference",
               "error_displacement", "error_velocity", "updates_per_1e4_steps", "update_time_ms",
               "config_updates", "fracture", "fragments", "mass_drift", "momentum_drift",
               "angular_momentum_drift", "config_hash", "skipped"]


@section(order=10)
def section_runs(jobs: list[Job], out: Path, duplicates: int) -> list[str]:
    """runs.csv (every job) and the list of jobs that did not complete."""
    rows = []
    for j in jobs:
        m = j.metrics
        rows.append([j.rel, j.label, j.scene, j.scheme, j.kernel, j.transfer, j.integrator, j.resolution, j.dx,
                     as_int(j.num("particles")), j.status, m.get("reason") or "", as_int(j.num("steps")),
                     j.num("sim_time"),
                     j.num("step_time_ms"), j.num("particle_steps_per_s"), j.num("loop_time_s"),
                     j.num("wall_time_s"), j.num("compile_time_s"), j.error_kind, j.error_ref,
                     j.error_displacement, j.error_velocity, j.num("updates_per_1e4_steps"),
                     j.num("update_time_ms"), as_int(j.num("config_updates")), j.num("fracture"),
                     as_int(j.num("fragments")), j.num("mass_drift"), j.num("momentum_drift"),
                     j.num("angular_momentum_drift"), m.get("config_hash") or "", m.get("skipped") or ""])
    write_csv(out / "runs.csv", RUN_COLUMNS, rows)
    counts = Counter(j.status for j in jobs)
    lines = ["## Runs", "",
             f"{len(jobs)} jobs ({', '.join(f'{n} {s}' for s, n in sorted(counts.items()))})"
             + (f"; {duplicates} duplicate(s) of an identical configuration merged" if duplicates else "")
             + ". One row per job in [runs.csv](runs.csv); run time is the wall time spent stepping "
               "(compile and logging excluded).", ""]
    lines += md_table(["dir", "scene", "label", "cells", "particles", "status", "steps", "ms/step",
                       "run time [s]"],
                      [[j.rel, j.scene, j.label, j.resolution, as_int(j.num("particles")), j.status,
                        as_int(j.num("steps")), j.num("step_time_ms"), j.num("loop_time_s")] for j in jobs])
    bad = [j for j in jobs if j.status != "completed"]
    if bad:
        lines += ["Jobs that did not complete:", ""]
        lines += md_table(["dir", "label", "cells", "status", "reason"],
                          [[j.rel, j.label, j.resolution, j.status, j.metrics.get("reason") or ""]
                           for j in bad])
    else:
        lines += ["All jobs completed.", ""]
    return lines
