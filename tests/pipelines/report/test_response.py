"""The sweep report's first figure: each response against the swept
parameter, a line per method, a log axis for a geometric sweep."""

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from mpm.responses import reduce
from pipelines.report import write_report
from pipelines.report.common import geometric, parameter_label
from pipelines.report.sections.response import swept_parameters


@pytest.mark.parametrize("values, expected", [
    ([5e4, 1e5, 2e5], True),  # doubling
    ([1, 2, 5, 10], True),  # the 1-2-5 series
    ([0.1, 1.0], True),  # two values a decade apart
    ([1, 2, 3], False),  # a constant step
    ([16, 24, 32, 40], False),
    ([0.0, 1.0, 2.0], False),  # not positive
    ([1.0], False),
])
def test_geometric_sweeps_get_a_log_axis(values, expected):
    assert geometric(values) is expected


def test_parameter_labels_carry_units():
    assert parameter_label("material.E") == "material.E [Pa]"
    assert parameter_label("scene.resolution") == "scene.resolution [cells]"
    assert parameter_label("scene.custom_thing") == "scene.custom_thing"


def _job(root: Path, name: str, scheme: str, E: float, ms: float) -> None:
    d = root / name
    (d / ".hydra").mkdir(parents=True)
    metrics = {"status": "completed", "reason": "", "steps": 100, "sim_time": 0.1, "dt": 1e-3 / E ** 0.5,
               "step_time_ms": ms, "loop_time_s": ms / 10, "scene": "ball", "resolution": 16, "dx": 1 / 16,
               "scheme": scheme, "kernel": "quadratic", "transfer": "mls", "config_hash": f"{scheme}-{E}",
               "fracture": {"total": 0.0, "ball": 0.0}}
    (d / "metrics.json").write_text(json.dumps(metrics))
    (d / ".hydra" / "overrides.yaml").write_text(f"- scheme={scheme}\n- material.E={E}\n- log.every=5\n")
    (d / ".hydra" / "config.yaml").write_text("scene:\n  name: ball\n  resolution: 16\n  domain: [1.0, 1.0]\n")


def test_a_three_value_sweep_plots_the_response_against_the_parameter_first(tmp_path):
    """Three values of E, two schemes: the first image of report.md is the
    response figure; response.csv holds a point per job and response; a
    response that is zero everywhere (fracture) is not plotted."""
    sweep = tmp_path / "sweep"
    values = [5e4, 1e5, 2e5]
    n = 0
    for scheme in ("empm", "tlmpm"):
        for E in values:
            _job(sweep, str(n), scheme, E, ms=1.0 + E / 1e5 + (scheme == "tlmpm"))
            n += 1
    report = write_report(sweep).read_text()
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert images and images[0] == "response_material_E.png"
    assert (sweep / images[0]).stat().st_size > 5000
    assert "(geometric: log axis)" in report
    rows = list(csv.DictReader(open(sweep / "response.csv")))
    plotted = {r["response"] for r in rows}
    assert plotted == {"step_time_ms", "dt"}  # fracture is 0 in every job: no plot
    times = [r for r in rows if r["response"] == "step_time_ms"]
    assert len(times) == 6
    lines = {r["line"] for r in times}
    assert len(lines) == 2 and all("material.E" not in line for line in lines)  # a line per scheme
    for r in times:
        E = float(r["value"])
        assert float(r["response_value"]) == pytest.approx(1.0 + E / 1e5 + ("tlmpm" in r["line"]))


def test_no_numeric_parameter_varies_no_figure(tmp_path):
    sweep = tmp_path / "sweep"
    for n, scheme in enumerate(("empm", "tlmpm")):
        _job(sweep, str(n), scheme, 1e5, ms=1.0)
    from pipelines.report.jobs import load_jobs

    assert swept_parameters(load_jobs(sweep)[0]) == {}
    report = write_report(sweep).read_text()
    assert "response_" not in report and not (sweep / "response.csv").exists()


def test_the_acceleration_reduction_fits_a_parabola():
    """reduce("acceleration"): q(t) = 0.3 + 0.1 t + 1.7 t^2 / 2 sampled at
    20 states gives 1.7 to round-off from a quarter of the run on; the
    states before t_end / 4 are left out (a different parabola there does
    not change it); fewer than four usable states give NaN."""
    t = np.linspace(0.0, 0.4, 21)[1:]
    q = 0.3 + 0.1 * t + 0.85 * t**2
    assert reduce("acceleration", q, t) == pytest.approx(1.7, rel=1e-9)
    early = t < 0.1
    assert reduce("acceleration", np.where(early, 5.0 * t**2, q), t) == pytest.approx(1.7, rel=1e-9)
    assert np.isnan(reduce("acceleration", q[:3], t[:3]))
