"""A run's recorded particle frames as plain arrays, with its colliders and
walls: what the VTK and USD writers take.

Everything comes from the run's ``recording.rrd`` (read by
:func:`pipelines.recording.recordings.read`): positions, ``dJ`` and the other
per-particle fields of each logged frame, the body of each particle, the
colliders' surfaces and the translations of moving ones, and the resolved
config (recording property ``config``) for the domain and its walls."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..recording import recordings


@dataclass
class Frame:
    """One logged particle frame."""

    step: int
    time: float  # simulated time [s]
    positions: np.ndarray  # (n, 3) [m], float32 as recorded; z = 0 in 2D
    channels: dict[str, np.ndarray]  # name -> (n,) per particle: dJ, the logged fields, body, index


@dataclass
class Surface:
    """A collider's or the walls' geometry [m]: triangles in 3D, polylines in 2D."""

    name: str
    vertices: np.ndarray  # (m, 3) [m]; z = 0 in 2D
    triangles: np.ndarray  # (k, 3) indices into vertices; (0, 3) for polylines
    lines: list[int] = field(default_factory=list)  # vertices per polyline, in order (2D); empty for triangles
    shifts: list[np.ndarray] | None = None  # a moving collider's translation (3,) [m] at each exported frame
    turns: list[np.ndarray] | None = None  # a turning collider's rotation (3, 3) at each exported frame: a vertex
    # q is at turns[k] q + shifts[k]


@dataclass
class Run:
    """What an export writes: the frames, the particle radius and the scene's solids."""

    dim: int
    frames: list[Frame]
    radius: float  # the particles' drawn radius [m] (0: not recorded)
    colliders: list[Surface]
    walls: Surface | None  # the inner faces of the walls that are not open (None: every wall open)


def pad(x: np.ndarray) -> np.ndarray:
    """Positions (n, 2 or 3) as (n, 3), z = 0 for 2D."""
    x = np.asarray(x)
    return x if x.shape[1] == 3 else np.concatenate([x, np.zeros((len(x), 3 - x.shape[1]), x.dtype)], axis=1)


def recording_path(run_dir: Path) -> Path:
    """The recording of a run directory (or the recording itself)."""
    run_dir = Path(run_dir)
    return run_dir if run_dir.suffix == ".rrd" else run_dir / "recording.rrd"


def read(run_dir: Path, every: int = 1) -> Run:
    """Every ``every``-th logged frame of the run in ``run_dir`` (from the
    first), with its colliders and walls."""
    rec = recordings.read(recording_path(run_dir))
    picked = range(0, len(rec.positions), every)
    removed = any(i is not None for i in rec.index)  # then every frame has its particles' numbers
    frames = [Frame(int(rec.steps[k]), float(rec.times[k]), pad(rec.positions[k]).astype(np.float32),
                    _channels(rec, k, removed)) for k in picked]
    config = recordings.scene_config(rec)
    colliders = [_collider(name, geo, rec, [int(rec.steps[k]) for k in picked])
                 for name, geo in (rec.colliders or {}).items()]
    return Run(rec.dim or int(config.get("dim", 2)), frames, float(rec.radius), colliders, walls(config))


def _channels(rec: recordings.Recording, k: int, numbered: bool) -> dict[str, np.ndarray]:
    """Frame ``k``'s per-particle values: dJ, the logged fields, the body
    index and (``numbered``: when the run removed particles at open walls)
    the particles' numbers, 0 to n - 1 before the first removal."""
    out = {}
    if rec.dJ[k] is not None:
        out["dJ"] = rec.dJ[k]
    out.update(rec.fields[k])
    index = rec.index[k] if rec.index else None
    if rec.body is not None:
        out["body"] = (rec.body if index is None else rec.body[index]).astype(np.int32)
    if numbered:
        out["index"] = np.arange(len(rec.positions[k]), dtype=np.int64) if index is None else index
    return out


def _collider(name: str, geo, rec: recordings.Recording, steps: list[int]) -> Surface:
    """A recorded collider surface (a triangle mesh, or a 2D outline's
    polylines) with its translation at each exported frame when it moves,
    and its rotation when it turns."""
    if isinstance(geo, tuple):
        vertices, triangles = geo
        surface = Surface(name, pad(vertices).astype(np.float64), np.asarray(triangles, np.int64))
    else:
        surface = Surface(name, pad(np.concatenate(geo)).astype(np.float64), np.zeros((0, 3), np.int64),
                          [len(line) for line in geo])
    moves = (rec.collider_shift or {}).get(name)
    if moves is not None:
        at, shift = moves
        idx = np.searchsorted(at, steps, side="right") - 1
        surface.shifts = [pad(shift[i:i + 1])[0] if i >= 0 else np.zeros(3) for i in idx]
    turns = (rec.collider_turn or {}).get(name)
    if turns is not None:
        at, mats = turns
        idx = np.searchsorted(at, steps, side="right") - 1
        surface.turns = [mats[i] if i >= 0 else np.eye(3) for i in idx]
    return surface


def walls(scene: dict) -> Surface | None:
    """The inner faces of the domain's walls (``wall_cells`` cells inside
    its faces) that are not open (``walls``: one type, or one per face in
    the order x_lo, x_hi, y_lo, ...): a quad of two triangles per face in
    3D, a segment per face in 2D. None without a recorded domain or when
    every wall is open."""
    try:
        L = np.asarray(scene["domain"], float)
        dim = len(L)
        w = int(scene.get("wall_cells", 0)) * L[0] / int(scene["resolution"])
        kinds = scene.get("walls", "slip")
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None
    kinds = [kinds] * 2 * dim if isinstance(kinds, str) else list(kinds)
    lo, hi = np.full(dim, w), L - w
    vertices, triangles, lines = [], [], []
    for f, kind in enumerate(kinds[:2 * dim]):
        if kind == "open":
            continue
        axis, side = divmod(f, 2)
        at = hi[axis] if side else lo[axis]
        if dim == 2:
            other = 1 - axis
            seg = np.zeros((2, 3))
            seg[:, axis], seg[:, other] = at, (lo[other], hi[other])
            vertices += list(seg)
            lines.append(2)
            continue
        a, b = [d for d in range(3) if d != axis]
        quad = np.zeros((4, 3))
        quad[:, axis] = at
        quad[:, a] = (lo[a], hi[a], hi[a], lo[a])
        quad[:, b] = (lo[b], lo[b], hi[b], hi[b])
        n = len(vertices)
        vertices += list(quad)
        triangles += [(n, n + 1, n + 2), (n, n + 2, n + 3)]
    if not vertices:
        return None
    return Surface("walls", np.asarray(vertices), np.asarray(triangles, np.int64).reshape(-1, 3), lines)
