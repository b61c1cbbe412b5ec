"""The Rerun sink: two ``.rrd`` files per run, one recording.

``recording.rrd`` holds the physics and how to reproduce it: two identical
runs give recordings that ``rerun rrd compare --unordered`` finds equal (rows
are sent as chunks of their own, so chunking does not depend on timing).
``recording.timings.rrd`` (:func:`pipelines.recording.sinks.timings_path`) holds the wall-clock side:
step and update times, start time, host and command line. Both carry the same
recording id, so the viewer merges them when opened together.

Particle frames are written by a thread of their own (colours, conversion
and serialisation overlap the next steps, whose Warp launches release the
GIL): ``particles`` hands the arrays over and returns, at most
``FRAMES_IN_FLIGHT`` frames wait, and ``close`` writes every one before the
files are finalised.

Layout of the recording (timelines ``step`` and ``sim_time``):

  /particles          Points2D/3D positions per logged frame, with the
                      component ``dJ`` (per-particle |det F^sn - 1|) and,
                      with plastic materials, their fields (``J_P``,
                      ``plastic_strain``, ...: mpm.materials.Plastic.fields);
                      colours by ``meta.color`` (the body, or a field on
                      the viridis map over a range fixed for the run:
                      ``COLOR_RANGES``, ``log.color_range``, or for
                      ``speed`` (|v| [m/s], recorded then) a bound found
                      before the run); once
                      particles were removed at open walls, ``index`` (their
                      numbers) with the ones left; radii and ``body_index`` (body
                      per particle) are static
  /channels/<field>   with log.channels, per field the particles again (the
                      positions of each frame), coloured by that field on
                      the viridis map over its fixed range (as /particles
                      would be by log.color=<field>); hidden in the
                      blueprint: the user shows one in the viewer
  /legend             what the colours mean: map, field and range (static)
  /domain             the domain box and the inner wall faces (static)
  /colliders/<name>   each collider's surface (3D) or outline (2D)
  /regions/<name>     each kinematic region's selection outlined where its
                      particles are, at every particle frame (LineStrips;
                      solid magenta while it acts, faint before and after:
                      pipelines.recording.regions); static for a region
                      that neither moves nor lets go
  /scalars/<name>     one Scalars series per physics scalar, sent in batches
                      with ``send_columns``, named with its unit (SeriesLines)
  /events             TextLog lines with machine-readable values beside them
  /__properties/...   resolved config, overrides, provenance, ``view`` (up axis)
Up is +y (:mod:`pipelines.recording.layout`: view coordinates in 3D, a
mirroring transform on the spatial entities in 2D); the blueprint opens on
the ``sim_time`` timeline.
and of the timings file:
  /timings/<name>     step_time_ms every step, update_ms on update steps
  /__properties/run   started, host, command
"""

from __future__ import annotations

import queue
import threading
import uuid
from collections import defaultdict
from pathlib import Path

import numpy as np
import rerun as rr

from . import layout, regions, surfaces
from .sinks import RunMeta, Sink, timings_path

APP_ID = "aulmpm"
VIRIDIS = np.array([(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)], float)
GREY = (150, 150, 150)  # a particle without a value (the field of another body's material)
PALETTE = np.array([
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
], dtype=np.uint8)


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


# the colour map's range of each field, fixed for the run (other fields: DEFAULT_RANGE)
COLOR_RANGES = {
    "dJ": (0.0, 0.1),  # |det F^sn - 1|: a tenth of the volume
    "plastic_strain": (0.0, 0.5),
    "J_P": (0.8, 1.2), "density_ratio": (0.8, 1.2),
    "hardening": (0.0, 1.0),
}
DEFAULT_RANGE = (0.0, 1.0)
UNITS = {"speed": "m/s"}  # of the coloured fields that have one (the others are ratios)


def color_range(field: str) -> tuple[float, float]:
    """The fixed (low, high) of ``field`` on the colour map."""
    return COLOR_RANGES.get(field, DEFAULT_RANGE)


def colormap(values: np.ndarray, top: float, bottom: float = 0.0) -> np.ndarray:
    """Packed viridis colours of ``values`` from ``bottom`` to ``top``
    (clamped; grey where not finite)."""
    finite = np.isfinite(values)
    span = (top - bottom) or 1.0
    level = (np.where(finite, values, bottom) - bottom) * ((COLOR_LEVELS - 1) / span)
    rgb = VIRIDIS_LUT[np.clip(level, 0.0, COLOR_LEVELS - 1).astype(np.intp)]
    rgb[~finite] = GREY_PACKED
    return rgb


def _stream(recording_id: str, path: Path) -> rr.RecordingStream:
    # one chunk per logged row: the file's chunks then depend on the data only
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id,
                             batcher_config=rr.ChunkBatcherConfig(flush_num_rows=1))
    rec.save(str(path))
    rec.__enter__()
    return rec


FRAMES_IN_FLIGHT = 2  # particle frames handed to the writer thread and not yet written
CHANNEL_DRAW_ORDER = 31.0  # 2D: the channels over the particles (Rerun's points: 30)


class RerunSink(Sink):
    def __init__(self, path: Path, flush_every: int = 500, threaded: bool = True):
        self.path = Path(path)
        self.flush_every = flush_every
        recording_id = str(uuid.uuid4())
        self.rec = _stream(recording_id, self.path)
        self.clock = _stream(recording_id, timings_path(self.path))
        self._open = True
        self._rows = 0
        self._buffer: dict[str, tuple[list, list, list]] = defaultdict(lambda: ([], [], []))
        self._timings: dict[str, tuple[list, list, list]] = defaultdict(lambda: ([], [], []))
        self._points = None
        self._moving = []
        self._regions = []  # pipelines.recording.regions.Region, drawn with each particle frame
        self._color = "body"
        self._range = DEFAULT_RANGE  # the colour map's (low, high), fixed for the run
        self._source = ""  # where the range comes from
        self._labelled: set[tuple] = set()  # scalar series named (with their unit) so far
        self._dim = 2
        self._body = None
        self._channels: dict = {}  # log.channels: field -> ((low, high), source)
        self._layout: tuple | None = None  # the blueprint's arguments (start), re-sent with the extents at close
        self._extents: dict[str, tuple[float, float]] = {}  # scalar name -> (min, max) over the run
        self._frames: queue.Queue | None = None  # to the writer thread (threaded)
        self._writer: threading.Thread | None = None
        self._failure: BaseException | None = None  # raised by the writer, re-raised here
        if threaded:
            self._frames = queue.Queue(maxsize=FRAMES_IN_FLIGHT)
            self._writer = threading.Thread(target=self._write_frames, name="rerun-frames", daemon=True)
            self._writer.start()

    # ---------------------------------------------------------------- static
    def start(self, meta: RunMeta) -> None:
        rec = self.rec
        rec.send_recording_name(meta.name)
        for name, values in meta.properties.items():
            rec.send_property(name, rr.AnyValues(**values))
        self.clock.send_recording_name(meta.name)
        for name, values in meta.run_properties.items():
            self.clock.send_property(name, rr.AnyValues(**values))
        self._points = rr.Points2D if meta.dim == 2 else rr.Points3D
        self._dim = meta.dim
        self._body = np.asarray(meta.particle_body)
        self._color, self._names = meta.color, meta.body_names
        given, self._source = meta.color_range
        self._range = tuple(given) if given is not None else color_range(self._color)
        self._source = self._source or "fixed for the field"
        self._channels = {}  # field -> ((low, high), where the range comes from)
        for name, (given, source) in (meta.channels or {}).items():
            self._channels[name] = ((tuple(given), source) if given is not None
                                    else (color_range(name), "fixed for the field"))
        layout.view_coordinates(rec, meta.dim, channels=bool(self._channels))
        rec.send_property("bodies", rr.AnyValues(names=list(meta.body_names)))
        rec.log("particles", self._points.from_fields(radii=meta.particle_radius),
                rr.AnyValues(body_index=self._body.astype(np.int32)), static=True)
        for name in self._channels:  # drawn over /particles in 2D when shown
            rec.log(f"channels/{name}", self._points.from_fields(
                radii=meta.particle_radius, **({"draw_order": CHANNEL_DRAW_ORDER} if meta.dim == 2 else {})),
                static=True)
        self._regions = regions.of_yaml(((meta.properties or {}).get("config") or {}).get("yaml") or "", meta.dim)
        self._legend()
        self._log_domain(meta)
        self._log_colliders(meta)
        for reg in self._regions:  # a region that never moves nor lets go: static
            if reg.still:
                self._log_region(reg, 0.0, static=True)
        self._layout = (meta.dim, meta.domain, meta.wall_cells * meta.dx, meta.scalar_groups, list(self._channels))
        rec.send_blueprint(layout.blueprint(*self._layout))

    def _log_colliders(self, meta: RunMeta) -> None:
        """Each collider's surface (3D) or outline (2D) at its initial place,
        static; a moving one is translated at every logged particle step."""
        self._moving = []
        for i, c in enumerate(meta.colliders):
            path = f"colliders/{c.name or c.type + str(i)}"
            color = (150, 150, 160)
            if meta.dim == 3:
                v, f = surfaces.surface_3d(c, np.zeros(3), meta.domain)
                self.rec.log(path, rr.Mesh3D(vertex_positions=v, triangle_indices=f,
                                             albedo_factor=(150, 150, 160, 110)), static=True)
            else:
                self.rec.log(path, rr.LineStrips2D(surfaces.outline_2d(c, np.zeros(2), meta.domain),
                                                   colors=[color]), static=True)
            if c.velocity is not None:
                self._moving.append((path, c))

    def _log_region(self, reg, t: float, static: bool = False) -> None:
        """A kinematic region's outline where its particles are at ``t`` [s]."""
        strips = [line.astype(np.float32) for line in reg.outline(t, len(reg.center))]
        color = regions.EDGE_RGBA if reg.active(t) else regions.EDGE_IDLE_RGBA
        kind = rr.LineStrips3D if len(reg.center) == 3 else rr.LineStrips2D
        self.rec.log(f"regions/{reg.name}", kind(strips, colors=[color]), static=static)

    def _log_domain(self, meta: RunMeta) -> None:
        L = np.asarray(meta.domain)
        w = meta.wall_cells * meta.dx
        if meta.dim == 2:
            self.rec.log("domain", rr.Boxes2D(mins=[[0.0, 0.0], [w, w]], sizes=[L, L - 2 * w],
                                              colors=[(200, 200, 200), (120, 120, 120)]), static=True)
        else:
            self.rec.log("domain", rr.Boxes3D(centers=[L / 2, L / 2], half_sizes=[L / 2, L / 2 - w],
                                              colors=[(200, 200, 200), (120, 120, 120)],
                                              fill_mode=rr.components.FillMode.MajorWireframe), static=True)

    def _colors(self, values: np.ndarray | None, index: np.ndarray | None) -> np.ndarray:
        """Packed colour per particle: the body palette, or ``values`` on the
        colour map (256 levels) over the run's fixed range (grey where not
        finite)."""
        if self._color == "body" or values is None:
            body = self._body if index is None else self._body[index]
            return PALETTE_PACKED[body % len(PALETTE)]
        return colormap(values, self._range[1], self._range[0])

    def _legend(self) -> None:
        """The colour key (static): each body's colour, or the field, its map and range."""
        if self._color == "body":
            text = "**Particle colour: the body**\n\n" + "\n".join(
                f"- {n}: rgb{tuple(int(c) for c in PALETTE[i % len(PALETTE)])}" for i, n in enumerate(self._names))
        else:
            (lo, hi), unit = self._range, UNITS.get(self._color, "")
            text = (f"**Particle colour: {self._color}{unit and f' [{unit}]'}** on the viridis map, fixed for "
                    f"the run: {lo:.3g} (dark purple) to {hi:.3g} (yellow){unit and ' ' + unit}, clamped "
                    f"({self._source}); grey: no value (another material)."
                    "\n\nEvery per-particle field is in the recording (select a particle to read it).")
        if self._regions:
            text += "\n\n**Kinematic regions** (magenta outlines, faint while not acting): " + ", ".join(
                f"{r.name} ({r.start:g} s to {r.end:g} s)" if np.isfinite(r.end) else f"{r.name} (from {r.start:g} s)"
                for r in self._regions)
        if self._channels:
            text += ("\n\n**Channels** (hidden: show one in the blueprint panel, eye icon, and hide /particles "
                     "in 3D), each field on the viridis map over a range fixed for the run:\n" + "\n".join(
                         f"- /channels/{n}: {n}{UNITS.get(n) and f' [{UNITS[n]}]' or ''} {lo:.3g} to {hi:.3g} "
                         f"({source})" for n, ((lo, hi), source) in self._channels.items()))
            self.rec.send_property("channels", rr.AnyValues(
                names=list(self._channels), low=[r[0] for r, _ in self._channels.values()],
                high=[r[1] for r, _ in self._channels.values()], source=[s for _, s in self._channels.values()]))
        self.rec.log("legend", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
        self.rec.send_property("color", rr.AnyValues(field=self._color, colormap="viridis" if self._color != "body"
                                                     else "palette", low=self._range[0], high=self._range[1],
                                                     unit=UNITS.get(self._color, ""), source=self._source))

    # ---------------------------------------------------------------- per step
    def particles(self, step, t, x, dJ, fields=None, index=None):
        """One frame; the arrays must not change afterwards (the writer
        thread reads them later)."""
        if self._frames is None:
            self._write_particles(step, t, x, dJ, fields, index)
            return
        self._check_writer()
        self._frames.put((step, t, x, dJ, fields, index))

    def _write_frames(self) -> None:
        """The writer thread: frames in order until None."""
        while (frame := self._frames.get()) is not None:
            if self._failure is None:
                try:
                    self._write_particles(*frame)
                except BaseException as e:  # noqa: BLE001 - handed to the main thread
                    self._failure = e

    def _check_writer(self) -> None:
        if self._failure is not None:
            failure, self._failure = self._failure, None
            raise RuntimeError(f"writing particle frames failed: {failure!r}") from failure

    def _drain(self) -> None:
        """Wait until every frame handed over is written; stop the writer."""
        if self._writer is not None and self._writer.is_alive():
            self._frames.put(None)
            self._writer.join()
        self._writer = None

    def _write_particles(self, step, t, x, dJ, fields=None, index=None):
        self.rec.set_time("step", sequence=step)
        self.rec.set_time("sim_time", duration=t)
        for path, c in self._moving:
            shift = np.asarray(c.offset(t), float)
            if len(shift) == 3:
                self.rec.log(path, rr.Transform3D(translation=shift))
            else:
                self.rec.log(path, rr.Transform3D(translation=[*shift, 0.0]))
        for reg in self._regions:
            if not reg.still:
                self._log_region(reg, t)
        values = dict(fields or {})
        if dJ is not None:
            values["dJ"] = dJ
        colors = self._colors(values.get(self._color), index)
        for name, ((lo, hi), _) in self._channels.items():
            if values.get(name) is not None:
                self.rec.log(f"channels/{name}", self._points.from_fields(
                    positions=x, colors=colormap(np.asarray(values[name]), hi, lo)))
        if index is not None:
            values["index"] = index.astype(np.int32)
        parts = [self._points.from_fields(positions=x, colors=colors)]
        if values:
            parts.append(rr.AnyValues(**values))
        self.rec.log("particles", *parts)

    @staticmethod
    def _append(buffer: dict, step: int, t: float, values: dict) -> None:
        for name, value in values.items():
            steps, times, vals = buffer[name]
            steps.append(step)
            times.append(t)
            vals.append(value)

    def scalars(self, step, t, values):
        self._append(self._buffer, step, t, values)
        self._rows += 1
        if self._rows >= self.flush_every:
            self.flush()

    def event(self, step, t, text, level="INFO", **values):
        self.rec.set_time("step", sequence=step)
        self.rec.set_time("sim_time", duration=t)
        parts = [rr.TextLog(text, level=level)]
        if values:
            parts.append(rr.AnyValues(**values))
        self.rec.log("events", *parts)

    def timings(self, step, t, values):
        self._append(self._timings, step, t, values)

    def flush(self):
        for rec, root, buffer in ((self.rec, "scalars", self._buffer), (self.clock, "timings", self._timings)):
            for name, (steps, times, vals) in buffer.items():
                if steps:
                    if (root, name) not in self._labelled:  # the series' name in the viewer, with its unit
                        self._labelled.add((root, name))
                        rec.log(f"{root}/{name}", rr.SeriesLines(names=layout.label(name, self._dim)), static=True)
                    finite = np.asarray(vals, dtype=np.float64)
                    finite = finite[np.isfinite(finite)]
                    if root == "scalars" and len(finite):  # the series' extent, for the plots' final y ranges
                        lo, hi = self._extents.get(name, (np.inf, -np.inf))
                        self._extents[name] = (min(lo, float(finite.min())), max(hi, float(finite.max())))
                    rec.send_columns(
                        f"{root}/{name}",
                        indexes=[rr.TimeColumn("step", sequence=steps),
                                 rr.TimeColumn("sim_time", duration=times)],
                        columns=rr.Scalars.columns(scalars=np.asarray(vals, dtype=np.float64)))
            buffer.clear()
        self._rows = 0

    def close(self):
        if not self._open:
            return
        self._open = False
        try:
            self._drain()
            self.flush()
            self._check_writer()
            if self._layout is not None and self._extents:  # the legends' room above the whole run's data
                self.rec.send_blueprint(layout.blueprint(*self._layout, extents=self._extents))
        finally:
            try:  # leaving the streams (last entered first) flushes and finalises the files
                self.clock.__exit__(None, None, None)
            finally:
                self.rec.__exit__(None, None, None)
