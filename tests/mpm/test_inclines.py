"""The incline closed forms (mpm.inclines) against what they must satisfy
independently: Newton's law for a block, the threshold where friction
holds it, and a rolling disk's energy balance and slip threshold."""

import math

import pytest

from mpm.inclines import rolling, sliding

G = 9.81


@pytest.mark.parametrize("theta", [10.0, 30.0, 60.0])
def test_a_block_slides_by_newtons_law_or_rests(theta):
    """m a = m g sin - mu m g cos while it slides; from rest it stays where
    tan theta <= mu, and a moving block decelerates there."""
    t = math.radians(theta)
    for mu in (0.0, 0.2, 0.5):
        assert sliding(theta, G, mu, 1.0) == pytest.approx(G * math.sin(t) - mu * G * math.cos(t), rel=1e-12)
    held = math.tan(t) * 1.01
    assert sliding(theta, G, held, 0.0) == 0.0 and sliding(theta, G, held, 1.0) < 0.0
    assert sliding(theta, G, math.tan(t) * 0.99, 0.0) > 0.0


@pytest.mark.parametrize("theta", [10.0, 30.0, 60.0])
def test_a_disk_rolls_by_its_energy_and_slips_below_the_threshold(theta):
    """Rolling from rest, the energy M g h = (1/2) M v^2 + (1/2) (M R^2 / 2)
    (v / R)^2 gives v^2 = (4/3) g s sin theta, a = (2/3) g sin theta; the
    friction needed, M g sin - M a = (1/3) M g sin, equals mu M g cos at
    mu = tan / 3, where rolling and sliding give the same acceleration."""
    t = math.radians(theta)
    s = 0.3  # [m] along the plane
    v2 = 4.0 / 3.0 * G * s * math.sin(t)
    threshold = math.tan(t) / 3.0
    assert rolling(theta, G, 1.0) == pytest.approx(v2 / (2 * s), rel=1e-12)
    assert rolling(theta, G, threshold) == pytest.approx(sliding(theta, G, threshold), rel=1e-9)
    below = 0.9 * threshold
    assert rolling(theta, G, below) == sliding(theta, G, below) > rolling(theta, G, 1.0)


@pytest.mark.parametrize("theta", [10.0, 30.0, 60.0])
def test_a_sphere_rolls_by_its_energy_and_slips_below_the_threshold(theta):
    """A solid sphere (I = (2/5) M R^2) from rest: M g h = (1/2) M v^2 +
    (1/2) (2/5) M R^2 (v / R)^2 gives v^2 = (10/7) g s sin theta, a =
    (5/7) g sin theta; the friction needed, (2/7) M g sin, equals
    mu M g cos at mu = (2/7) tan."""
    t = math.radians(theta)
    s = 0.3  # [m] along the plane
    v2 = 10.0 / 7.0 * G * s * math.sin(t)
    threshold = 2.0 / 7.0 * math.tan(t)
    assert rolling(theta, G, 1.0, "sphere") == pytest.approx(v2 / (2 * s), rel=1e-12)
    assert rolling(theta, G, threshold, "sphere") == pytest.approx(sliding(theta, G, threshold), rel=1e-9)
    below = 0.9 * threshold
    assert rolling(theta, G, below, "sphere") == sliding(theta, G, below) > rolling(theta, G, 1.0, "sphere")
