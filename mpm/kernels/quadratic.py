"""Quadratic B-spline: support 3 nodes per axis, C^1.

With t = x/dx - base in [0.5, 1.5):
w = (1/2 (3/2 - t)^2, 3/4 - (t - 1)^2, 1/2 (t - 1/2)^2).
"""

from typing import Any

import warp as wp

from .base import Kernel
from .spline import per_precision


@wp.func
def quadratic_weights(u: Any):
    a = type(u)(1.5) - u
    b = u - type(u)(1.0)
    c = u - type(u)(0.5)
    return wp.vector(type(u)(0.5) * a * a, type(u)(0.75) - b * b, type(u)(0.5) * c * c)


@wp.func
def quadratic_gradients(u: Any):
    return wp.vector(u - type(u)(1.5), type(u)(-2.0) * (u - type(u)(1.0)), u - type(u)(0.5))


QUADRATIC = Kernel(
    name="quadratic", support=3, offset=0.5, moment=0.25, margin=1.0,
    weights=per_precision(quadratic_weights), gradients=per_precision(quadratic_gradients),
)
"""the quadratic B-spline: support 3, C^1, one grid (the default)"""
