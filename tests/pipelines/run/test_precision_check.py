"""The run's precision check (pipelines.run.runner.precision_check): a note
before compiling where float32 cannot resolve the scene (mpm.precision), the
compensated sums on by default there (run.compensate), a warning naming the
remedies where they are turned off, and nothing for a resolved scene."""

import pytest

from pipelines.run.runner import precision_check, solver_options
from helpers import spec_for


@pytest.mark.parametrize("overrides,compensate,starts", [
    ([], True, "note: float32 cannot resolve"),
    (["run.compensate=false"], False, "warning: float32 cannot resolve"),
    (["run.compensate=true"], True, "note: float32 cannot resolve"),
    (["run.precision=float64"], False, ""),
])
def test_the_stiff_cantilever(overrides, compensate, starts):
    spec = spec_for(["scene=cantilever_stiff_2d", *overrides])
    entry, note = precision_check(spec)
    assert entry["compensate"] is compensate and solver_options(spec).compensate is compensate
    assert entry["resolved"] is (starts == "")
    assert note.startswith(starts) and ("r_F = 0.095" in note) is (starts != "")
    if not compensate and starts:
        assert "run.precision=float64" in note and "run.compensate=true" in note


@pytest.mark.parametrize("overrides,compensate", [([], False), (["run.compensate=true"], True)])
def test_a_resolved_scene(overrides, compensate):
    spec = spec_for(["scene=elastic_ball_2d", *overrides])
    entry, note = precision_check(spec)
    assert entry["resolved"] and entry["r_F"] > 1000 and note == ""
    assert solver_options(spec).compensate is compensate
