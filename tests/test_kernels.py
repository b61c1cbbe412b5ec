"""Interpolation kernels: partition of unity, linear reproduction, second
moment, gradient against a centred difference, stencil size."""

import functools

import numpy as np
import pytest
import warp as wp

import mpm
from mpm.types import make_types

KERNELS = list(mpm.KERNELS.values())


@functools.cache
def evaluator(kernel):
    t = make_types(2, "float64")
    weights, gradients = kernel.weights(t), kernel.gradients(t)
    Wv = wp.types.vector(kernel.support, wp.float64)

    @wp.kernel(module="unique")
    def run(u: wp.array(dtype=wp.float64), w: wp.array(dtype=Wv), dw: wp.array(dtype=Wv)):
        i = wp.tid()
        w[i] = weights(u[i])
        dw[i] = gradients(u[i])

    return run, Wv


def weights_at(kernel, x):
    """1-D weights and t-derivatives of the stencil of particles at x (dx = 1)."""
    base = np.floor(x - kernel.offset)
    u = x - base
    run, Wv = evaluator(kernel)
    w = wp.zeros(len(x), dtype=Wv)
    dw = wp.zeros(len(x), dtype=Wv)
    wp.launch(run, len(x), inputs=[wp.array(u, dtype=wp.float64), w, dw])
    nodes = base[:, None] + np.arange(kernel.support)[None, :]
    return nodes, w.numpy(), dw.numpy()


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_moments(kernel):
    x = np.random.default_rng(0).uniform(3.0, 9.0, 1000)
    nodes, w, _ = weights_at(kernel, x)
    r = nodes - x[:, None]
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-14)  # partition of unity
    np.testing.assert_allclose((w * r).sum(1), 0.0, atol=1e-14)  # linear reproduction
    np.testing.assert_allclose((w * r * r).sum(1), kernel.moment, atol=1e-14)  # K_p
    assert np.all(w >= 0.0)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_gradient_against_centred_difference(kernel):
    """dN/dx at fixed nodes, N(x) = sum over the stencil; central difference
    with h = 1e-6 has error O(h^2) + O(eps / h)."""
    x = np.random.default_rng(1).uniform(3.0, 9.0, 200)
    h = 1e-6
    nodes, _, dw = weights_at(kernel, x)

    def weight_of(node, xs):
        n2, w2, _ = weights_at(kernel, xs)
        return np.where(n2 == node[:, None], w2, 0.0).sum(1)

    for s in range(kernel.support):
        fd = (weight_of(nodes[:, s], x + h) - weight_of(nodes[:, s], x - h)) / (2 * h)
        np.testing.assert_allclose(dw[:, s], fd, atol=1e-8)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_weights_vanish_outside_the_stencil(kernel):
    """The kernel is continuous: nodes entering or leaving the stencil as a
    particle crosses a cell boundary carry zero weight."""
    x = np.arange(3, 9) + kernel.offset  # exactly at a stencil switch
    nodes_hi, w_hi, _ = weights_at(kernel, x)
    nodes_lo, w_lo, _ = weights_at(kernel, x - 1e-12)
    assert np.all(nodes_hi[:, 0] == nodes_lo[:, 0] + 1)
    np.testing.assert_allclose(w_lo[:, 0], 0.0, atol=1e-10)  # leaving node
    np.testing.assert_allclose(w_hi[:, -1], 0.0, atol=1e-10)  # entering node


def test_stencil_sizes():
    assert mpm.KERNELS["quadratic"].support ** 2 == 9
    assert mpm.KERNELS["quadratic"].support ** 3 == 27
