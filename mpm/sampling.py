"""Fill shapes with particles at a chosen number of particles per cell, and
the shapes' exact volumes that the particles share (mpm.model).

Two samplings (``Body.sampling``, :data:`SAMPLINGS`): "lattice", a regular
sub-lattice of the grid cut by the shape (:func:`sample_shape`; a ball's
top layer is then a flat facet); "shells", body-fitted for balls and discs
(:func:`sample_shells`): concentric layers about one sampling spacing apart,
the outermost half a layer inside the surface, so that the particles'
surface is a sphere (a circle) at their own scale."""

from __future__ import annotations

import math

import numpy as np

from .meshes import MeshShape
from .scene import Bowl, Box, Compound, Cylinder, Rotated, Sphere

SAMPLINGS = ("lattice", "shells")
"""lattice: the grid's sub-lattice cut by the shape (any shape); shells:
concentric layers (mpm.Sphere only: a ball in 3D, a disc in 2D, hollow or
not), each particle the volume of its layer over the layer's count."""
SHELL_SHAPES = "mpm.Sphere (a ball in 3D, a disc in 2D)"

PARTICLE_VOLUMES = ("shape", "cells")
"""shape: the particles of a body share its shape's exact volume equally
(where the shape has one: see :func:`shape_volume`); cells: each particle
stands for its sampling cell, dx^d / ppc (the union of the cells, not the
shape: a disc of 6 cells' radius at 4 particles per cell differs by a few
per cent)."""


def sample_shape(shape, dim: int, dx: float, ppc: int, jitter: float,
                 rng: np.random.Generator, offset=None) -> np.ndarray:
    """Particle positions [m] inside ``shape``, ``ppc`` candidates per grid cell.

    If ``ppc = k^dim`` the candidates form a regular k^dim sub-lattice at the
    sub-cell centres (displaced by ``jitter`` times the sub-spacing, uniformly
    at random) and shifted by ``offset`` [cells] per axis; otherwise they
    are uniform random points in each cell. Each particle then stands for a
    volume ``dx^dim / ppc``, or a share of :func:`shape_volume`.
    """
    lo, hi = shape.bounds()
    c0 = np.floor(np.asarray(lo) / dx).astype(np.int64)
    c1 = np.ceil(np.asarray(hi) / dx).astype(np.int64)
    axes = [np.arange(a, b) for a, b in zip(c0, c1)]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dim).astype(float)

    k = round(ppc ** (1.0 / dim))
    if k**dim == ppc:
        sub = (np.arange(k) + 0.5) / k
        offsets = np.stack(np.meshgrid(*([sub] * dim), indexing="ij"), -1).reshape(-1, dim)
        pts = (cells[:, None, :] + offsets[None, :, :]).reshape(-1, dim)
        if offset is not None:
            pts += np.asarray(offset, float)
        if jitter > 0.0:
            pts += (rng.random(pts.shape) - 0.5) * (jitter / k)
    else:
        pts = (cells[:, None, :] + rng.random((len(cells), ppc, dim))).reshape(-1, dim)
    pts *= dx
    return pts[shape.contains(pts)]


def sampling_problem(sampling, shape) -> str | None:
    """What is wrong with a body's ``sampling`` for its ``shape`` (one line
    ending in the accepted values), or None."""
    if sampling not in SAMPLINGS:
        return f"{sampling!r}; accepted: {', '.join(SAMPLINGS)}"
    if sampling == "shells" and type(shape) is not Sphere:
        return f"shells for a {type(shape).__name__}; accepted: lattice (any shape), shells for {SHELL_SHAPES}"
    return None


def sample_body(shape, sampling: str, dim: int, dx: float, ppc: int, spacing: float, jitter: float,
                rng: np.random.Generator, offset=None) -> tuple[np.ndarray, np.ndarray | None]:
    """A body's particle positions [m] by its ``sampling`` (``spacing`` [m]:
    its particles' at sampling, mpm.scene.Scene.spacings), and their volumes
    [m^d] where the sampling sets them (shells), else None (the caller
    shares the shape's volume or the cells')."""
    if sampling == "shells" and isinstance(shape, Sphere):
        return sample_shells(shape, dim, spacing)
    return sample_shape(shape, dim, dx, ppc, jitter, rng, offset), None


def sample_shells(shape: Sphere, dim: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Particle positions [m] (n, dim) and volumes [m^d] (n,) filling the ball
    (disc) ``shape`` on concentric layers, about ``spacing`` [m] apart.

    The radial span R - r_i is cut into n = max(1, round((R - r_i) / s))
    shells of equal thickness h = (R - r_i) / n; shell k holds
    N_k = max(1, round(V_k / s^d)) particles on the sphere (circle) of its
    mid radius, V_k its exact volume, each particle V_k / N_k (so the
    volumes add up to the shape's exactly). In 2D the ring's angles are
    evenly spaced, each ring turned by the golden angle from the last; in 3D
    a Fibonacci spiral about the z axis spreads them over equal areas.
    """
    c = np.asarray(shape.center, float)
    R, ri = float(shape.radius), float(shape.inner_radius)
    n = max(1, round((R - ri) / spacing))
    h = (R - ri) / n
    golden = math.pi * (3.0 - math.sqrt(5.0))  # [rad]
    xs, vs = [], []
    for k in range(n):
        a, b = ri + k * h, ri + (k + 1) * h
        r = 0.5 * (a + b)
        V = math.pi * (b * b - a * a) if dim == 2 else 4.0 / 3.0 * math.pi * (b**3 - a**3)
        N = max(1, round(V / spacing**dim))
        i = np.arange(N, dtype=float)
        if dim == 2:
            t = 2.0 * math.pi * i / N + golden * k
            u = np.stack([np.cos(t), np.sin(t)], -1)
        else:
            z = 1.0 - (2.0 * i + 1.0) / N
            t = golden * i + golden * k
            w = np.sqrt(np.maximum(1.0 - z * z, 0.0))
            u = np.stack([w * np.cos(t), w * np.sin(t), z], -1)
        xs.append(c + r * u)
        vs.append(np.full(N, V / N))
    return np.concatenate(xs), np.concatenate(vs)


def _ball_below(r: float, h: float, dim: int) -> float:
    """Volume [m^d] of a ball (a disc in 2D) of radius ``r`` below the plane
    (line) at height ``h`` above its centre."""
    h = min(max(h, -r), r)
    if dim == 2:  # the disc minus the segment above the chord
        return r * r * (math.pi - math.acos(h / r)) + h * math.sqrt(r * r - h * h)
    a = r + h  # the cap's height
    return math.pi * a * a * (3.0 * r - a) / 3.0


def shape_volume(shape, dim: int) -> float | None:
    """The exact volume [m^d] (area in 2D) of a scene shape: closed forms for
    boxes, balls, cylinders and bowls (and their shells), the divergence
    theorem over a mesh's triangles, a rotated shape's own, a union's sum when
    its parts' bounding boxes do not overlap; None for a union of overlapping
    parts (no closed form)."""
    if isinstance(shape, Rotated):
        return shape_volume(shape.shape, dim)
    if isinstance(shape, Box):
        return float(np.prod(2.0 * np.asarray(shape.half_size, float)))
    if isinstance(shape, Sphere):
        r, ri = shape.radius, shape.inner_radius
        return math.pi * (r * r - ri * ri) if dim == 2 else 4.0 / 3.0 * math.pi * (r**3 - ri**3)
    if isinstance(shape, Cylinder):
        return math.pi * (shape.radius**2 - shape.inner_radius**2) * 2.0 * shape.half_height
    if isinstance(shape, Bowl):
        R, t, h = shape.radius, shape.thickness, shape.rim
        return _ball_below(R + t, h, dim) - _ball_below(R, h, dim)
    if isinstance(shape, MeshShape):  # sum over the triangles of a . (b x c) / 6
        pts, tris = shape.geometry
        a, b, c = (pts[tris[:, k]].astype(np.float64) for k in range(3))
        return float(abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)
    if isinstance(shape, Compound):
        boxes = [tuple(np.asarray(v, float) for v in p.bounds()) for p in shape.parts]
        for i, (lo, hi) in enumerate(boxes):
            for lo2, hi2 in boxes[:i]:
                if np.all(lo < hi2) and np.all(lo2 < hi):
                    return None
        volumes = [shape_volume(p, dim) for p in shape.parts]
        known = [v for v in volumes if v is not None]
        return float(sum(known)) if len(known) == len(volumes) else None
    return None
