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
                      colours by ``meta.color`` (a field on a colour map from
                      0 to the largest value so far, or the body); once
                      particles were removed at open walls, ``index`` (their
                      numbers) with the ones left; radii and ``body_index`` (body
                      per particle) are static
  /legend             what the colours mean (a text updated with the range)
  /domain             the domain box and the inner wall faces (static)
  /scalars/<name>     one Scalars series per physics/timing scalar, sent in
                      batches with ``send_columns``
  /events             TextLog lines with machine-readable values beside them
  /__properties/...   resolved config, overrides, provenance
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
import rerun.blueprint as rrb

from . import surfaces
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


def colormap(values: np.ndarray, top: float) -> np.ndarray:
    """Packed viridis colours of ``values`` from 0 to ``top`` (clamped; grey
    where not finite)."""
    finite = np.isfinite(values)
    level = np.where(finite, values, 0.0) * ((COLOR_LEVELS - 1) / (top or 1.0))
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
        self._color = "body"
        self._range = 0.0  # the colour map's upper end: the largest value logged so far
        self._body = None
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
        self._body = np.asarray(meta.particle_body)
        self._color, self._names = meta.color, meta.body_names
        rec.log("particles", self._points.from_fields(radii=meta.particle_radius),
                rr.AnyValues(body_index=self._body.astype(np.int32)), static=True)
        if self._color == "body":
            self._legend()
        self._log_domain(meta)
        self._log_colliders(meta)
        rec.send_blueprint(self._blueprint(meta))

    def _log_colliders(self, meta: RunMeta) -> None:
        """Each collider's surface (3D) or outline (2D) at its initial place,
        static; a moving one is translated at every logged particle step."""
        self._moving = []
        for i, c in enumerate(meta.colliders):
            path = f"colliders/{c.name or c.kind + str(i)}"
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

    def _log_domain(self, meta: RunMeta) -> None:
        L = np.asarray(meta.domain)
        w = meta.wall_cells * meta.dx
        if meta.dim == 2:
            self.rec.log("domain", rr.Boxes2D(mins=[[0.0, 0.0], [w, w]], sizes=[L, L - 2 * w],
                                              colors=[(200, 200, 200), (120, 120, 120)],
                                              labels=["domain", "walls"]), static=True)
        else:
            self.rec.log("domain", rr.Boxes3D(centers=[L / 2, L / 2], half_sizes=[L / 2, L / 2 - w],
                                              colors=[(200, 200, 200), (120, 120, 120)],
                                              labels=["domain", "walls"]), static=True)

    def _colors(self, values: np.ndarray | None, index: np.ndarray | None) -> np.ndarray:
        """Packed colour per particle: the body palette, or ``values`` on the
        colour map (256 levels) from 0 to the largest value so far (grey where
        not finite)."""
        if self._color == "body" or values is None:
            body = self._body if index is None else self._body[index]
            return PALETTE_PACKED[body % len(PALETTE)]
        largest = float(np.max(values, where=np.isfinite(values), initial=0.0))
        if largest > self._range:
            self._range = largest
            self._legend()
        return colormap(values, self._range)

    def _legend(self) -> None:
        if self._color == "body":
            text = "Particle colour: the body (" + ", ".join(
                f"{n}: rgb{tuple(int(c) for c in PALETTE[i % len(PALETTE)])}" for i, n in enumerate(self._names)) + ")."
        else:
            text = (f"Particle colour: **{self._color}** on the viridis map, from 0 (dark purple) to "
                    f"**{self._range:.3g}** (yellow), the largest value logged so far; grey: no value "
                    "(another material).")
        self.rec.log("legend", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN))

    def _blueprint(self, meta: RunMeta):
        view = rrb.Spatial2DView if meta.dim == 2 else rrb.Spatial3DView
        series = [rrb.TimeSeriesView(name=name, origin="/",
                                     contents=[s if s.startswith("/") else f"/scalars/{s}" for s in names])
                  for name, names in meta.scalar_groups.items()]
        return rrb.Blueprint(
            rrb.Horizontal(
                view(name="particles", origin="/", contents=["/particles", "/domain", "/colliders/**"]),
                rrb.Vertical(rrb.TextDocumentView(name="colour", origin="/legend"), *series,
                             rrb.TextLogView(name="events", origin="/events"),
                             row_shares=[1] + [2] * len(series) + [2]),
                column_shares=[3, 2],
            ),
            collapse_panels=False,
        )

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
        values = dict(fields or {})
        if dJ is not None:
            values["dJ"] = dJ
        colors = self._colors(values.get(self._color), index)
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
        finally:
            try:  # leaving the streams (last entered first) flushes and finalises the files
                self.clock.__exit__(None, None, None)
            finally:
                self.rec.__exit__(None, None, None)
