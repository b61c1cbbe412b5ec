"""Linear (tent) B-spline: support 2 nodes per axis, C^0.

With t = x/dx - base in [0, 1): w = (1 - t, t). Its second moment t (1 - t)
dx^2 vanishes on the nodes, so the MLS/APIC moment matrix is singular there:
the affine matrix and the force come from the kernel gradient instead (APIC
paper, multilinear case), and MLS and APIC coincide.
"""

import functools

import warp as wp

from ..types import Types
from .base import Kernel


@functools.cache
def _weights(t: Types):
    S = t.scalar
    W = wp.types.vector(2, S)

    @wp.func
    def weights(u: S):
        return W(S(1.0) - u, u)

    return weights


@functools.cache
def _gradients(t: Types):
    S = t.scalar
    W = wp.types.vector(2, S)

    @wp.func
    def gradients(u: S):
        return W(S(-1.0), S(1.0))

    return gradients


LINEAR = Kernel(name="linear", support=2, offset=0.0, moment=None, margin=1.0,
                weights=_weights, gradients=_gradients, gradient_affine=True)
"""the linear (tent) B-spline: support 2, C^0, one grid"""
