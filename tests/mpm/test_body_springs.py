"""Contact between bodies through springs on their particles (mpm.body_springs, ``contact="elastic"``)."""

import sys
from pathlib import Path

import numpy as np
import pytest

import mpm
from mpm.body_springs import shares
from mpm.model import SceneError

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
import rolling  # noqa: E402  (examples/rolling.py)


@pytest.mark.parametrize("scheme", ["empm", "tlmpm"])
def test_a_disk_rolls_on_an_elastic_slab(scheme):
    """A disk (R = 0.1 m, E = 2e5 Pa) rolling from rest down a slab ten
    times stiffer at 20 degrees, mu = 0.5, 64 cells across 1 m: rolling
    without slip, a = (2/3) g sin(theta) (mpm.inclines.rolling). The
    issue's targets at 64 cells: within 3 %, slip under 0.1 cell from
    0.1 s on (measured +0.56 % / -0.07 cell EMPM, +0.70 % / -0.06 TLMPM).
    The grid's contact between bodies (mpm.contact) loses the approach it
    takes out at the band of nodes under the patch every step: -4.6 %
    (EMPM) and -11.4 % (TLMPM) at 64 cells (RESULTS.md)."""
    r = rolling.roll(on="body", scheme=scheme, resolution=64, boundary="elastic")
    assert abs(r.error) < 0.03, r.error
    assert abs(r.slip) < 0.1 * 1.0 / 64, r.slip


def test_the_grid_contact_loses_what_the_springs_keep():
    """The same disk with the grid's Coulomb contact between the bodies
    (``contact="friction"``): beyond the 3 % target (-4.6 % measured), the
    loss the springs mend."""
    r = rolling.roll(on="body", scheme="empm", resolution=64, boundary="separate")
    assert r.error < -0.03, r.error


def disks(contact: str = "elastic", friction: float = 0.0, resolution: int = 30) -> mpm.Scene:
    """Two elastic disks striking head-on along the diagonal (Sulsky, Chen
    and Schreyer 1994; conf/scene/two_disks.yaml), no gravity."""
    mat = mpm.NeoHookean(E=1000.0, nu=0.3, rho=1000.0)
    return mpm.Scene(dim=2, domain=(1.5, 1.5), resolution=resolution, gravity=(0.0, 0.0), walls=("slip",) * 4,
                     bodies=[mpm.Body(mpm.Sphere((0.5, 0.5), 0.2), mat, velocity=(0.1, 0.1)),
                             mpm.Body(mpm.Sphere((1.0, 1.0), 0.2), mat, velocity=(-0.1, -0.1))],
                     contact=contact, contact_friction=friction)


@pytest.mark.parametrize("scheme", [mpm.EMPM, mpm.TLMPM])
def test_two_disks_strike_and_part_keeping_momentum(scheme):
    """The two disks meet at t = 0.8 s (their surfaces 0.307 m apart,
    closing at 0.283 m/s) and part by 2.5 s. Each spring's force on a
    particle is taken back, in the same step, by the particles of the other
    body under it, so the total momentum, zero, stays zero to round-off
    (float64: 1e-12 of the bodies' momentum scale m |v|), every step. The
    springs store and give back, so the kinetic energy at the end is at
    most the initial (a spring gains none) and the disks part: each moves
    back along the diagonal."""
    model, state = mpm.build(disks(), mpm.QUADRATIC, "float64", "cpu")
    solver = mpm.Solver(model, scheme(), mpm.SolverOptions())
    m = model.mass.numpy()
    scale = float(m.sum()) * 0.1 * np.sqrt(2.0)

    class Momentum(mpm.Observer):
        worst = 0.0

        def on_step(self, driver, report):
            p = (m[:, None] * driver.state.v.numpy()).sum(axis=0)
            self.worst = max(self.worst, float(np.abs(p).max()) / scale)

    watch = Momentum()
    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=2.5), observers=[watch])
    assert driver.run().status == "completed"
    assert watch.worst < 1e-12, watch.worst
    v = driver.state.v.numpy()
    (a0, a1), (b0, b1) = model.body_ranges
    va, vb = v[a0:a0 + a1].mean(axis=0), v[b0:b0 + b1].mean(axis=0)
    assert va[0] < 0.0 and va[1] < 0.0 and vb[0] > 0.0 and vb[1] > 0.0, (va, vb)
    kinetic = 0.5 * float((m * (v**2).sum(axis=1)).sum())
    assert kinetic <= 0.5 * float(m.sum()) * 0.02 * (1.0 + 1e-9), kinetic


def test_the_softer_body_meets_the_stiffers_surface():
    """[a, b]: 1 where b is stiffer (a slave on b's surface), 1/2 between
    equals (each on the other's), 0 where b is softer and on the diagonal."""
    share = shares([2.0, 1.0, 1.0])
    assert share.tolist() == [[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [1.0, 0.5, 0.0]]


@pytest.mark.parametrize("stiffness", [0.0, -1.0, 4.5, float("nan")])
def test_a_contact_stiffness_out_of_range_is_named(stiffness):
    scene = disks()
    scene.contact_stiffness = stiffness
    with pytest.raises(SceneError, match="contact_stiffness"):
        mpm.build(scene, mpm.QUADRATIC)


def test_elastic_contact_is_refused_under_the_implicit_integrator():
    model, _ = mpm.build(disks(), mpm.QUADRATIC)
    with pytest.raises(ValueError, match="options.integrator: elastic colliders and contact"):
        mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=mpm.Implicit()))


def test_the_rolling_slab_scene_is_the_examples_disk_on_the_slab():
    """conf/scene/rolling_slab_2d.yaml builds the scene examples/rolling.py
    runs on the slab (the disk, the slab and its held strip, the 20 degree
    gravity, elastic contact at mu = 0.5), so its figures are the example's."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from helpers import spec_for  # tests/helpers.py

    scene, expected = spec_for(["scene=rolling_slab_2d"]).scene, rolling.scene(on="body", boundary="elastic")
    assert (scene.domain, scene.resolution, scene.ppc) == (tuple(expected.domain), 64, expected.ppc)
    assert scene.gravity == pytest.approx(expected.gravity, rel=1e-7)
    for key in ("contact", "contact_friction", "contact_stiffness", "contact_normal", "contact_share",
                "contact_fill"):
        assert getattr(scene, key) == getattr(expected, key), key
    for body, reference in zip(scene.bodies, expected.bodies, strict=True):
        assert body.shape == reference.shape and body.material == reference.material
    (region,), (reference,) = scene.regions, expected.regions
    assert (region.body, region.select, tuple(region.velocity)) == (reference.body, reference.select,
                                                                   tuple(reference.velocity))
