"""Plastic state: the plastic fields every job with a plastic body left
(metrics.json ``plastic``: min, mean and max per field), plastic.csv."""

from __future__ import annotations

from ..common import absent, md_table, natural_key, write_csv
from ..registry import section


@section(order=90)
def section_plastic(jobs: list, out) -> list[str]:
    """Report section: the plastic fields every job with a plastic body left
    (metrics.json ``plastic``: min, mean and max per field), plastic.csv."""
    title = "Plastic state"
    rows = []
    for j in sorted(jobs, key=lambda j: (j.scene, natural_key(j.label))):
        for body, fields in (j.metrics.get("plastic") or {}).items():
            for name, v in fields.items():
                rows.append([j.scene, j.label, j.status, body, name, v["min"], v["mean"], v["max"]])
    if not rows:
        return absent(title, "no job with a plastic body")
    headers = ["scene", "label", "status", "body", "field", "min", "mean", "max"]
    write_csv(out / "plastic.csv", headers, rows)
    return [f"## {title}", "", "Per-particle plastic fields at the end of each run: J_P (plastic "
            "volume ratio), density_ratio (rho / rho0), hardening factor, equivalent plastic strain, ... "
            "([plastic.csv](plastic.csv)).", ""] + md_table(headers, rows)
