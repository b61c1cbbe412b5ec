"""The spilled-fluid measure (mpm.diagnostics.spilled_fraction) and its
nearest-particle search (mpm.diagnostics.nearest_points)."""

import numpy as np
import pytest

from mpm.diagnostics import nearest_points, spilled_fraction
from mpm.scene import Bowl

BOWL = Bowl(center=(0.5, 0.385, 0.5), radius=0.26, thickness=0.05, rim=0.08)
SPACING = 0.01  # [m] the lattice of the bowl's and the fluid's points


def _lattice(lo, hi, h):
    axes = [np.arange(a + 0.5 * h, b, h) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(lo))


def _bowl_and_fluid():
    """The bowl's particles and a fluid's: 3/4 of the fluid in the cavity's
    lower half, 1/4 outside the bowl below its rim, all at least two
    spacings from the wall."""
    lo, hi = BOWL.bounds()
    pts = _lattice(lo - 0.1, hi + 0.1, SPACING)
    X_bowl = pts[BOWL.contains(pts)]
    d = pts - np.asarray(BOWL.center)
    r, h = np.linalg.norm(d, axis=1), d[:, 1]
    inside = pts[(r < BOWL.radius - 2 * SPACING) & (h < -0.05)]
    outside = pts[(r > BOWL.radius + BOWL.thickness + 2 * SPACING) & (h < BOWL.rim) & (h > -0.2)]
    rng = np.random.default_rng(1)
    inside = inside[rng.choice(len(inside), 300, replace=False)]
    outside = outside[rng.choice(len(outside), 100, replace=False)]
    return X_bowl, np.concatenate([inside, outside])


def test_nearest_points_is_the_brute_force_nearest():
    """Against the full distance table, in 3D and 2D, with queries inside,
    beside and far outside the points' cloud (found by doubling the cells)."""
    rng = np.random.default_rng(0)
    for dim in (2, 3):
        points = rng.random((3000, dim))
        queries = np.concatenate([rng.random((400, dim)) * 1.6 - 0.3, rng.random((3, dim)) + 40.0])
        brute = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(-1).argmin(1)
        assert (nearest_points(queries, points, radius=0.01) == brute).all()


def test_a_settled_squashed_bowl_is_judged_in_its_own_shape():
    """The bowl falls 0.2 m and flattens (x' = A (X - c) + c + t, A =
    diag(1.05, 0.85, 1.05)) with the fluid carried by the same map: a quarter
    of the fluid is outside below the rim, as before the motion. Against the
    bowl's initial place (no bowl particles given), the fluid resting on its
    lowered floor counts as outside too, which the measure once reported as a
    leak through the wall."""
    X_bowl, fluid = _bowl_and_fluid()
    assert spilled_fraction(fluid, BOWL) == pytest.approx(0.25)
    c = np.asarray(BOWL.center)
    A, t = np.diag([1.05, 0.85, 1.05]), np.array([0.01, -0.2, 0.0])

    def move(p):
        return (p - c) @ A.T + c + t

    x_bowl, moved = move(X_bowl), move(fluid)
    assert spilled_fraction(moved, BOWL, x_bowl, X_bowl, SPACING) == pytest.approx(0.25)
    assert spilled_fraction(moved, BOWL) > 0.4  # the initial place: the lowered floor's fluid "outside"


def test_fluid_through_the_wall_counts_as_spilled():
    """A fluid particle moved from the cavity to just outside the wall's
    outer face below the rim (no motion of the bowl) counts, judged either
    way: the measure still sees a real leak."""
    X_bowl, fluid = _bowl_and_fluid()
    leak = np.asarray(BOWL.center) + np.array([0.0, -(BOWL.radius + BOWL.thickness + 1.5 * SPACING), 0.0])
    with_leak = np.concatenate([fluid, leak[None]])
    expected = (100 + 1) / len(with_leak)
    assert spilled_fraction(with_leak, BOWL, X_bowl, X_bowl, SPACING) == pytest.approx(expected)
    assert spilled_fraction(with_leak, BOWL) == pytest.approx(expected)
