"""Interpolation kernels: partition of unity, linear-field reproduction (for
the compact kernel: on the pair of grids, not on one), second moment,
gradient against a centred difference, weights vanishing outside the
stencil, stencil sizes."""

import functools

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.launch import warp_kernel
from mpm.types import make_types

KERNELS = list(mpm.KERNELS.values())


@functools.cache
def evaluator(kernel):
    t = make_types(2, "float64")
    weights, gradients = kernel.weights(t), kernel.gradients(t)
    Wv = wp.types.vector(kernel.support, wp.float64)

    @warp_kernel
    def run(u: wp.array(dtype=wp.float64), w: wp.array(dtype=Wv), dw: wp.array(dtype=Wv)):
        i = wp.tid()
        w[i] = weights(u[i])
        dw[i] = gradients(u[i])

    return run, Wv


def weights_at(kernel, x, g=0):
    """1-D weights and t-derivatives on grid g of particles at x (dx = 1):
    node positions, weights, derivatives."""
    o = kernel.grids[g]
    base = np.floor(x - o - kernel.offset)
    u = x - o - base
    run, Wv = evaluator(kernel)
    w = wp.zeros(len(x), dtype=Wv)
    dw = wp.zeros(len(x), dtype=Wv)
    wp.launch(run, len(x), inputs=[wp.array(u, dtype=wp.float64), w, dw])
    nodes = base[:, None] + np.arange(kernel.support)[None, :] + o
    return nodes, w.numpy(), dw.numpy()


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_partition_of_unity_and_linear_reproduction(kernel):
    x = np.random.default_rng(0).uniform(3.0, 9.0, 1000)
    first = np.zeros_like(x)
    second = np.zeros_like(x)
    for g in range(kernel.n_grids):
        nodes, w, _ = weights_at(kernel, x, g)
        r = nodes - x[:, None]
        np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-14)  # each grid: full mass
        assert np.all(w >= -1e-15)
        first += (w * r).sum(1) / kernel.n_grids
        second += (w * r * r).sum(1) / kernel.n_grids
        if kernel.n_grids == 1:  # a single B-spline grid reproduces linear fields
            np.testing.assert_allclose((w * r).sum(1), 0.0, atol=1e-14)
    np.testing.assert_allclose(first, 0.0, atol=1e-14)  # the grids together do
    if kernel.moment is not None:
        np.testing.assert_allclose(second, kernel.moment, atol=1e-14)  # constant K_p
    else:
        assert np.ptp(second) > 1e-3  # varies: K_p per particle


def test_compact_grid_alone_does_not_reproduce_linear_fields():
    k = mpm.KERNELS["compact"]
    x = np.random.default_rng(1).uniform(3.0, 9.0, 100)
    nodes, w, _ = weights_at(k, x, 0)
    assert np.abs((w * (nodes - x[:, None])).sum(1)).max() > 1e-2


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_gradient_against_centred_difference(kernel):
    """dw/dx at fixed nodes by central differences, h = 1e-6: error O(h^2)
    where the kernel is smooth (the linear kernel only away from nodes)."""
    x = np.random.default_rng(1).uniform(3.0, 9.0, 200)
    h = 1e-6
    for g in range(kernel.n_grids):
        nodes, _, dw = weights_at(kernel, x, g)

        def weight_of(node, xs, g=g):
            n2, w2, _ = weights_at(kernel, xs, g)
            return np.where(np.isclose(n2, node[:, None]), w2, 0.0).sum(1)

        for s in range(kernel.support):
            fd = (weight_of(nodes[:, s], x + h) - weight_of(nodes[:, s], x - h)) / (2 * h)
            np.testing.assert_allclose(dw[:, s], fd, atol=1e-7)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_weights_vanish_outside_the_stencil(kernel):
    """Continuity: a node entering or leaving the stencil as the particle
    crosses a cell boundary carries zero weight there."""
    for g, o in enumerate(kernel.grids):
        x = np.arange(3, 9) + o + kernel.offset  # exactly at a stencil switch
        nodes_hi, w_hi, _ = weights_at(kernel, x, g)
        nodes_lo, w_lo, _ = weights_at(kernel, x - 1e-12, g)
        assert np.allclose(nodes_hi[:, 0], nodes_lo[:, 0] + 1)
        np.testing.assert_allclose(w_lo[:, 0], 0.0, atol=1e-10)  # leaving node
        np.testing.assert_allclose(w_hi[:, -1], 0.0, atol=1e-10)  # entering node


def test_compact_kernel_is_c2():
    """K(x) = 1 - |x| + sin(2 pi |x|)/(2 pi): value, slope and curvature
    vanish at |x| = 1 and the slope at 0 (C^2 across 0 and 1)."""
    k = mpm.KERNELS["compact"]
    _, w, dw = weights_at(k, np.array([4.75 + 1e-9, 5.25]))  # t = 0 and 0.5 on grid 0 (nodes at i - 1/4)
    assert w[0, 0] == pytest.approx(1.0) and dw[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert w[1, 0] == pytest.approx(0.5)  # K(t) + K(1 - t) = 1


def test_stencil_sizes():
    assert mpm.KERNELS["compact"].stencil_nodes(3) == 16
    assert mpm.KERNELS["quadratic"].stencil_nodes(3) == 27
    assert mpm.KERNELS["cubic"].stencil_nodes(3) == 64
    assert mpm.KERNELS["linear"].stencil_nodes(3) == 8


def test_compact_weights_are_accurate_next_to_a_node_in_float32():
    """A particle within 1e-6..1e-2 of a node: the far node's weight t -
    sin(2 pi t)/(2 pi) ~ 6.58 t^3 and the slope -2 sin^2(pi t) keep their
    relative accuracy in float32 (by subtraction they were round-off, and a
    PIC run blew up on them)."""
    k = mpm.KERNELS["compact"]
    t32 = make_types(1 + 1, "float32")
    weights, gradients = k.weights(t32), k.gradients(t32)
    W = wp.types.vector(2, wp.float32)

    @warp_kernel
    def run(u: wp.array(dtype=wp.float32), w: wp.array(dtype=W), dw: wp.array(dtype=W)):
        i = wp.tid()
        w[i] = weights(u[i])
        dw[i] = gradients(u[i])

    t = np.logspace(-6, -2, 30)
    w, dw = wp.zeros(len(t), dtype=W), wp.zeros(len(t), dtype=W)
    wp.launch(run, len(t), inputs=[wp.array(t.astype(np.float32), dtype=wp.float32), w, dw])
    x = 2 * np.pi * t.astype(np.float32).astype(np.float64)
    exact = (x**3 / 6 - x**5 / 120 + x**7 / 5040) / (2 * np.pi)  # far node, t - sin(2 pi t)/(2 pi)
    np.testing.assert_allclose(w.numpy()[:, 1], exact, rtol=1e-5)
    np.testing.assert_allclose(dw.numpy()[:, 1], 2 * np.sin(x / 2) ** 2, rtol=1e-5)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("with_gradients", [False, True])
def test_compact_grids_share_one_phase(precision, with_gradients):
    """The stencils the solver locates (mpm.stencil: both grids from grid 0's
    sine, sin 2 pi t_1 = -sin 2 pi t_0, sin^2 pi t_1 = cos^2 pi t_0) equal the
    kernel's 1-D weights and slopes evaluated on each grid's own coordinate,
    to round-off of an O(1) quantity; also where the stencil is clamped to
    the box (t outside [0, 1)) and next to a node (the series)."""
    from mpm.stencil import make_locate, make_origin, weight_matrix_type

    k = mpm.KERNELS["compact"]
    t = make_types(3, precision)
    origin, locate = make_origin(t, k, with_gradients), make_locate(t, k, with_gradients)
    weights, gradients = k.weights(t), k.gradients(t)
    Wm = weight_matrix_type(t, k)
    G = wp.types.vector(2, t.scalar)

    @warp_kernel
    def run(X: wp.array(dtype=t.vec), lo: t.ivec, shape: t.ivec, W: wp.array2d(dtype=Wm),
            dW: wp.array2d(dtype=Wm), W1: wp.array2d(dtype=Wm), dW1: wp.array2d(dtype=Wm)):
        i = wp.tid()
        offsets = G(t.scalar(-0.25), t.scalar(0.25))
        u0, P = origin(X[i], t.scalar(1.0), offsets)
        for g in range(2):
            flat, fx, w, dw = locate(u0, P, offsets[g] - offsets[0], g, lo, shape, 0)
            W[i, g] = w
            dW[i, g] = dw
            for d in range(3):  # the 1-D functions on this grid's own coordinate
                a = weights(fx[d])
                b = gradients(fx[d])
                for s in range(2):
                    W1[i, g][d, s] = a[s]
                    dW1[i, g][d, s] = b[s]

    rng = np.random.default_rng(7)
    X = rng.uniform(2.0, 30.0, (400, 3))
    X[:50] = np.round(X[:50] * 4.0) / 4.0 + rng.uniform(-1e-3, 1e-3, (50, 3))  # next to a node of a grid
    X[50:60] = rng.uniform(0.0, 2.0, (10, 3))  # before the box: clamped stencils
    X[60:70] = np.floor(X[60:70]) + 0.25  # exactly on a node of grid 1 (dx = 1)
    lo, shape = t.ivec(2, 2, 2), t.ivec(30, 30, 30)
    out = [wp.zeros((len(X), 2), dtype=Wm) for _ in range(4)]
    wp.launch(run, len(X), inputs=[wp.array(X, dtype=t.vec), lo, shape, *out])
    W, dW, W1, dW1 = (a.numpy() for a in out)
    eps = np.finfo(np.float32 if precision == "float32" else np.float64).eps
    np.testing.assert_allclose(W, W1, rtol=0, atol=16 * eps)
    if with_gradients:
        np.testing.assert_allclose(dW, dW1, rtol=0, atol=16 * eps)
    # on a node, the far node's weight and slope are exactly zero (no momentum without mass)
    np.testing.assert_array_equal(W[60:70, 1][:, :, 1], 0.0)
    if with_gradients:
        np.testing.assert_array_equal(dW[60:70, 1], 0.0)
    inside = np.r_[0:50, 60:len(X)]  # each grid: a partition of unity (a clamped stencil is not)
    np.testing.assert_allclose(W[inside].sum(-1), 1.0, atol=4 * eps)
