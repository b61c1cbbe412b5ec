"""Report sections that set measurements beside the A-ULMPM paper's tables:
Table 3 (configuration-update frequency and cost, A-ULMPM against EMPM) and
the journal version's Table 4 (mean time step, A-ULMPM against EMPM)."""

from __future__ import annotations

from pathlib import Path

from ..common import absent, md_table, positive, write_csv
from ..jobs import Job
from ..registry import section

# Table 3: updates per 1e4 steps (A-ULMPM) and the update cost per step (A-ULMPM, EMPM)
PAPER_TABLE3 = {"snow_bunnies": (24.33, 0.112, 0.479), "water_bunny": (3.31, 0.021, 0.662)}
# journal Table 4: mean time step [ms], (A-ULMPM, EMPM); the viscous armadillos ran implicitly
PAPER_TABLE4 = {"twisting_bar": (0.125, 0.178), "yoyo": (0.71, 0.54), "snow_bunnies": (2.52, 2.31),
                "water_bunny": (0.73, 0.73), "viscous_cup": (4.31, 4.25)}


def _pairs(jobs: list[Job], scenes, schemes=("empm", "aulmpm"), integrator: bool = False) -> dict:
    """(scene, kernel, resolution[, integrator]) -> {scheme: job} for completed
    jobs of ``scenes`` and ``schemes``."""
    out: dict = {}
    for j in jobs:
        if j.completed and j.scene in scenes and j.scheme in schemes:
            key = (j.scene, j.kernel, j.resolution) + ((j.integrator,) if integrator else ())
            out.setdefault(key, {}).setdefault(j.scheme, j)
    return out


@section(order=110)
def section_table3(jobs: list[Job], out: Path) -> list[str]:
    """table3.csv: A-ULMPM's updates per 1e4 steps and update cost beside EMPM's and the paper's."""
    title = "Table 3 of the A-ULMPM paper: configuration-update cost"
    pairs = {k: v for k, v in _pairs(jobs, PAPER_TABLE3).items() if len(v) == 2}
    if not pairs:
        return absent(title, "no completed EMPM and A-ULMPM pair on the snow bunnies or the water bunny")
    rows = []
    for (scene, kernel, res), by in sorted(pairs.items(), key=lambda kv: tuple(map(str, kv[0]))):
        a, e = by["aulmpm"], by["empm"]
        ta, te = a.num("update_time_ms"), e.num("update_time_ms")
        reduction = te / ta if positive(ta) and positive(te) else None
        pu, pa, pe = PAPER_TABLE3[scene]
        rows.append([scene, kernel, res, _int_or(a.num("particles")), a.num("updates_per_1e4_steps"), ta, te,
                     reduction, pu, pa, pe, pe / pa])
    write_csv(out / "table3.csv", ["scene", "kernel", "resolution", "particles", "updates_per_1e4_steps",
                                   "aulmpm_update_ms", "empm_update_ms", "reduction", "paper_updates_per_1e4",
                                   "paper_aulmpm_cost", "paper_empm_cost", "paper_reduction"], rows)
    return [f"## {title}", "",
            "Configuration updates per 10^4 steps of A-ULMPM and the mean wall time per step spent "
            "deciding and updating [ms], A-ULMPM against EMPM (which updates every body every step), "
            "beside the paper's values (its cost column is in its own units; compare the reductions) "
            "([table3.csv](table3.csv)).", "",
            *md_table(["scene", "kernel", "cells", "particles", "updates / 1e4 steps", "A-ULMPM [ms]",
                       "EMPM [ms]", "reduction", "paper: updates / 1e4", "paper: A-ULMPM", "paper: EMPM",
                       "paper: reduction"], rows)]


@section(order=120)
def section_table4(jobs: list[Job], out: Path) -> list[str]:
    """table4.csv: mean time step [ms] and steps of A-ULMPM, EMPM and TLMPM
    per integrator, beside the paper's (A-ULMPM, EMPM)."""
    title = "Table 4 of the A-ULMPM paper (journal version): mean time step"
    pairs = _pairs(jobs, PAPER_TABLE4, ("empm", "aulmpm", "tlmpm"), integrator=True)
    if not pairs:
        return absent(title, "no completed EMPM, TLMPM or A-ULMPM job on the Table 4 scenes")

    def dt_ms(j):
        return 1e3 * j.num("dt") if j is not None and j.num("dt") else None

    def steps(j):
        return _int_or(j.num("steps")) if j is not None else None

    rows = []
    for (scene, kernel, res, integrator), by in sorted(pairs.items(), key=lambda kv: tuple(map(str, kv[0]))):
        a, e, t = by.get("aulmpm"), by.get("empm"), by.get("tlmpm")
        da, de = dt_ms(a), dt_ms(e)
        pa, pe = PAPER_TABLE4[scene]
        particles = next(j for j in (a, e, t) if j is not None).num("particles")
        rows.append([scene, kernel, res, integrator, _int_or(particles), da, de, da / de if da and de else None,
                     dt_ms(t), steps(a), steps(e), steps(t), pa, pe, pa / pe])
    write_csv(out / "table4.csv", ["scene", "kernel", "resolution", "integrator", "particles", "aulmpm_dt_ms",
                                   "empm_dt_ms", "ratio", "tlmpm_dt_ms", "aulmpm_steps", "empm_steps",
                                   "tlmpm_steps", "paper_aulmpm_dt_ms", "paper_empm_dt_ms", "paper_ratio"], rows)
    return [f"## {title}", "",
            "Mean time step [ms] (simulated time over steps) and steps of A-ULMPM, EMPM and TLMPM with "
            "the adaptive step of each integrator (explicit: the CFL limit; implicit: the displacement "
            "limit), beside the paper's Table 4 (its viscous armadillos ran implicitly) "
            "([table4.csv](table4.csv)).", "",
            *md_table(["scene", "kernel", "cells", "integrator", "particles", "A-ULMPM [ms]", "EMPM [ms]",
                       "ratio", "TLMPM [ms]", "A-ULMPM steps", "EMPM steps", "TLMPM steps",
                       "paper: A-ULMPM", "paper: EMPM", "paper: ratio"], rows)]


def _int_or(value):
    return int(value) if value is not None else None
