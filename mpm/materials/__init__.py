"""Constitutive models, one module each; :data:`MATERIALS` maps names to classes.

Elastic: ``fixed_corotated``, ``neo_hookean``. Fluids: ``viscous``
(Newtonian, weakly compressible) and ``fluid`` (the same, inviscid by
default). Plastic (mpm.materials.plastic, a return mapping every step):
``snow``, ``sand``, ``von_mises``, ``nacc``, ``viscoplastic``. A model
defined elsewhere joins them with :func:`register_material`
(mpm.materials.registry; docs/extending.md).
"""

from __future__ import annotations

import dataclasses

from .base import Material, lame
from .fixed_corotated import FixedCorotated
from .nacc import NACC
from .neo_hookean import NeoHookean
from .plastic import Plastic
from .registry import MATERIALS, _add, material_problem, register_material
from .sand import Sand
from .snow import Snow
from .viscoplastic import Viscoplastic
from .viscous import Fluid, Viscous
from .von_mises import VonMises

for _cls in (FixedCorotated, NeoHookean, Fluid, Viscous, Snow, Sand, VonMises, NACC, Viscoplastic):
    _add(_cls, factories=False)
del _cls, _add


def material_fields(model: str) -> list[str]:
    """Parameter names accepted by a model (``model`` itself included)."""
    return [f.name for f in dataclasses.fields(MATERIALS[model])]


__all__ = ["MATERIALS", "Material", "Plastic", "FixedCorotated", "NeoHookean", "Fluid", "Viscous",
           "Snow", "Sand", "VonMises", "NACC", "Viscoplastic", "lame", "material_fields", "material_problem",
           "register_material"]
