"""Configuration-update cost: update_cost.csv, EMPM's update time against
A-ULMPM's."""

from __future__ import annotations

from pathlib import Path

from ..common import absent, as_int, md_table, natural_key, positive, write_csv
from ..jobs import Job, extras_without
from ..registry import section


@section(order=40)
def section_update_cost(jobs: list[Job], out: Path) -> list[str]:
    """update_cost.csv: configuration updates per 1e4 steps, their mean cost
    [ms], and the EMPM/A-ULMPM cost ratio at equal scene, kernel, transfer and resolution."""
    title = "Configuration-update cost"
    have = [j for j in jobs if j.completed and (j.num("update_time_ms") is not None
                                                or j.num("updates_per_1e4_steps") is not None)]
    if not have:
        return absent(title, "no completed job reports configuration updates")

    def match_key(j: Job) -> tuple:
        return (j.scene, j.kernel, j.transfer, j.resolution, extras_without(j, "scheme"))

    empm = {}
    for j in have:
        if j.scheme == "empm" and positive(j.num("update_time_ms")):
            empm.setdefault(match_key(j), j)
    rows, pairs = [], []
    for j in sorted(have, key=lambda j: (j.scene, natural_key(j.label), j.resolution or 0)):
        reduction, partner = None, None
        e = empm.get(match_key(j))
        if j.scheme == "aulmpm" and e is not None and positive(j.num("update_time_ms")):
            partner = e
            reduction = e.num("update_time_ms") / j.num("update_time_ms")
            pairs.append([j.scene, j.kernel, j.transfer, j.resolution, e.label, j.label,
                          e.num("update_time_ms"), j.num("update_time_ms"), reduction])
        rows.append([j.scene, j.label, j.scheme, j.kernel, j.transfer, j.resolution, j.rel,
                     j.num("updates_per_1e4_steps"), j.num("update_time_ms"), as_int(j.num("config_updates")),
                     reduction, partner.rel if partner else ""])
    write_csv(out / "update_cost.csv",
              ["scene", "label", "scheme", "kernel", "transfer", "resolution", "dir",
               "updates_per_1e4_steps", "update_time_ms", "config_updates", "reduction", "reduction_vs"],
              rows)
    lines = [f"## {title}", "",
             "Configuration updates per 10^4 steps and the mean wall time [ms] per step spent on them "
             "([update_cost.csv](update_cost.csv)); the reduction is EMPM's update time divided by "
             "A-ULMPM's for the same scene, kernel, transfer and resolution.", ""]
    lines += md_table(["scene", "label", "cells", "updates / 1e4 steps", "update time [ms]"],
                      [[r[0], r[1], r[5], r[7], r[8]] for r in rows])
    if pairs:
        lines += md_table(["scene", "kernel", "transfer", "cells", "EMPM", "A-ULMPM", "EMPM [ms]",
                           "A-ULMPM [ms]", "reduction"], pairs)
    else:
        lines += ["No EMPM and A-ULMPM jobs share a scene, kernel, transfer and resolution: "
                  "no reduction ratio.", ""]
    return lines
