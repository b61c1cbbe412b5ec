"""Warp scalar, vector and matrix types for one (dimension, precision) pair.

Every kernel factory takes a :class:`Types` so that one body of code serves
2D and 3D, float32 and float64, each combination compiled on its own.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import warp as wp


@wp.struct
class _Probe:
    unused: int


# the base class of every @wp.struct instance: Warp does not export it, so it
# is read off an instance that the public wp.struct made
StructInstance = next(c for c in type(_Probe()).__mro__ if c.__name__ == "StructInstance")

__all__ = ["PRECISIONS", "N_MATERIAL_PARAMS", "N_HISTORY", "StructInstance", "Types", "make_types"]

PRECISIONS = ("float32", "float64")

# Length of the per-body material parameter vector (see mpm.materials).
N_MATERIAL_PARAMS = 8
# Per-particle history variables of plastic models (see mpm.materials.plastic).
N_HISTORY = 2


@dataclass(frozen=True, eq=False)
class Types:
    """Warp types of one specialisation; obtain with :func:`make_types`."""

    dim: int
    precision: str
    scalar: type
    vec: type  # position, velocity [m, m/s]
    mat: type  # F, C, stress
    ivec: type  # grid indices
    params: type  # per-body material parameters
    history: type  # per-particle history variables of plastic models

    def __repr__(self) -> str:
        return f"Types({self.dim}D, {self.precision})"


@functools.cache
def make_types(dim: int, precision: str) -> Types:
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    scalar = wp.float32 if precision == "float32" else wp.float64
    return Types(
        dim=dim,
        precision=precision,
        scalar=scalar,
        vec=wp.types.vector(dim, scalar),
        mat=wp.types.matrix((dim, dim), scalar),
        ivec=wp.types.vector(dim, wp.int32),
        params=wp.types.vector(N_MATERIAL_PARAMS, scalar),
        history=wp.types.vector(N_HISTORY, scalar),
    )
