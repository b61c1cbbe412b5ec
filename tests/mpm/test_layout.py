"""The per-body reference grids (mpm.layout): every box covers the stencils
of its body's positions, the device tables follow the host's, and a commit
that changes nothing uploads nothing."""

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.layout import GridLayout
from mpm.types import make_types


def covers(lay, box, x):
    """Every stencil of positions x lies in ``box`` (kernel grid box % G)."""
    k = lay.kernel
    first = np.floor(x / lay.dx - k.grids[box % k.n_grids] - k.offset)
    return np.all(first >= lay.lo[box]) and np.all(first + k.support <= lay.lo[box] + lay.shape[box])


def device_tables(lay):
    return lay.lo_d.numpy(), lay.shape_d.numpy(), lay.offset_d.numpy()


@pytest.mark.parametrize("kernel", ["quadratic", "compact"])
@pytest.mark.parametrize("shared", [False, True])
def test_boxes_cover_the_bodies_and_unchanged_tables_are_not_uploaded(kernel, shared, monkeypatch):
    k = mpm.KERNELS[kernel]
    t = make_types(3, "float32")
    dx, cells = 0.1, (40, 40, 40)
    lay = GridLayout(t, k, dx, cells, n_bodies=2, device="cpu", shared=shared)
    uploads = []
    assign = wp.array.assign
    monkeypatch.setattr(wp.array, "assign", lambda self, v: (uploads.append(1), assign(self, v))[1])
    rng = np.random.default_rng(0)
    bodies = [rng.uniform(0.5, 1.5, (50, 3)), rng.uniform(2.0, 3.2, (50, 3))]

    def fit_all(xs):
        for b, x in enumerate(xs):
            lay.fit(b, x.min(axis=0), x.max(axis=0))
        lay.commit()

    fit_all(bodies)
    assert len(uploads) == 3  # the first commit uploads every table
    for b, x in enumerate(bodies):
        for g in range(k.n_grids):
            assert covers(lay, b * k.n_grids + g, x)
            if shared:
                assert covers(lay, b * k.n_grids + g, bodies[1 - b])
    for host, device in zip((lay.lo, lay.shape, lay.offset), device_tables(lay)):
        np.testing.assert_array_equal(device, host)
    sizes = np.prod(lay.shape, axis=1)
    assert lay.n_nodes == (sizes[:k.n_grids].sum() if shared else sizes.sum())

    uploads.clear()  # the bounds move by less than any cell boundary in between: nothing to upload
    lo_before, shape_before = lay.lo.copy(), lay.shape.copy()
    fit_all([x + 1e-6 for x in bodies])
    assert np.array_equal(lay.lo, lo_before) and np.array_equal(lay.shape, shape_before)
    assert uploads == []

    uploads.clear()  # body 1 moves by two cells: its boxes (and the offsets) change
    moved = [bodies[0], bodies[1] + 2 * dx]
    fit_all(moved)
    assert 0 < len(uploads) <= 3
    for b, x in enumerate(moved):
        assert all(covers(lay, b * k.n_grids + g, x) for g in range(k.n_grids))
    for host, device in zip((lay.lo, lay.shape, lay.offset), device_tables(lay)):
        np.testing.assert_array_equal(device, host)


@pytest.mark.parametrize("dim,kernel", [(2, "compact"), (3, "quadratic")])
def test_eulerian_nodes_sit_where_the_particles_put_them(dim, kernel):
    """EMPM's grid update places node i of box b at (lo_b + its index + o_g) dx
    (mpm.stencil.make_node_position); a Lagrangian scheme's P2G accumulates
    sum_p w_ip m_p (x_p + F^sn r) / m_i, which is the same point when the
    reference grid is the current one (x_p + r = X_i): equal to round-off on
    every node with mass, in several bodies' boxes and both compact grids."""
    from test_reference import tiny_scene

    scene = tiny_scene(dim)
    q = []
    for scheme in (mpm.EMPM(), mpm.AULMPM(epsilon=0.0, eta=1.0, affine="keep", criterion="paper")):
        model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", "cpu")
        solver = mpm.Solver(model, scheme)
        solver.prepare(state)
        solver.step(state, 1e-4)
        n = solver.layout.n_nodes
        has_mass = solver.grid.m.numpy()[:n] > 0
        q.append(solver.grid.q.numpy()[:n][has_mass])
    assert len(solver.layout.lo) == len(scene.bodies) * mpm.KERNELS[kernel].n_grids > 1
    assert len(q[0]) > 50
    np.testing.assert_allclose(q[0], q[1], rtol=0, atol=1e-13)
