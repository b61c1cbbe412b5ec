"""A run's frames as a VTK time series that ParaView opens as one:
``particles_000000.vtp``, ... (one PolyData per exported frame: the points,
a vertex cell each, a point-data array per channel, the field data
``TimeValue`` [s] and ``step``) and ``particles.pvd``, the collection that
gives each file its simulated time [s].

The solids beside them: ``walls.vtp`` (the inner faces of the walls that are
not open) and ``collider_<name>.vtp`` per collider (triangles in 3D,
polylines in 2D); a moving collider is a series of its own,
``collider_<name>_000000.vtp``, ... with ``collider_<name>.pvd``, at the
particles' times. The files are VTK's XML format, written by the ``vtk``
package (binary, appended, zlib-compressed); the ``.pvd`` collections, for
which it has no writer, by :mod:`xml.etree`."""

from __future__ import annotations

import re
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

from .frames import Frame, Run, Surface


def _cells(offsets: np.ndarray, connectivity: np.ndarray) -> vtkCellArray:
    cells = vtkCellArray()
    cells.SetData(numpy_support.numpy_to_vtkIdTypeArray(np.ascontiguousarray(offsets, np.int64), deep=True),
                  numpy_support.numpy_to_vtkIdTypeArray(np.ascontiguousarray(connectivity, np.int64), deep=True))
    return cells


def _points(x: np.ndarray) -> vtkPoints:
    points = vtkPoints()
    points.SetData(numpy_support.numpy_to_vtk(np.ascontiguousarray(x), deep=True))
    return points


def _array(name: str, values: np.ndarray):
    arr = numpy_support.numpy_to_vtk(np.ascontiguousarray(values), deep=True)
    arr.SetName(name)
    return arr


def particles(frame: Frame) -> vtkPolyData:
    """A frame as PolyData: its points, a vertex cell per point, its channels
    as point data, its time [s] and step as field data."""
    n = len(frame.positions)
    poly = vtkPolyData()
    poly.SetPoints(_points(frame.positions))
    poly.SetVerts(_cells(np.arange(n + 1), np.arange(n)))
    for name, values in frame.channels.items():
        poly.GetPointData().AddArray(_array(name, values))
    poly.GetFieldData().AddArray(_array("TimeValue", np.array([frame.time])))
    poly.GetFieldData().AddArray(_array("step", np.array([frame.step], np.int64)))
    return poly


def surface(s: Surface, shift: np.ndarray | None = None, turn: np.ndarray | None = None) -> vtkPolyData:
    """A solid's surface as PolyData (turned by ``turn`` (3, 3) about the
    origin, then translated by ``shift`` [m]): triangles, or the polylines
    of a 2D outline."""
    poly = vtkPolyData()
    v = s.vertices if turn is None else s.vertices @ np.asarray(turn).T
    poly.SetPoints(_points(v + (0.0 if shift is None else shift)))
    if s.lines:
        poly.SetLines(_cells(np.cumsum([0, *s.lines]), np.arange(sum(s.lines))))
    else:
        poly.SetPolys(_cells(3 * np.arange(len(s.triangles) + 1), s.triangles.reshape(-1)))
    return poly


def write_vtp(poly: vtkPolyData, path: Path) -> Path:
    """``poly`` as a VTK XML PolyData file (binary, appended, zlib)."""
    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(poly)
    writer.SetDataModeToAppended()
    writer.EncodeAppendedDataOff()
    writer.SetCompressorTypeToZLib()
    if not writer.Write():
        raise OSError(f"vtk could not write {path}")
    return path


def write_pvd(path: Path, entries: list[tuple[float, str]]) -> Path:
    """A ParaView collection: each (time [s], file name relative to it) a ``DataSet``."""
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for t, name in entries:
        ET.SubElement(collection, "DataSet", timestep=repr(float(t)), group="", part="0", file=name)
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def file_name(name: str) -> str:
    """A collider's name as part of a file name (other characters than
    letters, digits, ``-``, ``_`` and ``.`` become ``_``)."""
    return re.sub(r"[^\w.-]", "_", name)


def write(run: Run, out: Path, progress=None) -> list[Path]:
    """The particle series, its ``particles.pvd``, the walls and the
    colliders into ``out``; returns the files written. ``progress``
    (:class:`pipelines.run.progress.Progress`) is told of each frame."""
    out.mkdir(parents=True, exist_ok=True)
    written, entries = [], []
    start = time.perf_counter()
    for k, frame in enumerate(run.frames):
        name = f"particles_{k:06d}.vtp"
        written.append(write_vtp(particles(frame), out / name))
        entries.append((frame.time, name))
        if progress is not None:
            progress.update(k + 1, frame.time, 1e3 * (time.perf_counter() - start) / (k + 1))
    written.append(write_pvd(out / "particles.pvd", entries))
    if run.walls is not None:
        written.append(write_vtp(surface(run.walls), out / "walls.vtp"))
    for c in run.colliders:
        base = f"collider_{file_name(c.name)}"
        if c.shifts is None:
            written.append(write_vtp(surface(c), out / f"{base}.vtp"))
            continue
        series = []
        turns = c.turns or [None] * len(c.shifts)
        for k, (frame, shift, turn) in enumerate(zip(run.frames, c.shifts, turns, strict=True)):
            written.append(write_vtp(surface(c, shift, turn), out / f"{base}_{k:06d}.vtp"))
            series.append((frame.time, f"{base}_{k:06d}.vtp"))
        written.append(write_pvd(out / f"{base}.pvd", series))
    return written
