"""The pieces the plastic models' return mappings (``flow``,
mpm.materials.plastic) are built from, in principal stretches sigma.

* On the Hencky strain eps_i = ln sigma_i (sand, von Mises):
  ``hencky_strain`` (eps and tr eps), ``deviator`` (dev eps = eps - tr eps / d
  and its norm) and ``radial_return``, eps moved back along dev eps by a
  plastic amount and turned back into stretches (``exp_strain``).
* On the isochoric left Cauchy-Green strain b_bar_i = J^(-2/d) sigma_i^2
  (NACC, viscoplastic): ``isochoric_b`` (its mean and deviator) and
  ``stretches_of_b``, the stretches of a mean and a (scaled) deviator at the
  volume J.
"""

import functools

import warp as wp

from ..types import Types
from .plastic import STRETCH_FLOOR


@functools.cache
def make_hencky_strain(t: Types):
    """``hencky_strain(sigma) -> (eps, tr eps)``, eps_i = ln max(|sigma_i|, floor)."""
    S = t.scalar
    vec = t.vec

    @wp.func
    def hencky_strain(sigma: t.vec):
        eps = vec()
        tr = S(0.0)
        for i in range(wp.static(t.dim)):
            eps[i] = wp.log(wp.max(wp.abs(sigma[i]), S(STRETCH_FLOOR)))  # pyright: ignore[reportArgumentType]
            tr += eps[i]
        return eps, tr

    return hencky_strain


@functools.cache
def make_exp_strain(t: Types):
    """``exp_strain(eps) -> sigma``, sigma_i = exp(eps_i)."""
    vec = t.vec

    @wp.func
    def exp_strain(eps: t.vec):
        sigma = vec()
        for i in range(wp.static(t.dim)):
            sigma[i] = wp.exp(eps[i])
        return sigma

    return exp_strain


@functools.cache
def make_deviator(t: Types):
    """``deviator(eps, tr) -> (dev, |dev|)``: the deviator eps - tr/d 1 of a
    strain eps of trace tr, and its norm."""
    S = t.scalar
    d = float(t.dim)
    ones = t.vec(*([1.0] * t.dim))

    @wp.func
    def deviator(eps: t.vec, tr: S):
        dev = eps - (tr / S(d)) * ones
        return dev, wp.length(dev)

    return deviator


@functools.cache
def make_radial_return(t: Types):
    """``radial_return(eps, dev, norm, delta) -> sigma``: the stretches
    exp(eps - delta dev / |dev|) of the Hencky strain eps returned by delta
    along its deviator dev (norm |dev|) when delta > 0 and |dev| > 0, else
    exp(eps)."""
    S = t.scalar
    exp_strain = make_exp_strain(t)

    @wp.func
    def radial_return(eps: t.vec, dev: t.vec, norm: S, delta: S):
        if delta > S(0.0) and norm > S(0.0):
            return exp_strain(eps - (delta / norm) * dev)
        return exp_strain(eps)

    return radial_return


@functools.cache
def make_isochoric_b(t: Types):
    """``isochoric_b(sigma) -> (stretches, J, mean, dev)``: the stretches
    |sigma_i| (floored), J = their product, and the mean and deviator of the
    isochoric left Cauchy-Green strain b_bar_i = J^(-2/d) sigma_i^2 (the
    models on b_E: NACC, viscoplastic; s = mu dev)."""
    S = t.scalar
    vec = t.vec
    d = float(t.dim)
    minus_two_over_d = -2.0 / t.dim
    ones = vec(*([1.0] * t.dim))

    @wp.func
    def isochoric_b(sigma: t.vec):
        a = vec()
        J = S(1.0)
        for i in range(wp.static(t.dim)):
            a[i] = wp.max(wp.abs(sigma[i]), S(STRETCH_FLOOR))
            J *= a[i]
        scale = wp.pow(J, S(minus_two_over_d))
        b = vec()
        for i in range(wp.static(t.dim)):
            b[i] = scale * a[i] * a[i]
        mean = wp.dot(b, ones) / S(d)
        return a, J, mean, b - mean * ones

    return isochoric_b


@functools.cache
def make_stretches_of_b(t: Types):
    """``stretches_of_b(mean, dev, J) -> sigma``: the principal stretches whose
    isochoric strain is mean + dev and whose volume is J (an isochoric
    return keeps the volume exactly)."""
    S = t.scalar
    vec = t.vec
    one_over_d = 1.0 / t.dim

    @wp.func
    def stretches_of_b(mean: S, dev: t.vec, J: S):
        out = vec()
        prod = S(1.0)
        for i in range(wp.static(t.dim)):
            out[i] = wp.sqrt(wp.max(mean + dev[i], S(0.0)))  # pyright: ignore[reportArgumentType]
            prod *= out[i]
        return out * wp.pow(J / wp.max(prod, S(1.0e-30)), S(one_over_d))

    return stretches_of_b
