"""Fill shapes with particles at a chosen number of particles per cell."""

from __future__ import annotations

import numpy as np


def sample_shape(shape, dim: int, dx: float, ppc: int, jitter: float,
                 rng: np.random.Generator, offset=None) -> np.ndarray:
    """Particle positions [m] inside ``shape``, ``ppc`` candidates per grid cell.

    If ``ppc = k^dim`` the candidates form a regular k^dim sub-lattice at the
    sub-cell centres (displaced by ``jitter`` times the sub-spacing, uniformly
    at random) and shifted by ``offset`` [cells] per axis; otherwise they
    are uniform random points in each cell. Each particle then stands for a
    volume ``dx^dim / ppc``.
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
