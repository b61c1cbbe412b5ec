"""Quadratic B-spline: support 3 nodes per axis, C^1.

With t = x/dx - base in [0.5, 1.5):
w = (1/2 (3/2 - t)^2, 3/4 - (t - 1)^2, 1/2 (t - 1/2)^2).
"""

import functools

import warp as wp

from ..types import Types
from .base import Kernel


@functools.cache
def _weights(t: Types):
    S = t.scalar
    W = wp.types.vector(3, S)

    @wp.func
    def weights(u: S):
        a = S(1.5) - u
        b = u - S(1.0)
        c = u - S(0.5)
        return W(S(0.5) * a * a, S(0.75) - b * b, S(0.5) * c * c)

    return weights


@functools.cache
def _gradients(t: Types):
    S = t.scalar
    W = wp.types.vector(3, S)

    @wp.func
    def gradients(u: S):
        return W(u - S(1.5), S(-2.0) * (u - S(1.0)), u - S(0.5))

    return gradients


QUADRATIC = Kernel(
    name="quadratic", support=3, offset=0.5, moment=0.25, margin=1.0,
    weights=_weights, gradients=_gradients,
)
"""the quadratic B-spline: support 3, C^1, one grid (the default)"""
