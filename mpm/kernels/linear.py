"""Linear (tent) B-spline: support 2 nodes per axis, C^0.

With t = x/dx - base in [0, 1): w = (1 - t, t). Its second moment t (1 - t)
dx^2 vanishes on the nodes, so the MLS/APIC moment matrix is singular there:
the affine matrix and the force come from the kernel gradient instead (APIC
paper, multilinear case), and MLS and APIC coincide.
"""

from typing import Any

import warp as wp

from .base import Kernel
from .spline import per_precision


@wp.func
def linear_weights(u: Any):
    return wp.vector(type(u)(1.0) - u, u)


@wp.func
def linear_gradients(u: Any):
    return wp.vector(type(u)(-1.0), type(u)(1.0))


LINEAR = Kernel(name="linear", support=2, offset=0.0, moment=None, margin=1.0,
                weights=per_precision(linear_weights), gradients=per_precision(linear_gradients),
                gradient_affine=True)
"""the linear (tent) B-spline: support 2, C^0, one grid"""
