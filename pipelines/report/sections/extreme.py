"""The extreme-case suite (``+experiment=extreme``, cases in conf/extreme/):
per case and scheme the outcome against the expectation written in the
case's file (extreme.csv, stability.md)."""

from __future__ import annotations

from pathlib import Path

from ..common import absent, fmt, md_table, num, write_csv
from ..registry import section

EXTREME_KEY = "extreme"  # the suite's config group (conf/extreme/)


@section(order=170, document="stability.md")
def section_extreme(jobs: list, out: Path) -> list[str]:
    """The extreme-case suite: per case and scheme the outcome against the
    expectation written in the case's file (extreme.csv)."""
    title = "Extreme cases"
    have = [j for j in jobs if EXTREME_KEY in j.overrides]
    if not have:
        return absent(title, "no job of the extreme-case suite (+experiment=extreme)")
    lines = [f"## {title}", "",
             "Per case (conf/extreme/) and scheme: the outcome (unstable: the criterion and step), "
             "steps, simulated time, the energy change beyond the boundaries' work relative to the energy "
             "scale (the largest kinetic plus elastic energy, mpm.stepping.detection; metrics.json energy_change), "
             "the largest energy growth beyond the "
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
        change = num(m.get("energy_change"))  # (the recorder's; a run from before it: without the work)
        if change is None:
            scale = num(det.get("energy_scale"))
            e0, e1 = num(m.get("energy_initial")), num(m.get("energy_final"))
            change = ((e1 - e0) / scale if e0 is not None and e1 is not None and scale is not None and scale > 0
                      else None)
        frac = m.get("fracture")
        frac = frac.get("total") if isinstance(frac, dict) else frac
        rows.append([case, j.scheme, status, m.get("steps"), fmt(m.get("sim_time")), fmt(change, 3),
                     fmt(det.get("energy_growth_max"), 3), fmt(frac, 3), fmt(m.get("wall_time_s"), 3)])
    lines += md_table(headers, rows) + [""]
    if expected:
        lines += ["Expected outcomes (from the case files):", ""]
        lines += [f"- `{case}`: {text}" for case, text in sorted(expected.items())] + [""]
    write_csv(out / "extreme.csv", headers + ["expected"],
              [r + [expected.get(r[0], "")] for r in rows])
    return lines
