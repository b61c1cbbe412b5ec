"""The colour key drawn in the particle view, beside the domain: a labelled
swatch per body, or a colour bar of the field with its range and unit.

Each coloured entity has its key as a child (``/particles/key``,
``/channels/<field>/key``), so the key shows and hides with it; in 2D it
inherits the entity's y-up transform. Keys stand in columns to the right of
the domain (:func:`column_x`), one per coloured entity, so a channel shown
over the particles does not hide the particles' key. Positions are in the
scene's coordinates [m].
"""

from __future__ import annotations

import numpy as np
import rerun as rr
from numpy.typing import ArrayLike

from .colours import VIRIDIS_LUT, UNITS, body_colour

STEPS = 24  # colour bar: boxes (2D) or points (3D) from bottom to top
GAP, WIDTH = 0.06, 0.16  # a key column: gap before it and its width, in domain lengths


def column_x(domain, column: int) -> float:
    """Left edge [m] of key column ``column`` (0: the particles')."""
    L = float(max(domain))
    return float(domain[0]) + L * (GAP + column * (GAP + WIDTH))


def extent(domain, columns: int) -> float:
    """Right edge [m] of ``columns`` key columns (the 2D view's bounds)."""
    return column_x(domain, columns - 1) + float(max(domain)) * WIDTH if columns else float(domain[0])


def _points(dim: int, **kw):
    return (rr.Points2D if dim == 2 else rr.Points3D)(**kw)


def _at(dim: int, x: float, y: ArrayLike) -> np.ndarray:
    """Points at ``x`` and heights ``y``, on the back face z = 0 in 3D."""
    y = np.asarray(y, float)
    xy = np.stack([np.full_like(y, x), y], axis=1)
    return xy if dim == 2 else np.concatenate([xy, np.zeros((len(y), 1))], axis=1)


def log_bodies(rec: rr.RecordingStream, path: str, names: list[str], dim: int, domain, column: int = 0) -> None:
    """A swatch per body, labelled with its name, from the top down (static)."""
    L, top = float(max(domain)), float(domain[1])
    row = min(0.07 * L, 0.9 * top / max(len(names), 1))
    x = column_x(domain, column) + 0.03 * L
    y = top - row * (np.arange(len(names)) + 0.5)
    rgb = np.array([body_colour(i)[0] for i in range(len(names))], np.uint8).reshape(-1, 3)
    rec.log(path, _points(dim, positions=_at(dim, x, y), colors=rgb, radii=0.02 * L,
                          labels=[f"{n} ({body_colour(i)[1]})" for i, n in enumerate(names)],
                          show_labels=True), static=True)


def log_bar(rec: rr.RecordingStream, path: str, field: str, low: float, high: float, dim: int, domain,
            column: int = 0) -> None:
    """A colour bar of ``field`` from ``low`` (bottom) to ``high`` (top),
    over the domain's middle 60 % (thick line segments), with the two ends and the field (and
    unit) written beside it (static)."""
    L, H = float(max(domain)), float(domain[1])
    x = column_x(domain, column)
    y0, y1 = 0.2 * H, 0.8 * H
    level = (np.arange(STEPS) + 0.5) / STEPS
    colours = VIRIDIS_LUT[np.minimum((level * len(VIRIDIS_LUT)).astype(int), len(VIRIDIS_LUT) - 1)]
    h = (y1 - y0) / STEPS
    ys = y0 + h * (np.arange(STEPS) + 0.5)
    strips = [_at(dim, x + 0.02 * L, [y - 0.5 * h, y + 0.5 * h]) for y in ys]  # thick segments: a solid bar
    rec.log(f"{path}/bar", (rr.LineStrips2D if dim == 2 else rr.LineStrips3D)(
        strips, colors=colours, radii=0.02 * L), static=True)
    unit = UNITS.get(field, "")
    ends = [f"{low:.3g}", f"{high:.3g}{unit and ' ' + unit}", f"{field}{unit and f' [{unit}]'}"]
    # a label is drawn at its point in the point's colour: small dark points right of the bar
    rec.log(f"{path}/labels", _points(dim, positions=_at(dim, x + 0.09 * L, [y0, y1, y1 + 0.08 * H]),
                                      colors=[(60, 60, 60)] * 3, radii=0.002 * L, labels=ends, show_labels=True),
            static=True)
