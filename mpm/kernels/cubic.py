"""Cubic B-spline: support 4 nodes per axis, C^2.

N(d) = |d|^3 / 2 - d^2 + 2/3 for |d| < 1, (2 - |d|)^3 / 6 for 1 <= |d| < 2;
with t = x/dx - base in [1, 2) the four nodes lie at distances t, t-1, t-2, t-3.
Second moment dx^2 / 3.
"""

from typing import Any

import warp as wp

from .base import Kernel
from .spline import per_precision


@wp.func
def cubic_weights(u: Any):
    a = type(u)(2.0) - u  # node 0 at distance u in [1, 2)
    b = u - type(u)(1.0)  # node 1 at distance b in [0, 1)
    c = type(u)(2.0) - u  # node 2 at distance c in (0, 1]
    e = u - type(u)(1.0)  # node 3 at distance 3 - u = 2 - e in (1, 2]
    return wp.vector(a * a * a / type(u)(6.0),
                     type(u)(0.5) * b * b * b - b * b + type(u)(2.0) / type(u)(3.0),
                     type(u)(0.5) * c * c * c - c * c + type(u)(2.0) / type(u)(3.0),
                     e * e * e / type(u)(6.0))


@wp.func
def cubic_gradients(u: Any):
    a = type(u)(2.0) - u
    b = u - type(u)(1.0)
    c = type(u)(2.0) - u
    e = u - type(u)(1.0)
    return wp.vector(type(u)(-0.5) * a * a,
                     type(u)(1.5) * b * b - type(u)(2.0) * b,
                     -(type(u)(1.5) * c * c - type(u)(2.0) * c),
                     type(u)(0.5) * e * e)


CUBIC = Kernel(name="cubic", support=4, offset=1.0, moment=1.0 / 3.0, margin=1.0,
               weights=per_precision(cubic_weights), gradients=per_precision(cubic_gradients))
"""the cubic B-spline: support 4, C^2, one grid"""
