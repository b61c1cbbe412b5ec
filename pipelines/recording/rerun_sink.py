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
                      colours by ``meta.color``: the body, or a field on
                      the viridis map over its range (``log.color_range``,
                      else the run's own: a colour row per frame at its
                      step, written when the run ends;
                      :mod:`pipelines.recording.colours`); once
                      particles were removed at open walls, ``index`` (their
                      numbers) with the ones left; radii and ``body_index`` (body
                      per particle) are static
  /particles/key      the colour key beside the domain: a labelled swatch
                      per body, or the field's colour bar with its range
                      (:mod:`pipelines.recording.colour_key`; static)
  /channels/<field>   with log.channels, per field the particles again (the
                      positions of each frame), coloured by that field as
                      /particles would be by log.color=<field>, its key in
                      /channels/<field>/key; hidden in the
                      blueprint: the user shows one in the viewer
  /legend             what the colours mean in words: map, field, range (static)
  /domain             the domain box and the inner wall faces (static)
  /colliders/<name>   each collider's surface (3D) or outline (2D)
  /rigid/<name>       each rigid body's shape at rest (static), placed at
                      its pose at every particle frame (Transform3D:
                      translation and mat3x3, as a turning collider)
  /regions/<name>     each kinematic region's selection outlined where its
                      particles are, at every particle frame (LineStrips;
                      solid magenta while it acts, faint before and after:
                      pipelines.recording.regions); static for a region
                      that neither moves nor lets go
  /scalars/<name>     one Scalars series per physics scalar, sent in batches
                      with ``send_columns``, named with its unit (SeriesLines)
  /events             TextLog lines with machine-readable values beside them
  /__properties/...   resolved config, overrides, provenance, ``view`` (up axis),
                      ``color`` and ``channels`` (each coloured field's range and unit)
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
from typing import Any

import numpy as np
import rerun as rr

from . import colour_key, layout, regions, surfaces
from .colours import PALETTE, PALETTE_PACKED, UNITS, FrameValues, body_colour, colormap, describe
from .sinks import RunMeta, Sink, timings_path

APP_ID = "aulmpm"


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
    _points: type[rr.Points2D] | type[rr.Points3D]  # these: set by start()
    _body: np.ndarray  # body per particle
    _names: list[str]
    _domain: tuple

    def __init__(self, path: Path, flush_every: int = 500, threaded: bool = True, recording_id: str | None = None):
        """``recording_id``: another file's, to continue its recording (the viewer merges the two); None: new."""
        self.path = Path(path)
        self.flush_every = flush_every
        self.recording_id = recording_id = recording_id or str(uuid.uuid4())
        self.rec = _stream(recording_id, self.path)
        self.clock = _stream(recording_id, timings_path(self.path))
        self._open = True
        self._rows = 0
        self._buffer: dict[str, tuple[list, list, list]] = defaultdict(lambda: ([], [], []))
        self._timings: dict[str, tuple[list, list, list]] = defaultdict(lambda: ([], [], []))
        self._moving = []
        self._rigid: list[str] = []  # the rigid bodies' entities (RunMeta.rigid_bodies)
        self._regions = []  # pipelines.recording.regions.Region, drawn with each particle frame
        self._color = "body"
        self._ranges: dict = {}  # coloured field -> ((low, high), where it comes from); None: the run's, at close
        self._values: FrameValues | None = None  # the frames' values of the fields coloured at close
        self._labelled: set[tuple] = set()  # scalar series named (with their unit) so far
        self._dim = 2
        self._channels: list[str] = []  # log.channels: a /channels/<field> entity each
        self._layout: tuple | None = None  # the blueprint's arguments (start), re-sent with the extents at close
        self._extents: dict[str, tuple[float, float]] = {}  # scalar name -> (min, max) over the run
        self._same: dict[str, bool] = {}  # layout.SAME_AS series -> equal to its twin at every step so far
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
        self._channels = list(meta.channels or {})
        given = {**(meta.channels or {}), **({self._color: meta.color_range} if self._color != "body" else {})}
        self._ranges = {f: ((tuple(r), source) if r is not None else None) for f, (r, source) in given.items()}
        later = [f for f, r in self._ranges.items() if r is None]
        self._values = FrameValues(later) if later else None
        self._field_notes = dict(meta.field_notes or {})
        self._rigid = [f"rigid/{name}" for name, _ in meta.rigid_bodies]
        layout.view_coordinates(rec, meta.dim, channels=bool(self._channels), rigid=bool(self._rigid))
        rec.send_property("bodies", rr.AnyValues(names=list(meta.body_names)))
        rec.log("particles", self._points.from_fields(radii=meta.particle_radius),
                rr.AnyValues(body_index=self._body.astype(np.int32)), static=True)
        over: dict[str, Any] = {"draw_order": CHANNEL_DRAW_ORDER} if meta.dim == 2 else {}
        for name in self._channels:  # drawn over /particles in 2D when shown
            rec.log(f"channels/{name}", self._points.from_fields(radii=meta.particle_radius, **over), static=True)
        self._domain = tuple(meta.domain)
        self._regions = regions.of_yaml(((meta.properties or {}).get("config") or {}).get("yaml") or "", meta.dim)
        self._legend()
        self._key()
        self._log_domain(meta)
        self._log_colliders(meta)
        for path, (_, shape) in zip(self._rigid, meta.rigid_bodies):
            self._log_shape(path, shape, meta)
        for reg in self._regions:  # a region that never moves nor lets go: static
            if reg.still:
                self._log_region(reg, 0.0, static=True)
        self._layout = (meta.dim, meta.domain, meta.wall_cells * meta.dx, meta.scalar_groups, list(self._channels))
        rec.send_blueprint(layout.blueprint(*self._layout, title=self._title(), rigid=bool(self._rigid)))

    def _log_colliders(self, meta: RunMeta) -> None:
        """Each collider's surface (3D) or outline (2D) at its initial place,
        static; a moving one is translated, and a turning one turned about
        its pivot, at every logged particle step (Transform3D: translation,
        and mat3x3 where it turns)."""
        self._moving = []
        for i, c in enumerate(meta.colliders):
            path = f"colliders/{c.name or c.type + str(i)}"
            self._log_shape(path, c, meta)
            if c.velocity is not None or c.turns:
                self._moving.append((path, c, meta.dim))

    def _log_shape(self, path: str, c, meta: RunMeta) -> None:
        """A collider's (or rigid body's) surface (3D) or outline (2D) at its initial place, static."""
        color = (150, 150, 160)
        if meta.dim == 3:
            v, f = surfaces.surface_3d(c, np.zeros(3), meta.domain)
            self.rec.log(path, rr.Mesh3D(vertex_positions=v, triangle_indices=f,
                                         albedo_factor=(150, 150, 160, 110)), static=True)
        else:
            self.rec.log(path, rr.LineStrips2D(surfaces.outline_2d(c, np.zeros(2), meta.domain),
                                               colors=[color]), static=True)

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

    def _colors(self, field: str, values: np.ndarray | None, index: np.ndarray | None) -> np.ndarray | None:
        """Packed colour per particle: the body palette (``field`` body), or
        ``values`` on the colour map (256 levels) over the field's range
        (grey where not finite); None while that range is the run's, not
        known before it ends."""
        if field == "body" or values is None:
            body = self._body if index is None else self._body[index]
            return PALETTE_PACKED[body % len(PALETTE)]
        if self._ranges.get(field) is None:
            return None
        (lo, hi), _ = self._ranges[field]
        return colormap(np.asarray(values), hi, lo)

    def _range_words(self, field: str) -> str:
        """``speed 0 to 4.92 m/s (the run's range)``, or a note that the range comes at the end."""
        r = self._ranges.get(field)
        return (f"{describe(field, *r[0])} ({r[1]})" if r is not None else
                f"{field} on the run's range (written when the run ends)")

    def _title(self) -> str:
        """The particle view's name: what the colours mean (and which channels wait to be shown)."""
        if self._color != "body":
            title = f"particles: {self._range_words(self._color)}"
        elif len(self._names) > 4:
            title = "particles coloured by body (key on the right)"
        else:
            title = "particles: " + ", ".join(f"{n} {body_colour(i)[1]}" for i, n in enumerate(self._names))
        return title + (f"; hidden channels: {', '.join(self._channels)}" if self._channels else "")

    def _legend(self) -> None:
        """The colour key in words (static): each body's colour, or the field,
        its map and range; with the ``color`` and ``channels`` properties."""
        note = lambda f: f" {self._field_notes[f]}." if f in self._field_notes else ""  # noqa: E731
        if self._color == "body":
            text = "**Particle colour: the body**: " + ", ".join(
                f"{n} {body_colour(i)[1]}" for i, n in enumerate(self._names)) + "."
        else:
            text = (f"**Particle colour: {self._range_words(self._color)}**, viridis from dark purple (low) to "
                    f"yellow (high); grey: no value (another material).{note(self._color)}")
        if self._channels:  # on one line, in sight when the viewer opens
            text += ("\n\n**Channels** (hidden; the eye icon in the blueprint panel shows one, in 3D hide "
                     "/particles), viridis: " + "; ".join(
                         f"{self._range_words(n)} at /channels/{n}" for n in self._channels) + "."
                     + "".join(note(n) for n in self._channels if n != self._color))
        if self._regions:
            text += "\n\n**Kinematic regions** (magenta outlines, faint while not acting): " + ", ".join(
                f"{r.name} ({r.start:g} s to {r.end:g} s)" if np.isfinite(r.end) else f"{r.name} (from {r.start:g} s)"
                for r in self._regions)
        text += "\n\nEvery per-particle field is in the recording: select a particle to read it."
        if self._channels:
            if all(self._ranges[n] is not None for n in self._channels):  # else sent at the end
                self.rec.send_property("channels", rr.AnyValues(
                    names=self._channels, low=[self._ranges[n][0][0] for n in self._channels],
                    high=[self._ranges[n][0][1] for n in self._channels],
                    unit=[UNITS.get(n, "") for n in self._channels],
                    source=[self._ranges[n][1] for n in self._channels]))
        self.rec.log("legend", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
        known = {} if self._ranges.get(self._color) is None else dict(
            zip(("low", "high", "source"), (*self._ranges[self._color][0], self._ranges[self._color][1])))
        self.rec.send_property("color", rr.AnyValues(
            field=self._color, colormap="viridis" if self._color != "body" else "palette",
            unit=UNITS.get(self._color, ""), **known))

    def _key(self) -> None:
        """The colour key in the particle view (:mod:`pipelines.recording.colour_key`),
        once the ranges are known."""
        if self._color == "body":
            colour_key.log_bodies(self.rec, "particles/key", list(self._names), self._dim, self._domain)
        elif (r := self._ranges.get(self._color)) is not None:
            (lo, hi), _ = r
            colour_key.log_bar(self.rec, "particles/key", self._color, lo, hi, self._dim, self._domain)
        for k, name in enumerate(self._channels):
            if (r := self._ranges.get(name)) is not None:
                (lo, hi), _ = r
                colour_key.log_bar(self.rec, f"channels/{name}/key", name, lo, hi, self._dim, self._domain,
                                   column=k + 1)

    def _colour_frames(self) -> None:
        """At the end: the fields coloured on the run's range, a colour row
        per logged frame at its step and time (beside its positions), the
        ranges stated in the legend, properties, key and view title."""
        values = self._values
        assert values is not None  # close() calls this only then
        for field in values.fields:
            self._ranges[field] = (values.range(field), "the run's range")
        paths = [("particles", self._color)] * (self._color in values.fields) + [
            (f"channels/{n}", n) for n in self._channels if n in values.fields]
        for step, t, frame in values:
            self.rec.set_time("step", sequence=step)
            self.rec.set_time("sim_time", duration=t)
            for path, field in paths:
                self.rec.log(path, self._points.from_fields(colors=self._colors(field, frame[field], None)))
        values.close()
        self._values = None
        self._legend()
        self._key()

    # ---------------------------------------------------------------- per step
    def particles(self, step, t, x, dJ, fields=None, index=None, rigid=None):
        """One frame; the arrays must not change afterwards (the writer
        thread reads them later)."""
        if self._frames is None:
            self._write_particles(step, t, x, dJ, fields, index, rigid)
            return
        self._check_writer()
        self._frames.put((step, t, x, dJ, fields, index, rigid))

    def _write_frames(self) -> None:
        """The writer thread: frames in order until None."""
        assert self._frames is not None  # threaded: the writer's queue
        while (frame := self._frames.get()) is not None:
            if self._failure is None:
                try:
                    self._write_particles(*frame)
                except BaseException as e:  # noqa: BLE001 - handed to the main thread
                    self._failure = e
            self._frames.task_done()
        self._frames.task_done()

    def _check_writer(self) -> None:
        if self._failure is not None:
            failure, self._failure = self._failure, None
            raise RuntimeError(f"writing particle frames failed: {failure!r}") from failure

    def _drain(self) -> None:
        """Wait until every frame handed over is written; stop the writer."""
        if self._writer is not None and self._writer.is_alive():
            assert self._frames is not None  # made with the writer
            self._frames.put(None)
            self._writer.join()
        self._writer = None

    def _write_particles(self, step, t, x, dJ, fields=None, index=None, rigid: list | None = None):
        self.rec.set_time("step", sequence=step)
        self.rec.set_time("sim_time", duration=t)
        for path, (R, b) in zip(self._rigid, rigid if rigid is not None else []):  # (rotation, translation)
            self.rec.log(path, rr.Transform3D(translation=np.asarray(b, float), mat3x3=np.asarray(R, float)))
        for path, c, dim in self._moving:
            if not c.turns:
                self.rec.log(path, rr.Transform3D(translation=[*np.asarray(c.offset(t), float), 0.0][:3]))
                continue
            R, shift = c.pose(t, dim)
            R3 = np.eye(3)
            R3[:dim, :dim] = R
            self.rec.log(path, rr.Transform3D(translation=[*shift, 0.0][:3], mat3x3=R3))
        for reg in self._regions:
            if not reg.still:
                self._log_region(reg, t)
        values = dict(fields or {})
        if dJ is not None:
            values["dJ"] = dJ
        if self._values is not None:  # coloured at the end, on the run's range
            self._values.add(step, t, len(x), values)
        for name in self._channels:
            if values.get(name) is not None:
                self.rec.log(f"channels/{name}", self._points.from_fields(
                    positions=x, colors=self._colors(name, values[name], index)))
        colors = self._colors(self._color, values.get(self._color), index)
        if index is not None:
            values["index"] = index.astype(np.int32)
        parts: list[rr.AsComponents] = [self._points.from_fields(positions=x, colors=colors)]
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
        parts: list[rr.AsComponents] = [rr.TextLog(text, level=level)]
        if values:
            parts.append(rr.AnyValues(**values))
        self.rec.log("events", *parts)

    def timings(self, step, t, values):
        self._append(self._timings, step, t, values)

    def flush(self):
        for name, twin in layout.SAME_AS.items():  # a series equal to its twin so far is left out of the plots
            if name in self._buffer and twin in self._buffer:
                a, b = (np.asarray(self._buffer[n][2], np.float64) for n in (name, twin))
                self._same[name] = self._same.get(name, True) and np.array_equal(a, b, equal_nan=True)
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

    def sync(self) -> dict[str, int]:
        """The frames in flight written, the scalars sent, both streams flushed to their files; their sizes."""
        if self._frames is not None and self._writer is not None and self._writer.is_alive():
            self._frames.join()
        self._check_writer()
        self.flush()
        self.rec.flush()
        self.clock.flush()
        return {p.name: p.stat().st_size for p in (self.path, timings_path(self.path))}

    def close(self):
        if not self._open:
            return
        self._open = False
        try:
            self._drain()
            self.flush()
            self._check_writer()
            if self._values is not None:
                self._colour_frames()
            if self._layout is not None:  # the colour range in the title, the legends' room above the data
                self.rec.send_blueprint(layout.blueprint(*self._layout, extents=self._extents, title=self._title(),
                                                         same=tuple(n for n, same in self._same.items() if same),
                                                         rigid=bool(self._rigid)))
        finally:
            try:  # leaving the streams (last entered first) flushes and finalises the files
                self.clock.__exit__(None, None, None)
            finally:
                self.rec.__exit__(None, None, None)
