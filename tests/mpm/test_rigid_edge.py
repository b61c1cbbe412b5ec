"""A rigid body's box at the edges where its faces meet
(mpm.collider_device.make_edge): a block dropped with the compact kernel,
whose grids sit a quarter cell off the box's rows, slides instead of tipping."""

import pytest

pytest.importorskip("newton")


def test_block_dropped_with_the_compact_kernel_slides_without_tipping():
    """examples/rigid_incline.py, EMPM with the compact kernel, the block
    (0.1 x 0.05 m, mu = 0.3) dropped 5 mm onto the elastic slab at 32 cells,
    30 deg, over 0.2 s (the fit from 0.1 s): it slides at g (sin th - mu
    cos th) = 2.356 m/s^2 (mpm.inclines.sliding). Measured +0.3 % over 0.2 s
    (+1.3 % over 0.4 s), asked within 4 %. Before a node more than OUTSIDE cells
    under the bottom passed over the side face whose plane it lies behind,
    the node 0.25 cells inside the front edge took the side face, lost the
    bottom's support, and the block tipped (-88 % over 0.2 s, -117 % over
    0.4 s; RESULTS.md)."""
    from helpers import load_example

    run = load_example("rigid_incline").run("slide", 32, 30.0, 0.3, 0.2, kernel="compact")
    assert abs(run.error) < 0.04, run.error
