"""A kernel's ``weights`` and ``gradients`` factories (mpm.kernels.base)
from its 1-D formula written once: a generic Warp function of t (any
scalar type; constants as ``type(u)(c)``, so that they are of the
precision's type) returning the vector of the support's values."""

import functools

import warp as wp

from ..types import Types


def per_precision(formula):
    """The factory ``types -> Warp function t -> formula(t)`` of t.scalar,
    named as ``formula`` is (the registry tells kernels apart by where their
    weights factory is defined, mpm.kernels.registry)."""

    @functools.cache
    def factory(t: Types):
        S = t.scalar

        @wp.func
        def at(u: S):
            return formula(u)

        return at

    factory.__module__, factory.__qualname__ = formula.func.__module__, formula.func.__qualname__
    return factory
