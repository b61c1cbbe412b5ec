"""Leaks: the fraction of a fluid below a bowl's rim plane outside it
(spilled.csv)."""

from __future__ import annotations

from pathlib import Path

from ..common import md_table, natural_key, write_csv
from ..jobs import Job
from ..registry import section


@section(order=130)
def section_spilled(jobs: list[Job], out: Path) -> list[str]:
    """spilled.csv: the fraction of a fluid below a bowl's rim plane outside it (the leaking bowl)."""
    have = [j for j in jobs if j.completed and j.metrics.get("spilled")]
    if not have:
        return []
    rows = [[j.scene, j.label, j.resolution, j.rel, name, frac, (j.metrics.get("fragments") or {}).get(
        name.split("/")[1])] for j in sorted(have, key=lambda j: (j.scene, j.resolution or 0, natural_key(j.label)))
        for name, frac in j.metrics["spilled"].items()]
    write_csv(out / "spilled.csv", ["scene", "label", "resolution", "dir", "fluid/bowl", "spilled",
                                    "bowl_fragments"], rows)
    return ["## Leaks", "",
            "Fraction of each fluid's particles that end below a bowl's rim plane and outside it, and "
            "the bowl's pieces at the end ([spilled.csv](spilled.csv)).", "",
            *md_table(["scene", "label", "cells", "fluid / bowl", "spilled", "bowl fragments"],
                      [[r[0], r[1], r[2], r[4], r[5], r[6]] for r in rows])]
