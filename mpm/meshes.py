"""Triangle-mesh shapes: a closed mesh, placed in the scene, filled with
particles (inside test by the generalised winding number on Warp's mesh BVH).

``load_mesh`` reads OBJ, PLY, STL, OFF and glTF files through trimesh and USD
files through ``pxr`` (package usd-core); the name ``warp:bunny`` (and the
other ``warp:<name>``, see :func:`mesh_assets`) refers to the assets shipped
inside the warp-lang package, e.g. the Stanford bunny and a bear.
"""

import functools
import hashlib
import os
from dataclasses import dataclass
from typing import cast

import numpy as np
import warp as wp

from .launch import warp_kernel


MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".usd", ".usda", ".usdc")
ASSETS_DIR = os.path.join(os.path.dirname(wp.__file__), "examples", "assets")
CLOSED_ASSETS = ("bunny", "bear", "cube", "sphere")  # the shipped meshes that enclose a volume


def mesh_assets() -> list[str]:
    """Names of the closed meshes shipped with warp-lang (``warp:<name>``)."""
    return [a for a in CLOSED_ASSETS if os.path.exists(os.path.join(ASSETS_DIR, a + ".usd"))]


def asset_path(name: str) -> str:
    """Resolve ``warp:<name>`` to the USD asset inside warp-lang; other names are paths."""
    if name.startswith("warp:"):
        return os.path.join(ASSETS_DIR, name[5:] + ".usd")
    return name


@functools.cache
def file_digest(name: str) -> str:
    """SHA-256 of a mesh file's bytes (a run's config hash includes it)."""
    with open(asset_path(name), "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:16]


class MeshError(ValueError):
    """A mesh file that cannot be used; the message names the file and why."""


def _signed_volume(pts: np.ndarray, tris: np.ndarray, origin: np.ndarray) -> float:
    """sum over the triangles of (a - o) . ((b - o) x (c - o)) / 6: the enclosed
    volume, the same for every origin o when the surface is closed."""
    a, b, c = (pts[tris[:, k]] - origin for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def solid_properties(pts: np.ndarray, tris: np.ndarray) -> tuple[float, np.ndarray]:
    """(volume [m^3], centroid [m]) of the solid a closed triangle mesh
    encloses: the tetrahedra (o, a, b, c) of its triangles with a point o
    summed with their signed volumes, V = sum V_t, centroid =
    sum V_t (o + a + b + c) / 4 / V (either orientation of the triangles)."""
    o = pts.mean(axis=0)
    a, b, c = (pts[tris[:, k]] for k in range(3))
    v = np.einsum("ij,ij->i", a - o, np.cross(b - o, c - o)) / 6.0
    volume = float(v.sum())
    return abs(volume), (v[:, None] * (o + a + b + c)).sum(axis=0) / (4.0 * volume)


def _read(path: str) -> tuple[np.ndarray, np.ndarray]:
    if not path.lower().endswith((".usd", ".usda", ".usdc")):
        import trimesh

        mesh = cast(trimesh.Trimesh, trimesh.load(path, force="mesh", process=False))  # force="mesh": a Trimesh
        return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    from pxr import Usd, UsdGeom  # usd-core

    stage = Usd.Stage.Open(path)
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):  # pyright: ignore[reportArgumentType, reportCallIssue]  (types-usd 24.5: no IsA(type))
            mesh = UsdGeom.Mesh(prim)
            xf = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
            pts = np.asarray(mesh.GetPointsAttr().Get(), float)
            pts = pts @ xf[:3, :3] + xf[3, :3]  # USD: row vectors
            counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
            idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
            tris, k = [], 0
            for c in counts:  # fan-triangulate polygons
                tris += [[idx[k], idx[k + j], idx[k + j + 1]] for j in range(1, c - 1)]
                k += c
            return pts, np.asarray(tris, np.int64).reshape(-1, 3)
    return np.zeros((0, 3)), np.zeros((0, 3), np.int64)


@functools.cache
def load_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3), triangles (m, 3)) of a mesh file, in its own units.
    Raises :class:`MeshError` for a file that is not a closed triangle mesh
    enclosing a volume (a directory, an empty or unreadable file, no
    triangles, non-finite vertices, indices past the vertices, a flat or
    open surface)."""
    path = asset_path(name)
    if not os.path.exists(path):
        raise MeshError(f"{name}: no such file")
    if os.path.isdir(path):
        raise MeshError(f"{name}: a directory, not a mesh file")
    if os.path.getsize(path) == 0:
        raise MeshError(f"{name}: an empty file")
    try:
        pts, tris = _read(path)
    except Exception as e:  # noqa: BLE001 - any reader's failure: the file is not a mesh it can read
        first = next((ln for ln in str(e).splitlines() if ln.strip()), type(e).__name__)
        raise MeshError(f"{name}: not a readable mesh ({type(e).__name__}: {first[:120]})") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 4 or len(tris) < 4:
        raise MeshError(f"{name}: {len(pts)} vertices and {len(tris)} triangles: not a closed triangle mesh "
                        "(a mesh file with no triangles, or not a mesh at all)")
    bad = ~np.all(np.isfinite(pts), axis=1)
    if bad.any():
        raise MeshError(f"{name}: {int(bad.sum())} of its {len(pts)} vertices are not finite")
    if tris.min() < 0 or tris.max() >= len(pts):
        raise MeshError(f"{name}: a triangle refers to vertex {int(tris.max())}, past its {len(pts)} vertices")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float(np.max(hi - lo))
    volume = _signed_volume(pts, tris, 0.5 * (lo + hi))
    if extent <= 0.0 or abs(volume) <= 1e-9 * extent ** 3:
        raise MeshError(f"{name}: encloses no volume (flat, or an open surface)")
    if abs(_signed_volume(pts, tris, hi + extent) - volume) > 1e-6 * abs(volume):
        raise MeshError(f"{name}: an open surface (its enclosed volume depends on the origin)")
    return pts, tris.astype(np.int32)


@warp_kernel
def _inside(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    q = wp.mesh_query_point_sign_winding_number(mesh, pts[i], 1.0e6)
    if q.result and q.sign < 0.0:  # pyright: ignore[reportAttributeAccessIssue]
        out[i] = 1


@dataclass(frozen=True, eq=False)
class MeshShape:
    """A closed triangle mesh scaled uniformly so that the largest side of its
    bounding box is ``size`` [m], centred (bounding-box centre) at ``center``;
    ``up`` optionally rotates the mesh's +y axis onto another axis (0, 1, 2)."""

    source: str
    """a mesh file (OBJ, PLY, STL, OFF, glTF, USD) or a packaged asset ("warp:bunny")"""
    center: tuple[float, ...]
    size: float
    up: int = 1

    @functools.cached_property
    def geometry(self) -> tuple[np.ndarray, np.ndarray]:
        pts, tris = load_mesh(self.source)
        if self.up != 1:
            perm = {0: [1, 0, 2], 2: [0, 2, 1]}[self.up]
            pts = pts[:, perm]
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pts = (pts - 0.5 * (lo + hi)) * (self.size / np.max(hi - lo)) + np.asarray(self.center)
        return pts, tris

    def bounds(self):
        pts = self.geometry[0]
        return pts.min(axis=0), pts.max(axis=0)

    def contains(self, x: np.ndarray) -> np.ndarray:
        pts, tris = self.geometry
        with wp.ScopedDevice("cpu"):
            mesh = wp.Mesh(points=wp.array(pts.astype(np.float32), dtype=wp.vec3),
                           indices=wp.array(tris.reshape(-1), dtype=wp.int32),
                           support_winding_number=True)
            out = wp.zeros(len(x), dtype=wp.int32)
            wp.launch(_inside, len(x), inputs=[mesh.id, wp.array(x.astype(np.float32), dtype=wp.vec3), out])
            return out.numpy().astype(bool)
