"""Drawable surfaces of the rigid colliders (mpm.colliders), for the
recording and the replay's frames: a triangle mesh per collider in 3D, a
closed or open polyline in 2D, clipped to the domain box. Unbounded shapes
(half-spaces, wedges) are drawn where they cross the domain."""

from __future__ import annotations

import numpy as np

from mpm.colliders import Collider, axis_vector

N_AROUND = 32  # segments around a circle


def _basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to ``axis`` (3D) and to each other."""
    helper = np.eye(3)[np.argmin(np.abs(axis))]
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def _box_edges_polygon(p: np.ndarray, n: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The polygon where the plane through ``p`` with normal ``n`` cuts the box [lo, hi] (3D)."""
    corners = np.array([[hi[k] if (i >> k) & 1 else lo[k] for k in range(3)] for i in range(8)])
    pts = []
    for i in range(8):
        for k in range(3):
            j = i | (1 << k)
            if j == i:
                continue
            a, b = corners[i], corners[j]
            da, db = (a - p) @ n, (b - p) @ n
            if da * db <= 0 and da != db:
                pts.append(a + (b - a) * da / (da - db))
    if len(pts) < 3:
        return np.zeros((0, 3))
    pts = np.unique(np.round(np.array(pts), 12), axis=0)
    c = pts.mean(axis=0)
    e1, e2 = _basis(n)
    order = np.argsort(np.arctan2((pts - c) @ e2, (pts - c) @ e1))
    return pts[order]


def _clip(poly: np.ndarray, p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon with (x - p) . n <= 0."""
    out = []
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        da, db = (a - p) @ n, (b - p) @ n
        if da <= 0:
            out.append(a)
        if da * db < 0:
            out.append(a + (b - a) * da / (da - db))
    return np.array(out) if out else np.zeros((0, len(p)))


def _fan(poly: np.ndarray, start: int = 0) -> list[list[int]]:
    return [[start, start + i, start + i + 1] for i in range(1, len(poly) - 1)]


class _Mesh:
    def __init__(self):
        self.v: list[np.ndarray] = []
        self.f: list[list[int]] = []
        self.n = 0

    def polygon(self, poly):
        if len(poly) >= 3:
            self.v.append(poly)
            self.f += _fan(poly, self.n)
            self.n += len(poly)

    def grid(self, pts: np.ndarray, closed: bool = True):
        """A quad strip surface from an (rows, cols, 3) grid of points, the columns wrapping."""
        r, c = pts.shape[:2]
        idx = self.n + np.arange(r * c).reshape(r, c)
        for i in range(r - 1):
            for j in range(c if closed else c - 1):
                a, b = idx[i, j], idx[i, (j + 1) % c]
                a2, b2 = idx[i + 1, j], idx[i + 1, (j + 1) % c]
                self.f += [[a, b, b2], [a, b2, a2]]
        self.v.append(pts.reshape(-1, 3))
        self.n += r * c

    def result(self):
        if not self.v:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int32)
        return np.concatenate(self.v), np.array(self.f, np.int32)


def _revolve(profile: np.ndarray, center: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Points of a surface of revolution: ``profile`` rows (radius, height)."""
    e1, e2 = _basis(axis)
    ang = np.linspace(0, 2 * np.pi, N_AROUND, endpoint=False)
    ring = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2  # (N, 3)
    r, h = profile[:, 0][:, None, None], profile[:, 1][:, None, None]
    return center + h * axis[None, None, :] + r * ring[None, :, :]  # (rows, N, 3)


def _unit_normals(c: Collider) -> list[np.ndarray]:
    """A half-space's or a wedge's outward normals, of unit length."""
    given = [c.normal] if c.type == "half_space" else c.normals
    assert given is not None and all(n is not None for n in given)  # Collider.problems: its type's keys
    normals = [np.asarray(n, float) for n in given]
    return [n / np.linalg.norm(n) for n in normals]


def surface_3d(c: Collider, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3), triangles (m, 3)) of a 3D collider at its initial place."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = _Mesh()
    if c.type in ("half_space", "wedge"):
        p = np.asarray(c.point, float)
        normals = _unit_normals(c)
        for i, n in enumerate(normals):
            poly = _box_edges_polygon(p, n, lo, hi)
            for j, other in enumerate(normals):
                if j != i and len(poly):
                    poly = _clip(poly, p, other)
            m.polygon(poly)
        return m.result()
    if c.type == "mesh":
        assert c.mesh is not None  # Collider.problems: a mesh collider's mesh
        pts, tris = c.mesh.geometry
        return np.asarray(pts, float), np.asarray(tris, np.int32)
    center = np.asarray(c.center, float)
    if c.type == "box":
        h = np.asarray(c.half_size, float)
        corners = np.array([[(-1) ** (1 + ((i >> k) & 1)) for k in range(3)] for i in range(8)]) * h + center
        for k in range(3):
            for side in (0, 1):
                face = [i for i in range(8) if ((i >> k) & 1) == side]
                quad = corners[[face[0], face[1], face[3], face[2]]]
                m.polygon(quad)
        return m.result()
    if c.type == "sphere":
        th = np.linspace(0, np.pi, N_AROUND // 2 + 1)
        profile = np.stack([c.radius * np.sin(th), -c.radius * np.cos(th)], axis=1)
        m.grid(_revolve(profile, center, np.array([0.0, 1.0, 0.0])))
        return m.result()
    axis = np.asarray(axis_vector(c.axis, 3))
    if c.type == "cylinder":
        r, h = c.radius, c.half_height
        profile = np.array([[0, -h], [r, -h], [r, h], [0, h]])
    elif c.type == "cup":
        r, w, d = c.radius, c.thickness, c.depth
        profile = np.array([[0, -w], [r + w, -w], [r + w, d], [r, d], [r, 0], [0, 0]])
    else:  # bowl: outer cap, rim, inner cap (below the rim plane)
        R0, R1 = c.radius, c.radius + c.thickness
        th1 = np.arccos(np.clip(c.rim / R1, -1, 1))
        th0 = np.arccos(np.clip(c.rim / R0, -1, 1))
        t1 = np.linspace(np.pi, th1, N_AROUND // 2)
        t0 = np.linspace(th0, np.pi, N_AROUND // 2)
        profile = np.concatenate([np.stack([R1 * np.sin(t1), R1 * np.cos(t1)], axis=1),
                                  np.stack([R0 * np.sin(t0), R0 * np.cos(t0)], axis=1)])
    m.grid(_revolve(profile, center, axis))
    return m.result()


def outline_2d(c: Collider, lo, hi) -> list[np.ndarray]:
    """Polylines (each (n, 2)) of a 2D collider's boundary at its initial place."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if c.type in ("half_space", "wedge"):
        p = np.asarray(c.point, float)
        normals = _unit_normals(c)
        box = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
        solid = box
        for n in normals:
            solid = _clip(solid, p, n) if len(solid) else solid
        return [np.vstack([solid, solid[:1]])] if len(solid) else []
    center = np.asarray(c.center, float)
    if c.type == "box":
        h = np.asarray(c.half_size, float)
        return [center + h * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]])]
    ang = np.linspace(0, 2 * np.pi, 2 * N_AROUND + 1)
    if c.type == "sphere":
        return [center + c.radius * np.stack([np.cos(ang), np.sin(ang)], axis=1)]
    a = np.asarray(axis_vector(c.axis, 2))
    e = np.array([-a[1], a[0]])
    to = lambda rs: center + rs[:, :1] * e + rs[:, 1:] * a  # noqa: E731 - (radial, along) -> x
    if c.type == "cylinder":
        r, h = c.radius, c.half_height
        return [to(np.array([[-r, -h], [r, -h], [r, h], [-r, h], [-r, -h]]))]
    if c.type == "cup":
        r, w, d = c.radius, c.thickness, c.depth
        return [to(np.array([[-r - w, d], [-r - w, -w], [r + w, -w], [r + w, d], [r, d], [r, 0],
                             [-r, 0], [-r, d], [-r - w, d]]))]
    R0, R1 = c.radius, c.radius + c.thickness
    T1, T0 = (np.arccos(np.clip(-c.rim / R, -1, 1)) for R in (R1, R0))  # the rim's angle from the bottom
    t1, t0 = np.linspace(-T1, T1, N_AROUND), np.linspace(T0, -T0, N_AROUND)
    outer = np.stack([R1 * np.sin(t1), -R1 * np.cos(t1)], axis=1)
    inner = np.stack([R0 * np.sin(t0), -R0 * np.cos(t0)], axis=1)
    ring = np.vstack([outer, inner, outer[:1]])
    return [to(ring)]
