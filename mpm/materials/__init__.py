"""Constitutive models, one module each; :data:`MATERIALS` maps names to classes."""

from __future__ import annotations

import dataclasses

from .base import Material, lame
from .fixed_corotated import FixedCorotated
from .fluid import Fluid
from .neo_hookean import NeoHookean

MATERIALS: dict[str, type[Material]] = {
    cls.name: cls for cls in (FixedCorotated, NeoHookean, Fluid)
}


def material_fields(model: str) -> list[str]:
    """Parameter names accepted by a model (``model`` itself included)."""
    return [f.name for f in dataclasses.fields(MATERIALS[model])]


__all__ = ["MATERIALS", "Material", "FixedCorotated", "NeoHookean", "Fluid", "lame",
           "material_fields"]
