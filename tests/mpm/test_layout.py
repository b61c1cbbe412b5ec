"""The per-body reference grids (mpm.reference_grids): every box covers the stencils
of its body's positions, the device tables follow the host's, and a commit
that changes nothing uploads nothing."""

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.reference_grids import GridLayout
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
        solver.schedule(1e-4)
        solver.attempt(state)
        n = solver.layout.n_nodes
        has_mass = solver.grid.m.numpy()[:n] > 0
        q.append(solver.grid.q.numpy()[:n][has_mass])
    assert len(solver.layout.lo) == len(scene.bodies) * mpm.KERNELS[kernel].n_grids > 1
    assert len(q[0]) > 50
    np.testing.assert_allclose(q[0], q[1], rtol=0, atol=1e-13)


@pytest.mark.parametrize("kernel", ["quadratic", "compact"])
def test_refitting_one_body_leaves_the_others_steps_alone(kernel):
    """A Lagrangian body's stencils are cached at its last configuration
    update; another body's update that grows its own grid moves the boxes'
    offsets in the flat arrays. The cached stencils hold indices within their
    box, so the untouched body steps on, bit for bit, as in a run where
    nothing was refitted (two bodies far apart, no contact, TLMPM)."""
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, gravity=(0.0, -9.81), contact="none",
                      bodies=[mpm.Body(mpm.Sphere((0.3, 0.5), 0.1), mpm.FixedCorotated(), velocity=(0.5, 0.0)),
                              mpm.Body(mpm.Sphere((0.7, 0.5), 0.1), mpm.NeoHookean(), velocity=(0.0, 1.0))])
    runs = []
    for refit in (False, True):
        model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", "cpu")
        solver = mpm.Solver(model, mpm.TLMPM())
        solver.prepare(state)
        for k in range(20):
            report = solver.advance(state, 2e-4)
            if refit and k == 5:  # body 0's reference moves into a grid three cells wider
                offsets = solver.layout.offset.copy()
                solver.references.fit([0], report.box_lo, report.box_hi, pad=3 * model.dx)
                solver.references.move(state, [0], solver.const)
                assert solver.layout.offset[solver.model.kernel.n_grids] != offsets[solver.model.kernel.n_grids]
        body = model.body.numpy()
        runs.append({k: v[body == 1] for k, v in state.numpy().items() if k != "history"})
    for name in ("x", "v", "C", "F"):
        np.testing.assert_array_equal(runs[0][name], runs[1][name])
