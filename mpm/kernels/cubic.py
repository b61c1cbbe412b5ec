"""Cubic B-spline: support 4 nodes per axis, C^2.

N(d) = |d|^3 / 2 - d^2 + 2/3 for |d| < 1, (2 - |d|)^3 / 6 for 1 <= |d| < 2;
with t = x/dx - base in [1, 2) the four nodes lie at distances t, t-1, t-2, t-3.
Second moment dx^2 / 3.
"""

import functools

import warp as wp

from ..types import Types
from .base import Kernel


@functools.cache
def _weights(t: Types):
    S = t.scalar
    W = wp.types.vector(4, S)

    @wp.func
    def weights(u: S):
        a = S(2.0) - u  # node 0 at distance u in [1, 2)
        b = u - S(1.0)  # node 1 at distance b in [0, 1)
        c = S(2.0) - u  # node 2 at distance c in (0, 1]
        e = u - S(1.0)  # node 3 at distance 3 - u = 2 - e in (1, 2]
        return W(a * a * a / S(6.0),
                 S(0.5) * b * b * b - b * b + S(2.0) / S(3.0),
                 S(0.5) * c * c * c - c * c + S(2.0) / S(3.0),
                 e * e * e / S(6.0))

    return weights


@functools.cache
def _gradients(t: Types):
    S = t.scalar
    W = wp.types.vector(4, S)

    @wp.func
    def gradients(u: S):
        a = S(2.0) - u
        b = u - S(1.0)
        c = S(2.0) - u
        e = u - S(1.0)
        return W(S(-0.5) * a * a,
                 S(1.5) * b * b - S(2.0) * b,
                 -(S(1.5) * c * c - S(2.0) * c),
                 S(0.5) * e * e)

    return gradients


CUBIC = Kernel(name="cubic", support=4, offset=1.0, moment=1.0 / 3.0, margin=1.0,
               weights=_weights, gradients=_gradients)
"""the cubic B-spline: support 4, C^2, one grid"""
