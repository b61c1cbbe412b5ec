"""The physics groups: ``material``, ``scheme``, ``integrator`` and
``detect`` are the solver's own dataclasses (:mod:`mpm.materials`,
:mod:`mpm.schemes`, :mod:`mpm.integrators`, :class:`mpm.Detection`), whose
fields declare their defaults, docs, ranges and accepted names with
:func:`mpm.params.param`; nothing about them is restated here. Each option
of a group is its class (registered by :mod:`pipelines.config.schema`)."""

from __future__ import annotations

import mpm
from mpm.integrators import INTEGRATORS
from mpm.materials import MATERIALS, Material

from .fields import Context, Family, check, plain

MATERIAL = Family("material", "model", MATERIALS, example="{model: fluid, K: 1.0e5}")
SCHEME = Family("scheme", "name", mpm.SCHEMES)
INTEGRATOR = Family("integrator", "name", INTEGRATORS)
GROUPS = {"material": MATERIAL, "scheme": SCHEME, "integrator": INTEGRATOR}  # a ConfigStore node per option


def make_material(d, key: str = "material") -> Material:
    """A material from a ``material`` group node or an inline mapping."""
    return MATERIAL.check(plain(d), key, Context())


def make_scheme(d, key: str = "scheme"):
    return SCHEME.check(plain(d), key, Context())


def make_integrator(d, key: str = "integrator"):
    return INTEGRATOR.check(plain(d), key, Context())


def make_detect(d, key: str = "detect") -> mpm.Detection:
    return check(mpm.Detection, plain(d) or {}, key)

