"""Elastic colliders (mpm.elastic_contact): springs on the particles that touch them."""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

import mpm
from mpm.inclines import sliding

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
import plane_shift  # noqa: E402  (examples/plane_shift.py)
import rolling  # noqa: E402  (examples/rolling.py)


def test_a_disk_rolls_on_an_elastic_collider_whatever_the_step():
    """A disk (R = 0.1 m, E = 2e5 Pa) rolling from rest down a 20 degree
    collider at mu = 0.5, 64 cells across 1 m: a = (2/3) g sin(theta)
    (mpm.inclines.rolling). The grid rule loses the approach it takes out
    at the nodes under the contact every step, so its error grows as the
    step shrinks (RESULTS.md: -5.3 % at 2e-4 s, -7.8 % at 1e-4 s); the
    springs store it and give it back: the same disk within 3 % at both
    steps (the target of the contact benchmarks at 64 cells), within 1.5 %
    of each other."""
    runs = {dt: rolling.roll(resolution=64, boundary="elastic", dt=dt) for dt in (2e-4, 1e-4)}
    for dt, r in runs.items():
        assert abs(r.error) < 0.03, (dt, r.error)
    assert abs(runs[2e-4].acceleration - runs[1e-4].acceleration) < 0.015 * runs[1e-4].expected
    grid = rolling.roll(resolution=64, boundary="separate", dt=1e-4)
    assert grid.error < -0.03, grid.error  # the grid rule at the short step: the loss this mends


@pytest.mark.parametrize("shift", [0.0, 0.25, 0.5])
def test_a_block_slides_on_an_elastic_plane_wherever_it_lies_between_nodes(shift):
    """A block (E = 2e5 Pa) sliding down an elastic plane at 30 degrees,
    mu = 0.3, 64 cells, the plane shifted by 0, 0.25 and 0.5 cells from a
    node row: a = g (sin theta - mu cos theta) within 1 % (the issue's
    target; measured +0.25 / +0.04 / +0.24 %). At 0.25 cells the block's
    lowest particles are sampled on the plane, overlapping it by their half
    spacing: without taking that overlap as their rest (lap,
    mpm.elastic_contact) the springs threw the block off and the run
    stopped at step 2."""
    motion = plane_shift.run(shift, 30.0, 0.3, rule="elastic")
    expected = sliding(30.0, plane_shift.G, 0.3, 0.0)
    assert abs(plane_shift.acceleration(motion) / expected - 1.0) < 0.01


def test_an_elastic_collider_is_refused_under_the_implicit_integrator():
    model, _ = mpm.build(rolling.scene(resolution=64, boundary="elastic"), mpm.QUADRATIC)
    with pytest.raises(ValueError, match="options.integrator: elastic colliders"):
        mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=mpm.Implicit()))


@pytest.mark.parametrize("stiffness", [0.0, -1.0, 5.0, float("nan")])
def test_a_stiffness_out_of_range_is_named(stiffness):
    plane = rolling.scene(resolution=64, boundary="elastic").colliders[0]
    problems = dataclasses.replace(plane, stiffness=stiffness).problems(2)
    assert [field for field, _ in problems] == ["stiffness"]


def test_the_rolling_scene_is_the_examples_disk_on_an_elastic_collider():
    """conf/scene/rolling_2d.yaml builds the scene examples/rolling.py runs
    (the disk, the 20 degree gravity, the elastic plane), so its figures
    are the example's."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from helpers import spec_for  # tests/helpers.py

    scene, expected = spec_for(["scene=rolling_2d"]).scene, rolling.scene(resolution=64, boundary="elastic")
    assert (scene.domain, scene.resolution, scene.ppc) == (tuple(expected.domain), 64, expected.ppc)
    assert scene.gravity == pytest.approx(expected.gravity, rel=1e-7)
    plane, reference = scene.colliders[0], expected.colliders[0]
    for key in ("type", "boundary", "friction", "stiffness", "point", "normal"):
        assert tuple(np.atleast_1d(getattr(plane, key))) == tuple(np.atleast_1d(getattr(reference, key))), key
    assert scene.bodies[0].shape == expected.bodies[0].shape
    assert scene.bodies[0].material == expected.bodies[0].material
