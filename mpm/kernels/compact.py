"""The compact C^2 kernel of CK-MPM on a staggered pair of grids.

K(x) = 1 - |x| + sin(2 pi |x|) / (2 pi) on |x| < 1 (units of dx), with
K(t) + K(1 - t) = 1. Two grids, shifted by -dx/4 and +dx/4 from the lattice;
on each a particle touches 2 nodes per axis with weights (K(t), 1 - K(t)), so
2^d nodes per grid, 16 in 3D against 27 for the quadratic B-spline. Each grid
receives the full mass; velocities come back averaged. A single grid does not
reproduce linear fields: the first moments of the two grids cancel, so only
the pair does, and the MLS/APIC moment matrix is a full, per-particle matrix.

Evaluated without cancellation: with g(s) = s - sin(2 pi s)/(2 pi) the
weights are (g(1 - t), g(t)) and g is summed from its Taylor series
(2 pi)^2 s^3/6 - (2 pi)^4 s^5/120 + ... for small s; the derivative is
K'(t) = cos(2 pi t) - 1 = -2 sin^2(pi t). Written as 1 - K(t) and
cos - 1, a particle sitting on a node of one grid got node masses and forces
made of round-off (1e-19 kg, 5e8 m/s in float32) and blew up with the PIC
transfer.
"""

import functools
import math

import warp as wp

from ..types import Types
from .base import Kernel

SERIES_BELOW = 0.05  # g(s) by its series below this (x = 2 pi s < 0.32: 5 terms, abs. err < 1e-16)


@functools.cache
def _g_series(t: Types):
    """g(s) = s - sin(2 pi s) / (2 pi) by its series, for s < SERIES_BELOW."""
    S = t.scalar
    two_pi = 2.0 * math.pi
    c3, c5, c7, c9, c11 = (two_pi**2 / 6.0, -(two_pi**4) / 120.0, two_pi**6 / 5040.0,
                           -(two_pi**8) / 362880.0, two_pi**10 / 39916800.0)

    @wp.func
    def g_series(s: S):
        s2 = s * s
        return s * s2 * (S(c3) + s2 * (S(c5) + s2 * (S(c7) + s2 * (S(c9) + s2 * S(c11)))))

    return g_series


@functools.cache
def _phase(t: Types, with_gradients: bool):
    """``phase(u) -> (sin 2 pi u, sin^2 pi u, cos^2 pi u)`` (the last two only
    ``with_gradients``): what both grids' weights and slopes take from the
    sines. Grid 1 sits half a cell from grid 0, t_1 = t_0 - 1/2 + n, so
    sin 2 pi t_1 = -sin 2 pi t_0 and sin^2 pi t_1 = cos^2 pi t_0: one sine per
    axis (one sine and cosine with slopes) for both grids."""
    S = t.scalar
    P = wp.types.vector(3, S)
    half_turn, two_pi = math.pi, 2.0 * math.pi  # Python floats: Warp would evaluate 2 * pi in float32

    @wp.func
    def phase(u: S):
        if wp.static(with_gradients):
            s = wp.sin(S(half_turn) * u)
            # cos(pi u) as sin(pi (1/2 - u)): 1/2 - u is exact near u = 1/2, so a
            # particle on a node of grid 1 gets a slope of exactly zero there
            c = wp.sin(S(half_turn) * (S(0.5) - u))
            return P(S(2.0) * s * c, s * s, c * c)
        else:
            return P(wp.sin(S(two_pi) * u), S(0.0), S(0.0))

    return phase


@functools.cache
def _weights_at(t: Types):
    """(g(1 - u), g(u)) on grid g from the shared ``phase`` of grid 0."""
    S = t.scalar
    W = wp.types.vector(2, S)
    P = wp.types.vector(3, S)
    g_series = _g_series(t)
    two_pi = 2.0 * math.pi

    @wp.func
    def weights_at(u: S, ph: P, g: int):
        r = ph[0] / S(two_pi)  # sin(2 pi u) / (2 pi); sin(2 pi (1 - u)) = -sin(2 pi u)
        if g == 1:
            r = -r
        a = S(1.0) - u
        wa = a + r
        wb = u - r
        if a < S(SERIES_BELOW):
            wa = g_series(a)
        if u < S(SERIES_BELOW):
            wb = g_series(u)
        return W(wa, wb)

    return weights_at


@functools.cache
def _gradients_at(t: Types):
    S = t.scalar
    W = wp.types.vector(2, S)
    P = wp.types.vector(3, S)

    @wp.func
    def gradients_at(u: S, ph: P, g: int):
        s2 = ph[1]  # sin^2(pi u) on grid 0, cos^2 on grid 1
        if g == 1:
            s2 = ph[2]
        dk = S(-2.0) * s2  # K'(t) = cos(2 pi t) - 1 = -2 sin^2(pi t)
        return W(dk, -dk)

    return gradients_at


def _on_grid0(at, with_gradients: bool):
    """The factory of ``at``'s function (``_weights_at`` or ``_gradients_at``)
    on its own, at grid 0: one sine, (g(1 - u), g(u)) or K'(u)."""

    @functools.cache
    def factory(t: Types):
        phase, f_at = _phase(t, with_gradients), at(t)

        @wp.func
        def on_grid0(u: t.scalar):
            return f_at(u, phase(u), 0)

        return on_grid0

    return factory


_weights = _on_grid0(_weights_at, False)
_gradients = _on_grid0(_gradients_at, True)


COMPACT = Kernel(name="compact", support=2, offset=0.0, moment=None, margin=1.0,
                 weights=_weights, gradients=_gradients, grids=(-0.25, 0.25),
                 phase=_phase, weights_at=_weights_at, gradients_at=_gradients_at)
"""CK-MPM's compact C^2 kernel: support 2 on two grids shifted by -dx/4 and +dx/4"""
