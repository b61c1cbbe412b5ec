"""Reading recordings back: particles per logged step, scalar series, events,
recording properties, and the wall-clock timings of the companion file.

A run killed without warning (SIGKILL, power loss) leaves a recording
without its footer: :func:`read` still reads it (the chunks are all there,
``Recording.complete`` is False) and :func:`repair` rewrites it with one.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, cast

import numpy as np

from .sinks import timings_path


@dataclass
class Recording:
    steps: np.ndarray  # logged particle steps
    times: np.ndarray  # their simulated times [s]
    positions: list[np.ndarray]  # per logged step, (n, dim)
    dJ: list[np.ndarray | None]  # per logged step
    fields: list[dict[str, np.ndarray]]  # per logged step: the other per-particle components
    body: np.ndarray | None  # body index per particle (static)
    colors: np.ndarray | None  # RGBA per particle, packed 0xRRGGBBAA: the body colours
    scalars: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> (steps, values)
    properties: dict[str, list]  # "config:overrides" -> [values], "provenance:git_commit" -> [value]
    update_steps: np.ndarray  # steps with a configuration-update event
    colliders: dict | None = None  # name -> (vertices, triangles) in 3D, or a list of (n, 2) polylines in 2D
    # (a rigid body's shape at rest among them, named rigid/<name>, with its pose per frame in collider_shift
    # and collider_turn)
    collider_shift: dict | None = None  # name -> (steps, translations) of a moving collider
    timings: dict = field(default_factory=dict)  # name -> (steps, values) [ms], from the timings file
    run: dict = field(default_factory=dict)  # "started", "host", "command" -> [value], from the timings file
    index: list = field(default_factory=list)  # per logged step: the particles' numbers (None: all of them)
    complete: bool = True  # False: the file has no footer (the writer was killed)
    end: tuple = (0, 0.0)  # the last step with a scalar row or particles, and its time [s]
    clock: tuple = (np.zeros(0, np.int64), np.zeros(0))  # (steps, simulated times [s]) of the scalar rows
    radius: float = 0.0  # the particles' drawn radius [m] (0: not recorded)
    collider_turn: dict | None = None  # name -> (steps, (n, 3, 3) rotations) of a turning collider: a rest
    # point q is drawn at R q + its collider_shift

    @property
    def dim(self) -> int:
        return self.positions[0].shape[1] if self.positions else 0


def _open(path: str | Path):
    """An RrdReader on ``path`` and whether the file has its footer (Rerun
    warns, and scans the whole file, when it has none)."""
    from rerun.chunk import RrdReader

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        reader = RrdReader(str(path))
    return reader, not any("no footer" in str(w.message) for w in caught)


def _load(path: str | Path, particles: bool = True):
    """The chunks of an .rrd file in a store (without the particle frames
    unless ``particles``), and whether it has its footer."""
    from rerun.chunk import RrdReader

    def chunks(reader):
        stream = reader.stream()
        return (stream if particles else stream.drop(content="/particles/**")).collect()

    if not Path(path).is_file():
        raise FileNotFoundError(f"no recording at {path}")
    reader, complete = _open(path)
    try:
        return chunks(reader), complete
    except RuntimeError:
        if complete:
            raise
    # killed in the middle of writing a message: read a repaired copy (the original is left as it is)
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "recording.rrd"
        shutil.copyfile(path, copy)
        repair(copy)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return chunks(RrdReader(str(copy))), False


def is_complete(path: str | Path) -> bool:
    """Whether the file ends with its footer (a finalised recording)."""
    return _open(path)[1]


def repair(path: str | Path) -> Path | None:
    """Rewrite a recording without footer (a killed run) with one, in place,
    with Rerun's own ``rerun rrd migrate``; the original is kept as
    ``<name>.backup.rrd``, which is returned (None: nothing to repair)."""
    path = Path(path)
    if is_complete(path):
        return None
    run = subprocess.run([sys.executable, "-m", "rerun", "rrd", "migrate", str(path)],
                         capture_output=True, text=True)
    if run.returncode != 0 or not is_complete(path):
        raise RuntimeError(f"rerun rrd migrate could not repair {path}: {run.stderr.strip()[-500:]}")
    return path.with_name(path.stem + ".backup.rrd")


def join(target: str | Path, parts: list) -> None:
    """Write ``parts`` (one recording's files, in order: a run and its resumed continuations, with or
    without footer) as one file at ``target``, atomically, with Rerun's own ``rerun rrd merge``; the parts
    are left as they are. RuntimeError (one line) when the merge fails: ``target`` is left as it was."""
    target = Path(target)
    tmp = target.with_name(target.stem + ".merging.rrd")
    run = subprocess.run([sys.executable, "-m", "rerun", "rrd", "merge", *map(str, parts), "-o", str(tmp)],
                         capture_output=True, text=True)
    if run.returncode != 0 or not tmp.is_file():
        tmp.unlink(missing_ok=True)
        said = (run.stderr.strip().splitlines() or ["no output"])[-1][-300:]
        raise RuntimeError(f"rerun rrd merge could not join {', '.join(Path(p).name for p in parts)}: {said}")
    tmp.replace(target)


def read(path: str | Path, particles: bool = True) -> Recording:
    """A recording's contents; ``particles=False``: without its particle
    frames (no positions, dJ or fields: the scalars, events, properties and
    colliders of a recording too large to hold its frames in memory)."""
    data, complete = _load(path, particles)
    parts = data.reader(index="step", contents="/particles").to_pandas()
    pos_col = next((c for c in parts.columns if c.endswith(":positions")), None)
    steps, times, positions, dJs, fields, index = [], [], [], [], [], []
    other = [c for c in parts.columns if c.startswith("/particles:")  # the fields (AnyValues: no archetype)
             and c.split(":", 1)[1] not in ("dJ", "positions", "colors", "radii", "body_index")
             and ":" not in c.split(":", 1)[1]]
    if pos_col is not None:
        row: Any  # a pandas row: its cells' types vary by column
        for _, row in parts.iterrows():
            if row[pos_col] is None:
                continue
            steps.append(int(row["step"]))
            times.append(row["sim_time"].total_seconds())
            pos = row[pos_col]
            positions.append(np.stack(pos).astype(np.float64) if len(pos) else
                             np.zeros((0, 3 if "Points3D" in pos_col else 2)))
            d = row.get("/particles:dJ")
            dJs.append(None if d is None else np.asarray(d, dtype=np.float64))
            fields.append({c.split(":", 1)[1]: np.asarray(row[c], dtype=np.float64) for c in other
                           if row[c] is not None})
            index.append(None if fields[-1].get("index") is None else fields[-1].pop("index").astype(np.int64))
    static = data.reader(index=None, contents="/particles").to_pandas()
    body = colors = None
    body_col = "/particles:body_index"
    if body_col in static.columns and len(static) and static[body_col].iloc[0] is not None:
        from .colours import PALETTE_PACKED

        body = np.asarray(static[body_col].iloc[0], dtype=np.int64)
        colors = PALETTE_PACKED[body % len(PALETTE_PACKED)]
    else:  # recordings before per-frame colours: static body colours
        col = next((c for c in static.columns if c.endswith(":colors")), None)
        if col is not None and len(static) and static[col].iloc[0] is not None:
            colors = np.asarray(static[col].iloc[0], dtype=np.uint32)
            body = np.unique(colors, return_inverse=True)[1]
    radius = next((float(np.ravel(static[c].iloc[0])[0]) for c in static.columns if c.endswith(":radii")
                   and len(static) and static[c].iloc[0] is not None and len(static[c].iloc[0])), 0.0)
    scalars_df = data.reader(index="step", contents="/scalars/**").to_pandas()
    scalars = _series(scalars_df, "/scalars")
    end = _end(scalars_df, steps, times)
    clock = ((scalars_df["step"].to_numpy(np.int64), scalars_df["sim_time"].dt.total_seconds().to_numpy())
             if len(scalars_df) and "sim_time" in scalars_df.columns else (np.zeros(0, np.int64), np.zeros(0)))
    props_df = data.reader(index=None, contents="/__properties/**").to_pandas()
    props = {}
    for c in props_df.columns:
        if c.startswith("property:"):
            v = props_df[c].iloc[0]
            props[c[len("property:"):]] = [] if v is None else list(v)
    events = data.reader(index="step", contents="/events").to_pandas()
    update_steps = [int(s) for s, u in zip(cast(Iterable, events.get("step", [])),  # (pandas: get's type has None)
                                           cast(Iterable, events.get("/events:update_step", []))) if u is not None]
    colliders, shifts, turns = _colliders(data)
    return Recording(np.asarray(steps), np.asarray(times), positions, dJs, fields, body, colors, scalars,
                     props, np.asarray(update_steps, dtype=np.int64), colliders, shifts,
                     *_timings(timings_path(path)), index, complete, end, clock, radius, turns)


def scene_config(rec: Recording) -> dict:
    """The resolved ``scene`` config the run recorded (property ``config:yaml``); empty if none or unreadable."""
    import yaml

    try:
        config = yaml.safe_load((rec.properties.get("config:yaml") or [""])[0])
    except yaml.YAMLError:
        return {}
    return (config.get("scene") or {}) if isinstance(config, dict) else {}


def _end(df, steps: list, times: list) -> tuple[int, float]:
    """The last step reached and its simulated time [s]: the last particle
    frame's, or the scalar rows' (``df``) if they go further."""
    end = (int(steps[-1]), float(times[-1])) if steps else (0, 0.0)
    if len(df) and int(df["step"].max()) > end[0]:
        row = df.loc[df["step"].idxmax()]
        end = (int(row["step"]), row["sim_time"].total_seconds())
    return end


def _series(df, root: str) -> dict:
    """``root/<name>`` Scalars series of a step-indexed frame -> {name: (steps, values)}."""
    out = {}
    for c in df.columns:
        if c.startswith(f"{root}/") and c.endswith(":scalars"):  # (not the series' names)
            name = c[len(root) + 1:].split(":")[0]
            s = df[["step", c]].dropna()
            out[name] = (s["step"].to_numpy(), np.array([v[0] for v in s[c]], dtype=np.float64))
    return out


def _timings(path: Path) -> tuple[dict, dict]:
    """The timings file's series and run properties (empty when it is missing)."""
    if not path.is_file():
        return {}, {}
    data, _ = _load(path)
    props = data.reader(index=None, contents="/__properties/**").to_pandas()
    run = {c[len("property:run:"):]: list(props[c].iloc[0]) for c in props.columns
           if c.startswith("property:run:") and props[c].iloc[0] is not None}
    try:
        series = _series(data.reader(index="step", contents="/timings/**").to_pandas(), "/timings")
    except ValueError:  # no step timed (a run that took none): the file has no step index
        series = {}
    return series, run


def _colliders(data) -> tuple[dict, dict, dict]:
    """The colliders' static geometry, the translations of moving ones and
    the rotations of turning ones (Rerun keeps a mat3x3 column by column);
    the rigid bodies' (/rigid/<name>) with them, named ``rigid/<name>``."""
    geo, shifts, turns = _solids(data, "/colliders/", "")
    for out, more in zip((geo, shifts, turns), _solids(data, "/rigid/", "rigid/")):
        out.update(more)
    return geo, shifts, turns


def _solids(data, root: str, prefix: str) -> tuple[dict, dict, dict]:
    """:func:`_colliders` of the entities under ``root``, their names after ``prefix``."""
    meshes: dict = {}
    strips: dict = {}
    static = data.reader(index=None, contents=root + "**").to_pandas()
    for c in static.columns:
        if not c.startswith(root):
            continue
        name, kind = prefix + c[len(root):].split(":")[0], c.split(":")[-1]
        values = static[c].dropna()
        if not len(values):
            continue
        v = values.iloc[0]
        if kind in ("vertex_positions", "triangle_indices"):
            meshes.setdefault(name, {})[kind] = np.stack(v)
        elif kind == "strips":
            strips[name] = [np.stack(strip).astype(np.float64) for strip in v]
    geo = {name: (m["vertex_positions"].astype(np.float64), m["triangle_indices"].astype(np.int64))
           for name, m in meshes.items() if len(m) == 2}
    geo.update(strips)
    shifts, turns = {}, {}
    if not geo:
        return geo, shifts, turns
    moving = data.reader(index="step", contents=root + "**").to_pandas()
    for c in moving.columns:
        if c.startswith(root) and c.endswith(":translation"):
            rows = moving[["step", c]].dropna()
            shifts[prefix + c[len(root):].split(":")[0]] = (
                rows["step"].to_numpy(), np.stack([_flat(v) for v in rows[c]]))
        if c.startswith(root) and c.endswith(":mat3x3"):
            rows = moving[["step", c]].dropna()
            turns[prefix + c[len(root):].split(":")[0]] = (
                rows["step"].to_numpy(), np.stack([_flat(v).reshape(3, 3).T for v in rows[c]]))
    return geo, shifts, turns


def _flat(value) -> np.ndarray:
    """A logged vector as a flat float array (the reader hands a translation
    as an object array holding one vector)."""
    return np.concatenate([np.asarray(x, np.float64).reshape(-1) for x in np.ravel(value)])


def compare(a: Recording, b: Recording) -> dict:
    """Bit-for-bit comparison of particles, dJ and physics scalars (the
    wall-clock timings live in another file); returns {"match": bool, "largest": {...}, "checked": {...}}."""
    largest: dict[str, float] = {}
    mismatch = []
    if not np.array_equal(a.steps, b.steps):
        mismatch.append("logged particle steps differ")
    for k, (pa, pb) in enumerate(zip(a.positions, b.positions)):
        if pa.shape != pb.shape:
            mismatch.append(f"particle count differs at step {a.steps[k]}")
            continue
        dev = float(np.max(np.abs(pa - pb))) if pa.size else 0.0
        largest["positions"] = max(largest.get("positions", 0.0), dev)
    for da, db in zip(a.dJ, b.dJ):
        if da is not None and db is not None and da.shape == db.shape and da.size:  # (a frame may be empty)
            largest["dJ"] = max(largest.get("dJ", 0.0), float(np.max(np.abs(da - db))))
    for name, (sa, va) in a.scalars.items():
        if name not in b.scalars or not np.array_equal(sa, b.scalars[name][0]):
            mismatch.append(f"scalar {name} missing or on other steps")
            continue
        vb = b.scalars[name][1]
        same = (va == vb) | (np.isnan(va) & np.isnan(vb))  # infinities included
        with np.errstate(invalid="ignore"):
            dev = float(np.max(np.where(same, 0.0, np.abs(va - vb)))) if len(va) else 0.0
        largest[f"scalar:{name}"] = dev
    match = not mismatch and all(v == 0.0 for v in largest.values())
    return {"match": match, "problems": mismatch,
            "largest": {k: v for k, v in largest.items() if v != 0.0},
            "checked": {"particle_frames": len(a.positions), "scalars": len(largest)}}
