"""Speed: ms per step and particle-steps per second (speed.csv, speed.png),
each kernel against the quadratic one."""

from __future__ import annotations

import math
from pathlib import Path

from ..common import absent, add_image, as_int, bar_chart, md_table, natural_key, positive, write_csv
from ..jobs import Job, extras_without, group_name
from ..registry import section


@section(order=50)
def section_speed(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """speed.csv and speed.png: median ms per step and particle-steps per second,
    with each kernel's ms/step relative to the quadratic kernel's."""
    title = "Speed"
    have = [j for j in jobs if j.completed and positive(j.num("step_time_ms"))]
    if not have:
        return absent(title, "no completed job reports a step time")

    def kernel_key(j: Job) -> tuple:
        return (j.scene, j.scheme, j.transfer, j.resolution, extras_without(j, "kernel"))

    quadratic = {}
    for j in have:
        if j.kernel == "quadratic":
            quadratic.setdefault(kernel_key(j), j)
    rows, ratios = [], []
    for j in sorted(have, key=lambda j: (j.scene, j.resolution or 0, natural_key(j.label))):
        q = quadratic.get(kernel_key(j))
        ratio = None
        if q is not None and q is not j and j.kernel != "quadratic":
            ratio = j.num("step_time_ms") / q.num("step_time_ms")
            ratios.append([j.scene, j.scheme, j.transfer, j.resolution, j.kernel, j.num("step_time_ms"),
                           q.num("step_time_ms"), ratio])
        elif q is j and any(kernel_key(o) == kernel_key(j) and o.kernel != "quadratic" for o in have):
            ratio = 1.0
        rows.append([j.scene, j.label, j.resolution, as_int(j.num("particles")), j.rel,
                     j.num("step_time_ms"), j.num("particle_steps_per_s"), ratio])
    write_csv(out / "speed.csv", ["scene", "label", "resolution", "particles", "dir", "step_time_ms",
                                  "particle_steps_per_s", "ms_per_step_vs_quadratic"], rows)
    groups = sorted({group_name(j) for j in have}, key=natural_key)
    values: dict[tuple[str, str], float] = {}
    for j in have:  # the fastest job of a label in a group (repeats, varying extras aside)
        key = (group_name(j), j.label)
        ms = j.num("step_time_ms")
        assert ms is not None  # have: jobs that report it
        values[key] = min(values.get(key, math.inf), ms)
    bar_chart(out / "speed.png", groups, values, style, "median wall time per step [ms]")
    lines = [f"## {title}", "",
             "Median wall time per step [ms] per method, grouped by scene and resolution, and "
             "particle-steps per second ([speed.csv](speed.csv)).", ""]
    add_image(lines, "speed.png", "ms per step")
    lines += md_table(["scene", "label", "cells", "particles", "ms/step", "particle-steps/s"],
                      [[r[0], r[1], r[2], r[3], r[5], r[6]] for r in rows])
    if ratios:
        lines += ["Kernels against the quadratic kernel (same scene, scheme, transfer and resolution):", ""]
        lines += md_table(["scene", "scheme", "transfer", "cells", "kernel", "ms/step",
                           "quadratic ms/step", "ratio"], ratios)
    return lines
