"""Report sections beside the papers: Table 3 and Table 4 of A-ULMPM over a
hand-made sweep, the leaking bowl, and the dam break against Martin & Moyce
over a short real run."""

import csv
from pathlib import Path

import numpy as np
import pytest

from helpers import ROOT, run_cli
from pipelines.report.sections.dam_break import MARTIN_MOYCE_T, MARTIN_MOYCE_Z
from pipelines.report import write_report
from test_report import _job, _metrics


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_tables_3_and_4_and_leaks(tmp_path):
    root = tmp_path / "sweep"
    n = 0
    for scene in ("snow_bunnies", "water_bunny", "yoyo"):
        for scheme, dt, upd in (("empm", 2.0e-3, 4.0), ("aulmpm", 2.5e-3, 0.25)):
            _job(root, str(n), _metrics(scheme, "quadratic", 48, scene=scene, dt=dt, update_time_ms=upd,
                                        updates_per_1e4_steps=20.0 if scheme == "aulmpm" else 1e4,
                                        config_hash=f"{scene}-{scheme}"),
                 [f"scene={scene}", f"scheme={scheme}"])
            n += 1
    _job(root, str(n), _metrics("empm", "quadratic", 48, scene="bowl_fsi", config_hash="bowl",
                                spilled={"water/bowl": 0.125}, fragments={"total": 5, "water": 2, "bowl": 3}),
         ["scene=bowl_fsi", "scheme=empm"])
    report = write_report(root, tmp_path / "out")
    text = report.read_text()
    assert "## Table 3 of the A-ULMPM paper" in text and "## Table 4 of the A-ULMPM paper" in text
    t3 = {r["scene"]: r for r in _rows(report.parent / "table3.csv")}
    assert set(t3) == {"snow_bunnies", "water_bunny"}
    assert float(t3["snow_bunnies"]["reduction"]) == pytest.approx(16.0)
    assert float(t3["water_bunny"]["paper_reduction"]) == pytest.approx(0.662 / 0.021)
    t4 = {r["scene"]: r for r in _rows(report.parent / "table4.csv")}
    assert set(t4) == {"snow_bunnies", "water_bunny", "yoyo"}
    assert float(t4["yoyo"]["aulmpm_dt_ms"]) == pytest.approx(2.5)
    assert float(t4["yoyo"]["ratio"]) == pytest.approx(1.25)
    assert float(t4["yoyo"]["paper_empm_dt_ms"]) == pytest.approx(0.54)
    leaks = _rows(report.parent / "spilled.csv")
    assert [(r["fluid/bowl"], float(r["spilled"]), r["bowl_fragments"]) for r in leaks] == \
        [("water/bowl", 0.125, "3")]


def test_martin_moyce_data_are_monotone():
    assert np.all(np.diff(MARTIN_MOYCE_T) > 0) and np.all(np.diff(MARTIN_MOYCE_Z) > 0)
    assert MARTIN_MOYCE_Z[0] > 1.0  # the front has left the column's width a


def test_connected_front_leaves_out_detached_spray():
    """A block of particles 0.01 m apart over [0, 0.2] x [0, 0.05], a drop
    0.05 m ahead of it (5 spacings: detached) and a chain of particles 0.015
    m apart leading off its front (1.5 spacings: attached): the bulk's front
    is the chain's end, not the drop."""
    from pipelines.report.sections.dam_break import connected_front

    s = 0.01
    block = np.stack(np.meshgrid(np.arange(0.0, 0.2001, s), np.arange(0.0, 0.0501, s)), -1).reshape(-1, 2)
    chain = np.array([[0.2 + 0.015 * k, 0.0] for k in range(1, 5)])  # to x = 0.26
    drop = np.array([[0.31, 0.01]])
    x = np.concatenate([block, chain, drop])
    assert connected_front(x, s, np.zeros(2)) == pytest.approx(0.26)
    assert connected_front(np.concatenate([block, drop]), s, np.zeros(2)) == pytest.approx(0.2)
    assert connected_front(np.concatenate([block, [[0.215, 0.0]]]), s, np.zeros(2)) == pytest.approx(0.215)


def test_dam_break_references_and_their_measures():
    """The height table is Martin & Moyce's Table 6 against tau = t sqrt(g/a):
    no point falls faster than free fall (H >= 1 - tau^2 / 4 for the column's
    top); the MPS front is monotone and leads the experiment at equal Z. A
    front shifted by dT in time leads the experiment by exactly dT; the
    column's height is the top of the particles near the back wall."""
    from pipelines.report.sections.dam_break import (MARTIN_MOYCE_H, MARTIN_MOYCE_TAU, MPS_T, MPS_Z,
                                                     column_height, time_lead)

    assert np.all(MARTIN_MOYCE_H >= 1.0 - MARTIN_MOYCE_TAU ** 2 / 4.0)
    assert not np.all(MARTIN_MOYCE_H >= 1.0 - (MARTIN_MOYCE_TAU / np.sqrt(2.0)) ** 2 / 4.0)  # read as T: too fast
    assert np.all(np.diff(MPS_T) > 0) and np.all(np.diff(MPS_Z) > 0)
    assert time_lead(MPS_T, MPS_Z, MARTIN_MOYCE_T, MARTIN_MOYCE_Z) == pytest.approx(-0.24, abs=0.03)
    T = np.linspace(0.0, 4.0, 401)
    Z_exp = np.interp(T, MARTIN_MOYCE_T, MARTIN_MOYCE_Z)  # the experiment, linear between its points
    for dT in (0.0, -0.3, 0.2):
        assert time_lead(T + dT, Z_exp, MARTIN_MOYCE_T[1:-1], MARTIN_MOYCE_Z[1:-1]) == pytest.approx(dT, abs=1e-9)
    assert time_lead(T, np.ones_like(T), MARTIN_MOYCE_T, MARTIN_MOYCE_Z) is None  # reaches no station
    x = np.array([[0.0, 0.1], [0.01, 0.12], [0.05, 0.3]])  # the last too far from the back wall
    assert column_height(x, 0.0, 0.01) == pytest.approx(0.12)
    assert np.isnan(column_height(x + [1.0, 0.0], 0.0, 0.01))


@pytest.mark.slow
def test_dam_break_front_against_the_experiment(tmp_path):
    """A short 2D dam break: its front starts at Z = 1 and the report reads
    its recording and sets it against the measured points it reaches."""
    sweep = tmp_path / "sweep"
    p = run_cli(["scene=dam_break_2d", "run.duration=0.06", "log.every=20",
                 f"hydra.run.dir={sweep / 'empm'}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    from pipelines.report.sections.dam_break import front
    from pipelines.report.jobs import load_jobs

    jobs, _ = load_jobs(sweep)
    T, Z = front(jobs[0])
    spacing = 0.4 / 160 / 2  # particle spacing [m]: dx / 2 (4 particles per cell)
    assert T[0] == 0.0 and Z[0] == pytest.approx(1.0, abs=spacing / 0.05715)  # within a spacing of a
    assert np.all(np.diff(Z) >= -1e-9) and Z[-1] > 1.05
    report = write_report(sweep, tmp_path / "out")
    assert "## Dam break against Martin & Moyce (1952)" in report.read_text()
    row, = _rows(report.parent / "dam_break.csv")
    inside = MARTIN_MOYCE_T <= T.max()
    assert int(row["points"]) == int(inside.sum()) >= 2
    # the table's deviations are those of the front against the measured points it reaches
    rel = (np.interp(MARTIN_MOYCE_T[inside], T, Z) - MARTIN_MOYCE_Z[inside]) / MARTIN_MOYCE_Z[inside]
    assert float(row["mean_relative_deviation"]) == pytest.approx(rel.mean(), rel=4 * np.finfo(float).eps, abs=0)
    assert float(row["max_relative_deviation"]) == pytest.approx(np.abs(rel).max(), rel=4 * np.finfo(float).eps, abs=0)
    # and the front runs with the experiment: measured +11 % on average, +22 % at most, over
    # its first two points (T <= 1.1, where the weakly compressible column starts)
    assert abs(rel.mean()) < 0.2 and np.abs(rel).max() < 0.35
    assert (report.parent / "dam_break.png").stat().st_size > 1000
