"""Open walls remove the particles that leave through them (counted, logged,
their mass accounted), instead of ending the run; a closed wall still does."""

import numpy as np
import pytest

from helpers import spec_for
from pipelines.recording import recordings
from pipelines.run.runner import execute

# a ball translating at v = 4 m/s towards the open x_hi face, no gravity: a
# rigid translation, which every scheme reproduces exactly (zero stress, the
# grid velocity is v wherever the ball has mass), so each particle is at
# x_p(t) = X_p + v t until it crosses the interior's bound and is removed
V = 4.0
OPEN = ["scene.resolution=24", "scene.walls=[slip,open,slip,slip]", "scene.gravity=[0,0]",
        f"scene.bodies.0.velocity=[{V},0]", "log.every=5"]


@pytest.mark.parametrize("scheme", ["empm", "aulmpm"])
def test_particles_leaving_through_an_open_wall_are_removed(tmp_path, scheme):
    spec = spec_for(OPEN + [f"scheme={scheme}", "run.duration=0.1"])
    m = execute(spec, tmp_path)
    assert m["status"] == "completed", m["reason"]
    final = np.load(tmp_path / "final_state.npz")
    x, X0, mass, t = final["x"].astype(float), final["X0"], final["mass"], float(final["time"])
    alive = mass > 0
    n = len(X0)
    # the interior's upper bound along x, where G2P removes a particle: removed
    # particles stay where they crossed, clamped to it
    hi = np.max(x[~alive, 0])
    expected = X0[:, 0] + V * t
    tol = 2 * V * m["dt_max"]  # the step at which a particle crosses: within one step of the exact time
    assert 0 < m["removed"]["total"] < n and m["removed"]["ball"] == m["removed"]["total"] == (~alive).sum()
    assert np.all(~alive[expected > hi + tol]) and np.all(alive[expected < hi - tol])
    # the ones left moved rigidly (float32 positions)
    np.testing.assert_allclose(x[alive], X0[alive] + np.array([V * t, 0.0]), atol=1e-5)
    # mass: what is left plus what left is what was there
    assert m["mass_drift"] < 1e-6
    particle_mass = mass[alive][0]  # the ball's particles all weigh the same
    assert np.all(mass[alive] == particle_mass)
    assert m["removed"]["mass"] == pytest.approx(m["removed"]["total"] * particle_mass, rel=1e-6)
    # the recording logs the particles left, with their numbers, and the removals as events
    rec = recordings.read(tmp_path / "recording.rrd")
    assert rec.index[0] is None and rec.index[-1] is not None
    assert np.array_equal(rec.index[-1], np.flatnonzero(alive)) and len(rec.positions[-1]) == alive.sum()
    assert rec.scalars["removed"][1][-1] == m["removed"]["total"]
    assert np.all(np.diff(rec.scalars["removed"][1]) >= 0)


def test_a_ball_leaving_entirely_ends_the_run_completed(tmp_path):
    m = execute(spec_for(OPEN + ["run.duration=0.25"]), tmp_path)
    assert m["status"] == "completed" and m["removed"]["total"] == m["particles"]
    assert m["mass_drift"] < 1e-6
    rec = recordings.read(tmp_path / "recording.rrd")
    assert len(rec.positions[-1]) == 0


def test_a_closed_wall_crossed_is_still_unstable(tmp_path):
    """Through a slip wall at 400 m/s the ball leaves the domain: unstable, not removed."""
    m = execute(spec_for(["scene.resolution=24", "scene.gravity=[0,0]", "scene.bodies.0.velocity=[400,0]",
                          "run.dt=1e-3", "run.steps=5", "log.every=0", "detect.action=off"]), tmp_path)
    assert m["status"] == "unstable" and m["unstable_criterion"] in ("outside", "nonfinite")
    assert "removed" not in m
