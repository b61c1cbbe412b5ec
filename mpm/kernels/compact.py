"""The compact C^2 kernel of CK-MPM on a staggered pair of grids.

K(x) = 1 - |x| + sin(2 pi |x|) / (2 pi) on |x| < 1 (units of dx), with
K(t) + K(1 - t) = 1. Two grids, shifted by -dx/4 and +dx/4 from the lattice;
on each a particle touches 2 nodes per axis with weights (K(t), 1 - K(t)), so
2^d nodes per grid, 16 in 3D against 27 for the quadratic B-spline. Each grid
receives the full mass; velocities come back averaged. A single grid does not
reproduce linear fields: the first moments of the two grids cancel, so only
the pair does, and the MLS/APIC moment matrix is a full, per-particle matrix.
"""

import functools
import math

import warp as wp

from ..types import Types
from .base import Kernel


@functools.cache
def _weights(t: Types):
    S = t.scalar
    W = wp.types.vector(2, S)
    two_pi = 2.0 * math.pi

    @wp.func
    def weights(u: S):
        k = S(1.0) - u + wp.sin(S(two_pi) * u) / S(two_pi)
        return W(k, S(1.0) - k)

    return weights


@functools.cache
def _gradients(t: Types):
    S = t.scalar
    W = wp.types.vector(2, S)
    two_pi = 2.0 * math.pi

    @wp.func
    def gradients(u: S):
        dk = wp.cos(S(two_pi) * u) - S(1.0)
        return W(dk, -dk)

    return gradients


COMPACT = Kernel(name="compact", support=2, offset=0.0, moment=None, margin=1.0,
                 weights=_weights, gradients=_gradients, grids=(-0.25, 0.25))
