"""Numerical fracture: the fraction of neighbouring particle pairs torn apart
and the fragments (fracture.csv, fracture.png)."""

from __future__ import annotations

from pathlib import Path

from ..common import absent, add_image, as_int, bar_chart, md_table, natural_key, write_csv
from ..jobs import Job, group_name
from ..registry import section


@section(order=70)
def section_fracture(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """fracture.csv and fracture.png: fraction of initially neighbouring particle
    pairs torn apart, and the number of fragments, per method."""
    title = "Numerical fracture"
    have = [j for j in jobs if j.completed and j.num("fracture") is not None]
    if not have:
        return absent(title, "no completed job reports fracture")
    rows = []
    for j in sorted(have, key=lambda j: (j.scene, j.resolution or 0, natural_key(j.label))):
        rows.append([j.scene, j.label, j.resolution, j.rel, j.num("fracture"), as_int(j.num("fragments"))])
    write_csv(out / "fracture.csv", ["scene", "label", "resolution", "dir", "fracture", "fragments"], rows)
    groups = sorted({group_name(j) for j in have}, key=natural_key)
    values: dict[tuple[str, str], float] = {}
    for j in have:
        key = (group_name(j), j.label)
        fracture = j.num("fracture")
        assert fracture is not None  # have: jobs that report it
        values[key] = max(values.get(key, 0.0), fracture)
    lines = [f"## {title}", "",
             "Fraction of initially neighbouring particle pairs torn apart at the end of the run, per "
             "method, grouped by scene and resolution, and the number of fragments "
             "([fracture.csv](fracture.csv)).", ""]
    if any(values.values()):
        bar_chart(out / "fracture.png", groups, values, style, "pairs torn apart [fraction]",
                  title="Numerical fracture at the end of each run")
        add_image(lines, "fracture.png", "numerical fracture")
    else:  # an empty chart says less than a line
        lines += ["No job tore a pair apart: no plot.", ""]
    lines += md_table(["scene", "label", "cells", "fracture", "fragments"],
                      [[r[0], r[1], r[2], r[4], r[5]] for r in rows])
    return lines
