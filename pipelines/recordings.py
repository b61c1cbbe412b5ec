"""Reading recordings back: particles per logged step, scalar series, events,
recording properties."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Recording:
    steps: np.ndarray  # logged particle steps
    times: np.ndarray  # their simulated times [s]
    positions: list[np.ndarray]  # per logged step, (n, dim)
    dJ: list[np.ndarray | None]  # per logged step
    fields: list[dict[str, np.ndarray]]  # per logged step: the other per-particle components
    body: np.ndarray | None  # body colour index per particle (from the static colours)
    colors: np.ndarray | None  # static RGBA colours per particle
    scalars: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> (steps, values)
    properties: dict[str, list]  # "config:overrides" -> [values], "provenance:git_commit" -> [value]
    update_steps: np.ndarray  # steps with a configuration-update event
    colliders: dict = None  # name -> (vertices, triangles) in 3D, or a list of (n, 2) polylines in 2D
    collider_shift: dict = None  # name -> (steps, translations) of a moving collider

    @property
    def dim(self) -> int:
        return self.positions[0].shape[1] if self.positions else 0


def read(path: str | Path) -> Recording:
    from rerun.chunk import RrdReader

    data = RrdReader(str(path)).store().stream().collect()
    parts = data.reader(index="step", contents="/particles").to_pandas()
    pos_col = next((c for c in parts.columns if c.endswith(":positions")), None)
    steps, times, positions, dJs, fields = [], [], [], [], []
    other = [c for c in parts.columns if c.startswith("/particles:")
             and c.split(":", 1)[1] not in ("dJ", "positions", "colors", "radii")
             and not c.split(":", 1)[1].startswith("Points")]
    if pos_col is not None:
        for _, row in parts.iterrows():
            if row[pos_col] is None:
                continue
            steps.append(int(row["step"]))
            times.append(row["sim_time"].total_seconds())
            positions.append(np.stack(row[pos_col]).astype(np.float64))
            d = row.get("/particles:dJ")
            dJs.append(None if d is None else np.asarray(d, dtype=np.float64))
            fields.append({c.split(":", 1)[1]: np.asarray(row[c], dtype=np.float64) for c in other
                           if row[c] is not None})
    static = data.reader(index=None, contents="/particles").to_pandas()
    colors = None
    col = next((c for c in static.columns if c.endswith(":colors")), None)
    if col is not None and len(static) and static[col].iloc[0] is not None:
        colors = np.asarray(static[col].iloc[0], dtype=np.uint32)
    body = np.unique(colors, return_inverse=True)[1] if colors is not None else None
    scalars_df = data.reader(index="step", contents="/scalars/**").to_pandas()
    scalars = {}
    for c in scalars_df.columns:
        if c.startswith("/scalars/"):
            name = c[len("/scalars/"):].split(":")[0]
            s = scalars_df[["step", c]].dropna()
            scalars[name] = (s["step"].to_numpy(), np.array([v[0] for v in s[c]], dtype=np.float64))
    props_df = data.reader(index=None, contents="/__properties/**").to_pandas()
    props = {}
    for c in props_df.columns:
        if c.startswith("property:"):
            v = props_df[c].iloc[0]
            props[c[len("property:"):]] = [] if v is None else list(v)
    events = data.reader(index="step", contents="/events").to_pandas()
    update_steps = [int(s) for s, u in zip(events.get("step", []), events.get("/events:update_step", []))
                    if u is not None]
    colliders, shifts = _colliders(data)
    return Recording(np.asarray(steps), np.asarray(times), positions, dJs, fields, body, colors, scalars,
                     props, np.asarray(update_steps, dtype=np.int64), colliders, shifts)


def _colliders(data) -> tuple[dict, dict]:
    """The colliders' static geometry and the translations of moving ones."""
    meshes: dict = {}
    strips: dict = {}
    static = data.reader(index=None, contents="/colliders/**").to_pandas()
    for c in static.columns:
        if not c.startswith("/colliders/"):
            continue
        name, kind = c[len("/colliders/"):].split(":")[0], c.split(":")[-1]
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
    moving = data.reader(index="step", contents="/colliders/**").to_pandas()
    shifts = {}
    for c in moving.columns:
        if c.startswith("/colliders/") and c.endswith(":translation"):
            rows = moving[["step", c]].dropna()
            shifts[c[len("/colliders/"):].split(":")[0]] = (
                rows["step"].to_numpy(), np.stack([np.asarray(v).reshape(-1) for v in rows[c]]))
    return geo, shifts


TIMING_SCALARS = {"step_time_ms"}  # wall-clock figures, never reproducible


def compare(a: Recording, b: Recording) -> dict:
    """Bit-for-bit comparison of particles, dJ and physics scalars (wall-clock
    timings aside); returns {"match": bool, "largest": {...}, "checked": {...}}."""
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
        if da is not None and db is not None and da.shape == db.shape:
            largest["dJ"] = max(largest.get("dJ", 0.0), float(np.max(np.abs(da - db))))
    for name, (sa, va) in a.scalars.items():
        if name in TIMING_SCALARS:
            continue
        if name not in b.scalars or not np.array_equal(sa, b.scalars[name][0]):
            mismatch.append(f"scalar {name} missing or on other steps")
            continue
        vb = b.scalars[name][1]
        both_nan = np.isnan(va) & np.isnan(vb)
        dev = float(np.max(np.where(both_nan, 0.0, np.abs(va - vb)))) if len(va) else 0.0
        largest[f"scalar:{name}"] = dev
    match = not mismatch and all(v == 0.0 for v in largest.values())
    return {"match": match, "problems": mismatch,
            "largest": {k: v for k, v in largest.items() if v != 0.0},
            "checked": {"particle_frames": len(a.positions), "scalars": len(largest)}}
