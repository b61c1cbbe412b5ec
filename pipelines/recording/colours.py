"""Particle colours: the body palette, and a per-particle field on the
viridis map over one range per field taken from the recorded run.

A field's range is the run's own (:func:`run_range` of the finite values of
every logged frame) unless the config fixes it (``log.color_range``), so no
particle drawn is clipped. The range is known only once the run has ended:
:class:`FrameValues` keeps each frame's values of the coloured fields in a
temporary file until then. The viewer (:mod:`pipelines.recording.rerun_sink`)
and the frames (:mod:`pipelines.recording.display`) use the same range, read
from the recording's ``color`` and ``channels`` properties.
"""

from __future__ import annotations

import tempfile

import numpy as np

VIRIDIS = np.array([(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)], float)
GREY = (150, 150, 150)  # a particle without a value (the field of another body's material)
PALETTE = np.array([
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
], dtype=np.uint8)
PALETTE_NAMES = ("blue", "orange", "green", "red", "purple", "brown", "pink", "grey", "olive", "cyan")


def packed(rgb) -> np.ndarray:
    """RGB rows (uint8) as Rerun's packed 0xRRGGBBAA colours, opaque."""
    rgb = np.asarray(rgb, np.uint32).reshape(-1, 3)
    return (rgb[:, 0] << 24) | (rgb[:, 1] << 16) | (rgb[:, 2] << 8) | np.uint32(255)


# the colour map in 256 steps (a particle's colour is one lookup), the palette and grey, packed
COLOR_LEVELS = 256
VIRIDIS_LUT = packed(np.stack([np.interp(np.linspace(0.0, 1.0, COLOR_LEVELS), np.linspace(0.0, 1.0, len(VIRIDIS)),
                                         VIRIDIS[:, c]) for c in range(3)], axis=1).round())
PALETTE_PACKED = packed(PALETTE)
GREY_PACKED = packed(GREY)[0]

UNITS = {"speed": "m/s"}  # of the coloured fields that have one (the others are ratios)
# magnitudes: their range starts at 0 (|v|, |det F^sn - 1|, accumulated plastic strain, hardening)
FROM_ZERO = frozenset({"speed", "dJ", "plastic_strain", "hardening"})


def body_colour(i: int) -> tuple[tuple[int, int, int], str]:
    """Body ``i``'s colour (RGB) and its name."""
    r, g, b = (int(c) for c in PALETTE[i % len(PALETTE)])
    return (r, g, b), PALETTE_NAMES[i % len(PALETTE)]


def colormap(values: np.ndarray, top: float, bottom: float = 0.0) -> np.ndarray:
    """Packed viridis colours of ``values`` from ``bottom`` to ``top``
    (clamped; grey where not finite)."""
    finite = np.isfinite(values)
    span = (top - bottom) or 1.0
    level = (np.where(finite, values, bottom) - bottom) * ((COLOR_LEVELS - 1) / span)
    rgb = VIRIDIS_LUT[np.clip(level, 0.0, COLOR_LEVELS - 1).astype(np.intp)]
    rgb[~finite] = GREY_PACKED
    return rgb


def run_range(field: str, low: float, high: float) -> tuple[float, float]:
    """The colour range of ``field`` whose finite values over the run lie in
    [``low``, ``high``] (``low > high``: none): that interval, from 0 for a
    magnitude (:data:`FROM_ZERO`); a constant value sits in the middle of a
    range as wide as it (1 wide at 0); no value at all: (0, 1)."""
    if low > high:
        return 0.0, 1.0
    if field in FROM_ZERO:
        low = min(low, 0.0)
    if high > low:
        return float(low), float(high)
    half = 0.5 * (abs(low) or 1.0)
    return (0.0, 2.0 * half) if field in FROM_ZERO else (float(low) - half, float(high) + half)


def values_range(field: str, frames) -> tuple[float, float]:
    """:func:`run_range` of the finite values in ``frames`` (arrays or None)."""
    low, high = np.inf, -np.inf
    for v in frames:
        if v is not None:
            v = np.asarray(v)[np.isfinite(v)]
            if v.size:
                low, high = min(low, float(v.min())), max(high, float(v.max()))
    return run_range(field, low, high)


def describe(field: str, low: float, high: float) -> str:
    """``speed 0 to 4.92 m/s``: a field, its range and unit in words."""
    unit = UNITS.get(field, "")
    return f"{field} {low:.3g} to {high:.3g}{unit and ' ' + unit}"


class FrameValues:
    """Every logged frame's values of the fields coloured with the run's
    range, kept in a temporary file (float32) until the run has ended, with
    each field's extent so far. Frames may hold different numbers of
    particles (particles removed at open walls)."""

    def __init__(self, fields):
        self.fields = list(fields)
        self._file = tempfile.TemporaryFile()
        self._frames: list[tuple[int, float, int]] = []  # (step, time [s], particles)
        self._extent = {f: (np.inf, -np.inf) for f in self.fields}

    def add(self, step: int, t: float, n: int, values: dict) -> None:
        """One frame of ``n`` particles: ``values[field]`` per particle (a missing field: NaN)."""
        for f in self.fields:
            v = values.get(f)
            v = np.full(n, np.nan, np.float32) if v is None else np.ascontiguousarray(v, np.float32)
            self._file.write(v.tobytes())
            finite = v[np.isfinite(v)]
            if finite.size:
                lo, hi = self._extent[f]
                self._extent[f] = (min(lo, float(finite.min())), max(hi, float(finite.max())))
        self._frames.append((step, t, n))

    def range(self, field: str) -> tuple[float, float]:
        """:func:`run_range` of ``field`` over the frames added so far."""
        return run_range(field, *self._extent[field])

    def __iter__(self):
        """(step, time [s], {field: values}) per frame, in the order added."""
        self._file.seek(0)
        for step, t, n in self._frames:
            yield step, t, {f: np.frombuffer(self._file.read(4 * n), np.float32) for f in self.fields}

    def close(self) -> None:
        self._file.close()
