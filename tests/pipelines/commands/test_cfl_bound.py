"""python -m pipelines.cfl_bound: the explicit step's linear stability bound
per kernel."""

import numpy as np
import pytest


def test_linear_bound_of_the_lumped_hat_kernel_is_the_cfl_number_one():
    """pipelines.cfl_bound against the closed form: linear elements with
    lumped mass have omega_max = 2 c / dx, i.e. k* = 1 exactly, in 1D and
    2D, with MLS or gradient weights; the smoother B-splines allow more
    (quadratic sqrt(3) in 1D with the exact gradient on a fine periodic
    lattice, within the lattice's resolution of the highest mode)."""
    from pipelines.cfl_bound import bound

    for dim in (1, 2):
        for mls in (True, False):
            assert bound("linear", mls, dim=dim, cells=8) == pytest.approx(1.0, rel=1e-9)
    assert bound("quadratic", False, dim=1, cells=40) == pytest.approx(np.sqrt(3.0), rel=1e-3)
    assert bound("linear", dim=1) < bound("quadratic", dim=1) < bound("cubic", dim=1)
