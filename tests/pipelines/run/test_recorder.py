"""The run's observer (pipelines.run.recorder): what metrics.json says of
the states it did not log."""

import pytest

from helpers import spec_for
from pipelines.run.runner import execute


@pytest.mark.parametrize("scalars", ["true", "false"])
def test_the_last_state_is_measured_whether_or_not_scalars_are_logged(scalars, tmp_path):
    """The final row (mass, energies) comes from the last state, measured on
    the host when the steps logged no scalars: the mass is conserved exactly
    and the ball still has its energy, the same figures either way."""
    base = ["scene=elastic_ball_2d", "scene.resolution=24", "run.steps=30", "log.every=0", "log.progress=false"]
    m = {}
    for s in ("true", scalars):
        m[s] = execute(spec_for(base + [f"log.scalars={s}"]), tmp_path / s)
        assert m[s]["status"] == "completed"
        assert m[s]["mass_drift"] == 0.0 and m[s]["kinetic_energy_final"] > 0.0
    for key in ("energy_initial", "energy_final", "kinetic_energy_final", "elastic_energy_final"):
        assert m["true"][key] == m[scalars][key]
