"""A run's frames as a USD stage, ``stage.usdc``, written with ``pxr``
(usd-core).

Metres (``metersPerUnit`` 1), y up (as every view of the project). Time
codes are simulated time: a frame at t [s] is sampled at time code
t x ``timeCodesPerSecond``, the rate being the frames per simulated second
of the export (rounded, at least 1; ``framesPerSecond`` the same), so a
player at its own rate plays the run in simulated real time and
t = time code / ``timeCodesPerSecond``. Prims under the default prim
``/World``:

  particles          UsdGeom.Points: time-sampled ``points`` (float32, z = 0 in
                     2D) and ``extent``, constant ``widths`` (the recorded
                     particle diameter), a ``vertex`` primvar per channel
                     (dJ, the logged fields, ``index``) time-sampled; ``body``
                     time-sampled only once particles were removed, else
                     constant
  walls              the inner faces of the walls that are not open
  colliders/<name>   each collider; a moving one with a time-sampled
                     ``xformOp:translate``

Solids are UsdGeom.Mesh (triangles) in 3D and linear UsdGeom.BasisCurves
(outlines) in 2D."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, Vt

from .frames import Run, Surface

FILE = "stage.usdc"
SOLID_RGB = (0.6, 0.6, 0.65)


def rate(times: list[float]) -> float:
    """Time codes per simulated second: the export's frames per simulated
    second (from the median interval), rounded, at least 1."""
    gaps = np.diff(np.asarray(times, float))
    gaps = gaps[gaps > 0]
    return float(max(1, round(1.0 / float(np.median(gaps))))) if len(gaps) else 1.0


def _vt(values: np.ndarray):
    """A channel's values as the Vt array of their type, and its Sdf type."""
    values = np.ascontiguousarray(values)
    if values.dtype.kind in "iu":
        if values.dtype.itemsize <= 4:
            return Vt.IntArray.FromNumpy(values.astype(np.int32)), Sdf.ValueTypeNames.IntArray
        return Vt.Int64Array.FromNumpy(values.astype(np.int64)), Sdf.ValueTypeNames.Int64Array
    return Vt.DoubleArray.FromNumpy(values.astype(np.float64)), Sdf.ValueTypeNames.DoubleArray


def _extent(x: np.ndarray, pad: float = 0.0) -> Vt.Vec3fArray:
    if not len(x):
        return Vt.Vec3fArray([Gf.Vec3f(0.0), Gf.Vec3f(0.0)])
    lo, hi = x.min(axis=0) - pad, x.max(axis=0) + pad
    return Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))])


def _solid(stage: Usd.Stage, path: str, s: Surface, codes: list[float], width: float) -> Usd.Prim:
    """A solid as a Mesh (triangles) or linear BasisCurves (2D polylines,
    ``width`` [m] wide), translated at each time code when it moves."""
    points = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(s.vertices, np.float32))
    if s.lines:
        geom = UsdGeom.BasisCurves.Define(stage, path)
        geom.CreateTypeAttr(UsdGeom.Tokens.linear)
        geom.CreateCurveVertexCountsAttr(Vt.IntArray([int(n) for n in s.lines]))
        geom.CreateWidthsAttr(Vt.FloatArray([width]))
        geom.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    else:
        geom = UsdGeom.Mesh.Define(stage, path)
        geom.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(s.triangles)))
        geom.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(s.triangles.reshape(-1),
                                                                                     np.int32)))
        geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geom.CreateDoubleSidedAttr(True)
    geom.CreatePointsAttr(points)
    geom.CreateExtentAttr(_extent(s.vertices))
    geom.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(*SOLID_RGB)]))
    if s.shifts is not None and s.turns is not None:  # USD's row vectors: q' = q M, M = [[R^T, 0], [shift, 1]]
        op = geom.AddTransformOp()
        for code, shift, turn in zip(codes, s.shifts, s.turns, strict=True):
            M = np.eye(4)
            M[:3, :3] = np.asarray(turn, float).T
            M[3, :3] = shift
            op.Set(Gf.Matrix4d(*map(float, M.reshape(-1))), Usd.TimeCode(code))
    elif s.shifts is not None:
        op = geom.AddTranslateOp()
        for code, shift in zip(codes, s.shifts, strict=True):
            op.Set(Gf.Vec3d(*map(float, shift)), Usd.TimeCode(code))
    return geom.GetPrim()


def write(run: Run, out: Path, progress=None) -> list[Path]:
    """The stage into ``out``/stage.usdc; returns [its path]. ``progress``
    (:class:`pipelines.run.progress.Progress`) is told of each frame."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / FILE
    times = [f.time for f in run.frames]
    per_s = rate(times)
    codes = [t * per_s for t in times]
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(per_s)
    stage.SetFramesPerSecond(per_s)
    if codes:
        stage.SetStartTimeCode(codes[0])
        stage.SetEndTimeCode(codes[-1])
    stage.GetRootLayer().documentation = (f"simulated time [s] = time code / {per_s:g} (timeCodesPerSecond); "
                                          f"metres, y up")
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    points = UsdGeom.Points.Define(stage, "/World/particles")
    points.CreateWidthsAttr(Vt.FloatArray([2.0 * run.radius]))
    points.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    primvars = UsdGeom.PrimvarsAPI(points)
    varying = any("index" in f.channels for f in run.frames)  # particles removed: the body of each changes
    made: dict = {}
    start = time.perf_counter()
    for k, (frame, code) in enumerate(zip(run.frames, codes, strict=True)):
        at = Usd.TimeCode(code)
        points.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(frame.positions, np.float32)), at)
        points.GetExtentAttr().Set(_extent(frame.positions, run.radius), at)
        for name, values in frame.channels.items():
            array, kind = _vt(values)
            if name not in made:
                made[name] = primvars.CreatePrimvar(name, kind, UsdGeom.Tokens.vertex)
            if name == "body" and not varying:
                made[name].Set(array)
            else:
                made[name].Set(array, at)
        if progress is not None:
            progress.update(k + 1, frame.time, 1e3 * (time.perf_counter() - start) / (k + 1))
    line = run.radius or 0.005  # the outlines' width [m]
    if run.walls is not None:
        _solid(stage, "/World/walls", run.walls, codes, line)
    if run.colliders:
        UsdGeom.Scope.Define(stage, "/World/colliders")
    for c in run.colliders:
        _solid(stage, f"/World/colliders/{Tf.MakeValidIdentifier(c.name)}", c, codes, line)
    stage.GetRootLayer().Save()
    return [path]
