"""Report sections that set measurements beside the A-ULMPM paper's tables:
Table 3 (configuration-update frequency and cost, A-ULMPM against EMPM) and
the journal version's Table 4 (mean time step, A-ULMPM against EMPM)."""

from __future__ import annotations

from pathlib import Path

from .report import Job, _absent, _md_table, _positive, _write_csv

# Table 3: updates per 1e4 steps (A-ULMPM) and the update cost per step (A-ULMPM, EMPM)
PAPER_TABLE3 = {"snow_bunnies": (24.33, 0.112, 0.479), "water_bunny": (3.31, 0.021, 0.662)}
# journal Table 4: mean time step [ms], (A-ULMPM, EMPM); the viscous armadillos ran implicitly
PAPER_TABLE4 = {"twisting_bar": (0.125, 0.178), "yoyo": (0.71, 0.54), "snow_bunnies": (2.52, 2.31),
                "water_bunny": (0.73, 0.73), "viscous_cup": (4.31, 4.25)}


def _pairs(jobs: list[Job], scenes) -> dict:
    """(scene, kernel, resolution) -> {scheme: job} for completed jobs of ``scenes``."""
    out: dict = {}
    for j in jobs:
        if j.completed and j.scene in scenes and j.scheme in ("empm", "aulmpm"):
            out.setdefault((j.scene, j.kernel, j.resolution), {}).setdefault(j.scheme, j)
    return out


def section_table3(jobs: list[Job], out: Path) -> list[str]:
    """table3.csv: A-ULMPM's updates per 1e4 steps and update cost beside EMPM's and the paper's."""
    title = "Table 3 of the A-ULMPM paper: configuration-update cost"
    pairs = {k: v for k, v in _pairs(jobs, PAPER_TABLE3).items() if len(v) == 2}
    if not pairs:
        return _absent(title, "no completed EMPM and A-ULMPM pair on the snow bunnies or the water bunny")
    rows = []
    for (scene, kernel, res), by in sorted(pairs.items(), key=lambda kv: tuple(map(str, kv[0]))):
        a, e = by["aulmpm"], by["empm"]
        ta, te = a.num("update_time_ms"), e.num("update_time_ms")
        reduction = te / ta if _positive(ta) and _positive(te) else None
        pu, pa, pe = PAPER_TABLE3[scene]
        rows.append([scene, kernel, res, _int_or(a.num("particles")), a.num("updates_per_1e4_steps"), ta, te,
                     reduction, pu, pa, pe, pe / pa])
    _write_csv(out / "table3.csv", ["scene", "kernel", "resolution", "particles", "updates_per_1e4_steps",
                                    "aulmpm_update_ms", "empm_update_ms", "reduction", "paper_updates_per_1e4",
                                    "paper_aulmpm_cost", "paper_empm_cost", "paper_reduction"], rows)
    return [f"## {title}", "",
            "Configuration updates per 10^4 steps of A-ULMPM and the mean wall time per step spent "
            "deciding and updating [ms], A-ULMPM against EMPM (which updates every body every step), "
            "beside the paper's values (its cost column is in its own units; compare the reductions) "
            "([table3.csv](table3.csv)).", "",
            *_md_table(["scene", "kernel", "cells", "particles", "updates / 1e4 steps", "A-ULMPM [ms]",
                        "EMPM [ms]", "reduction", "paper: updates / 1e4", "paper: A-ULMPM", "paper: EMPM",
                        "paper: reduction"], rows)]


def section_table4(jobs: list[Job], out: Path) -> list[str]:
    """table4.csv: mean time step [ms] of A-ULMPM and EMPM beside the paper's."""
    title = "Table 4 of the A-ULMPM paper (journal version): mean time step"
    pairs = _pairs(jobs, PAPER_TABLE4)
    if not pairs:
        return _absent(title, "no completed EMPM or A-ULMPM job on the Table 4 scenes")
    rows = []
    for (scene, kernel, res), by in sorted(pairs.items(), key=lambda kv: tuple(map(str, kv[0]))):
        a, e = by.get("aulmpm"), by.get("empm")
        da = 1e3 * a.num("dt") if a is not None and a.num("dt") else None
        de = 1e3 * e.num("dt") if e is not None and e.num("dt") else None
        pa, pe = PAPER_TABLE4[scene]
        particles = (a or e).num("particles")
        rows.append([scene, kernel, res, _int_or(particles), da, de, da / de if da and de else None,
                     pa, pe, pa / pe])
    _write_csv(out / "table4.csv", ["scene", "kernel", "resolution", "particles", "aulmpm_dt_ms", "empm_dt_ms",
                                    "ratio", "paper_aulmpm_dt_ms", "paper_empm_dt_ms", "paper_ratio"], rows)
    return [f"## {title}", "",
            "Mean time step [ms] (simulated time over steps) of A-ULMPM and EMPM with the adaptive "
            "explicit step, beside the paper's Table 4 (its viscous armadillos ran implicitly) "
            "([table4.csv](table4.csv)).", "",
            *_md_table(["scene", "kernel", "cells", "particles", "A-ULMPM [ms]", "EMPM [ms]", "ratio",
                        "paper: A-ULMPM", "paper: EMPM", "paper: ratio"], rows)]


def _int_or(value):
    return int(value) if value is not None else None
