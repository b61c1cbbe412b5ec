"""Volumes and surface areas of the scene shapes, computed independently of
mpm.scene and mpm.sampling: closed forms for boxes, balls, cylinders and
bowls (and their shells), the divergence theorem over a mesh's triangles,
and for a union of overlapping parts a midpoint quadrature on a fine
lattice with membership tests written here."""

from __future__ import annotations

import math

import numpy as np

import mpm
from mpm.meshes import MeshShape


def _ball_below(rho: float, h: float) -> float:
    """Volume of a ball of radius rho below the plane at height h above its centre."""
    if h >= rho:
        return 4.0 / 3.0 * math.pi * rho**3
    if h <= -rho:
        return 0.0
    return math.pi * (rho + h) ** 2 * (2.0 * rho - h) / 3.0


def inside(shape, x: np.ndarray) -> np.ndarray:
    """Membership of the points x (n, d) in a primitive, rotated or compound shape."""
    if isinstance(shape, mpm.scene.Rotated):
        c = np.asarray(shape.shape.center, float)
        return inside(shape.shape, c + (x - c) @ shape.R)  # x = c + R (y - c)
    if isinstance(shape, mpm.Compound):
        return np.any([inside(p, x) for p in shape.parts], axis=0)
    d = x - np.asarray(shape.center, float)
    if isinstance(shape, mpm.Box):
        return np.all(np.abs(d) <= np.asarray(shape.half_size), axis=1)
    if isinstance(shape, mpm.Sphere):
        r2 = np.sum(d * d, axis=1)
        return (r2 <= shape.radius**2) & (r2 >= shape.inner_radius**2)
    if isinstance(shape, mpm.Cylinder):
        along = d[:, shape.axis]
        r2 = np.sum(d * d, axis=1) - along**2
        return (np.abs(along) <= shape.half_height) & (r2 <= shape.radius**2) & (r2 >= shape.inner_radius**2)
    raise TypeError(type(shape).__name__)


def volume_and_area(shape, dim: int, spacing: float) -> tuple[float, float, float]:
    """(volume, surface area, the volume's own error bound): exact for a single
    shape (bound 0); for a compound, the volume of the union by the midpoint
    rule on a lattice of ``spacing``, whose error is within sqrt(d)/2 of a
    lattice cell across the surface (area: the parts' sum, an upper bound)."""
    if isinstance(shape, mpm.scene.Rotated):
        return volume_and_area(shape.shape, dim, spacing)
    if isinstance(shape, MeshShape):
        pts, tris = shape.geometry
        a, b, c = (pts[tris[:, k]] for k in range(3))
        return (abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0,
                0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum(), 0.0)
    if isinstance(shape, mpm.Box):
        e = 2.0 * np.asarray(shape.half_size, float)
        area = 2 * (e[0] + e[1]) if dim == 2 else 2 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2])
        return float(np.prod(e)), float(area), 0.0
    if isinstance(shape, mpm.Sphere):
        r, ri = shape.radius, shape.inner_radius
        if dim == 2:
            return math.pi * (r * r - ri * ri), 2 * math.pi * (r + ri), 0.0
        return 4.0 / 3.0 * math.pi * (r**3 - ri**3), 4 * math.pi * (r * r + ri * ri), 0.0
    if isinstance(shape, mpm.Cylinder):
        r, ri, L = shape.radius, shape.inner_radius, 2.0 * shape.half_height
        return (math.pi * (r * r - ri * ri) * L, 2 * math.pi * (r + ri) * L + 2 * math.pi * (r * r - ri * ri),
                0.0)
    if isinstance(shape, mpm.scene.Bowl):
        assert dim == 3
        R, t, h = shape.radius, shape.thickness, shape.rim
        volume = _ball_below(R + t, h) - _ball_below(R, h)
        area = (2 * math.pi * (R + t) * (R + t + min(h, R + t)) + 2 * math.pi * R * (R + min(h, R))
                + math.pi * max((R + t) ** 2 - h * h, 0.0))
        return volume, area, 0.0
    if isinstance(shape, mpm.Compound):
        area = sum(volume_and_area(p, dim, spacing)[1] for p in shape.parts)
        lo, hi = (np.asarray(b, float) for b in shape.bounds())
        axes = [np.arange(a + 0.5 * spacing, b, spacing) for a, b in zip(lo, hi)]
        n = 0
        for x0 in axes[0]:  # a slab at a time: the lattice can hold tens of millions of points
            grid = np.stack(np.meshgrid(*([[x0]] + axes[1:]), indexing="ij"), -1).reshape(-1, dim)
            n += int(inside(shape, grid).sum())
        return n * spacing**dim, area, 0.5 * math.sqrt(dim) * area * spacing
    raise TypeError(type(shape).__name__)
