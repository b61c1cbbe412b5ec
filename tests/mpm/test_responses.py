"""A run's physical responses (mpm.responses): each quantity and reduction
against values worked out by hand, and a disc in free fall followed by a
tracker: its centre's lowest point y0 - g t^2 / 2."""

import numpy as np
import pytest

import mpm
from mpm.responses import QUANTITIES, REDUCTIONS, Response, Tracker, quantity, reached, reduce


class _Model:
    """The two fields a tracker reads: the particles' masses and each body's (start, count)."""

    def __init__(self, mass, ranges):
        self.mass = type("A", (), {"numpy": lambda self, m=np.asarray(mass, float): m})()
        self.body_ranges = ranges


X = np.array([[0.1, 0.5], [0.3, 0.2], [0.2, 0.9], [2.0, 2.0]])
M = np.array([1.0, 1.0, 2.0, 5.0])


CASES = [("bottom", 0.2), ("top", 0.9), ("height", 0.7), ("width", 0.2), ("front", 0.3), ("back", 0.1),
         ("center_x", 0.2), ("center_y", 0.625)]  # each quantity of the first three particles, by hand


@pytest.mark.parametrize("name,want", CASES)
def test_each_quantity(name, want):
    # the first three particles: centre x = (0.1 + 0.3 + 2 * 0.2) / 4, y = (0.5 + 0.2 + 1.8) / 4
    assert quantity(name, X[:3], M[:3]) == pytest.approx(want)


def test_the_lists_name_every_quantity_and_reduction():
    assert sorted(QUANTITIES) == sorted(name for name, _ in CASES)  # each has its worked value above
    values = np.array([1.0, 0.4, 0.7, 0.6])
    times = np.array([0.0, 0.1, 0.2, 0.3])  # [s]
    got = {k: reduce(k, values, times) for k in REDUCTIONS}
    # acceleration: the parabola through the four states (all from a quarter of the run on but the
    # first: three left, too few for a fit: NaN)
    assert np.isnan(got.pop("acceleration"))
    assert got == pytest.approx({"min": 0.4, "max": 1.0, "final": 0.6, "max_after_min": 0.7, "drop": 0.6})
    assert np.isnan(reduce("max", np.array([])))


def test_an_extremum_at_the_last_state_is_not_reached():
    """A ball still sinking when the run ends: its smallest height is the
    last, a bound on the compression, not the peak; once it rises again the
    peak is reached. The rebound is reached only once the rise has turned."""
    sinking = np.array([1.0, 0.9, 0.8])
    turned = np.array([1.0, 0.8, 0.9, 0.95, 0.9])
    assert not reached("drop", sinking) and not reached("min", sinking) and reached("max", sinking)
    assert reached("drop", turned) and reached("max_after_min", turned)
    assert not reached("max_after_min", turned[:4])  # still rising
    assert reached("final", sinking) and not reached("max", np.array([]))


def test_a_tracker_follows_one_body_or_all():
    model = _Model(M, [(0, 3), (3, 1)])
    tracker = Tracker([Response("low", "bottom", 0, "min"), Response("all_front", "front", None, "final")], model)
    tracker.update(X, 0.0)
    tracker.update(X - [0.0, 0.1], 0.1)
    assert tracker.values() == pytest.approx({"low": 0.1, "all_front": 2.0})
    assert tracker.reached() == {"low": False, "all_front": True}
    assert tracker.summary(["a", "b"])["low"] == {"value": pytest.approx(0.1), "unit": "m", "quantity": "bottom",
                                                  "reduce": "min", "body": "a", "reached": False}
    with pytest.raises(ValueError, match="body 2"):
        Tracker([Response("x", "top", 2)], model)
    with pytest.raises(ValueError, match="a name twice"):
        Tracker([Response("x", "top"), Response("x", "bottom")], model)
    with pytest.raises(ValueError, match="quantity 'mass'"):
        Response("x", "mass")


def test_a_falling_disc_lowest_centre(device):
    """The disc's centre falls freely for 0.1 s (no wall reached): its
    lowest value is the last, y0 - g t^2 / 2 within symplectic Euler's g dt t."""
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, gravity=(0.0, -9.81),
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.6), 0.1), mpm.NeoHookean(E=1.0e5, nu=0.3))])
    model, state = mpm.build(scene, mpm.QUADRATIC, "float64", device)
    tracker = Tracker([Response("lowest", "center_y", 0, "min")], model)

    class Follow(mpm.Observer):
        def on_start(self, driver):
            tracker.update(driver.state.x.numpy(), driver.time)

        def on_step(self, driver, report):
            tracker.update(driver.state.x.numpy(), driver.time)

    driver = mpm.Driver(mpm.Solver(model, mpm.TLMPM()), state, mpm.StepPolicy(duration=0.1), observers=[Follow()])
    driver.run()
    y0 = tracker.series[0][0][1]
    assert y0 == pytest.approx(0.6, abs=0.5 / 32)  # the sampled disc's centre, within half a cell
    dt = max(driver.dts)
    assert tracker.values()["lowest"] == pytest.approx(y0 - 0.5 * 9.81 * 0.1**2, abs=9.81 * dt * 0.1)


def test_removed_particles_are_left_out():
    """Particles removed at an open wall (``kept``: those left) do not count;
    a body with none left gives NaN for that state, and the reduction skips it."""
    model = _Model(M, [(0, 3), (3, 1)])
    tracker = Tracker([Response("front", "front", 0, "max"), Response("far", "front", 1, "max")], model)
    tracker.update(X, 0.0, kept=np.array([0, 2, 3]))  # particle 1 (x = 0.3) removed
    tracker.update(X, 0.1, kept=np.array([0, 2]))  # body 1's only particle removed
    assert tracker.values() == pytest.approx({"front": 0.2, "far": 2.0})
    assert np.isnan(tracker.series[1][1][1])
