"""Kinematic regions (the scene's ``regions``, mpm.scene.KinematicRegion) in
the replay's frames and the Rerun recording (/regions/<name>, logged with
each particle frame by pipelines.recording.rerun_sink): each region's
selection outlined where its particles are at the frame's time, read from
the recorded config (property ``config:yaml``), so recordings made before
this module show them in the frames too.

A region moves its particles rigidly (or with its prescribed homogeneous
stretch) while ``start <= t < end``: a point r from the region's centre c
goes to c(t) + exp(G tau) r, c(t) = c + u tau, tau = min(t, end) - start
(u its velocity, G its velocity gradient, the skew matrix of its angular
velocity plus any ``velocity_gradient``). The outline is drawn solid while
the region acts and dashed before and after (then where it let go).
Outlines: a box's edges, a sphere's circle (3D: three great circles), a
cylinder's rims and four lines along its axis; a bowl as its outer sphere
and a mesh as the cube of its size (their bounds); a compound's parts each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np

EDGE = (0.85, 0.0, 0.85)  # the outlines' colour (magenta: apart from the bodies' palette and the colliders' grey)
EDGE_RGBA = (217, 0, 217, 255)  # ... in the Rerun recording while the region acts
EDGE_IDLE_RGBA = (217, 0, 217, 90)  # ... before and after (Rerun draws no dashes: faint instead)
N_AROUND = 48  # segments of a circle


@dataclass
class Region:
    name: str
    select: dict  # the selection's shape, as configured (type, center, half_size, radius, ...)
    velocity: np.ndarray  # [m/s]
    gradient: np.ndarray  # (d, d) [1/s]
    center: np.ndarray  # [m] at the start
    start: float  # [s]
    end: float  # [s]

    def active(self, t: float) -> bool:
        return self.start <= t < self.end

    @property
    def still(self) -> bool:
        """Acting from the start, for ever, without moving: one outline, one style."""
        return self.start <= 0.0 and math.isinf(self.end) and not self.velocity.any() and not self.gradient.any()

    def outline(self, t: float, dim: int) -> list[np.ndarray]:
        """Polylines, each (n, dim) [m], of the selection at time ``t`` [s]."""
        tau = min(max(t, self.start), self.end) - self.start
        A = _expm(self.gradient * tau)
        c = self.center + self.velocity * tau
        return [c + (line - self.center) @ A.T for line in _lines(self.select, dim)]


def _expm(A: np.ndarray) -> np.ndarray:
    """exp(A) of a small matrix: Taylor series after scaling, then squaring."""
    n = max(0, int(math.ceil(math.log2(max(float(np.abs(A).sum()), 1e-300)))) + 1)
    B = A / 2.0 ** n
    out, term = np.eye(len(A)), np.eye(len(A))
    for k in range(1, 16):
        term = term @ B / k
        out = out + term
    for _ in range(n):
        out = out @ out
    return out


def _circle(center, e1, e2, r) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, N_AROUND + 1)[:, None]
    return center + r * (np.cos(a) * e1 + np.sin(a) * e2)


def _box(center, half) -> list[np.ndarray]:
    c, h = np.asarray(center, float), np.asarray(half, float)
    if len(c) == 2:
        return [c + h * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], float)]
    corners = lambda z: c + h * np.array([[-1, -1, z], [1, -1, z], [1, 1, z], [-1, 1, z], [-1, -1, z]], float)  # noqa: E731
    return [corners(-1), corners(1)] + [c + h * np.array([[x, y, -1], [x, y, 1]], float)
                                        for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]


def _sphere(center, r, dim) -> list[np.ndarray]:
    c = np.asarray(center, float)
    e = np.eye(dim)
    if dim == 2:
        return [_circle(c, e[0], e[1], r)]
    return [_circle(c, e[i], e[j], r) for i, j in ((0, 1), (1, 2), (2, 0))]


def _rotation(value, dim: int):
    """The rotation matrix of a configured ``rotation`` (None: none, or random: unknown here)."""
    if value is None or isinstance(value, str):
        return None
    from mpm.scene import rotation_matrix

    return rotation_matrix(value if dim == 3 else float(value), dim)


def _lines(shape: dict, dim: int) -> list[np.ndarray]:
    """The outline of a configured shape, before any motion."""
    kind = shape.get("type", "box")
    if kind == "compound":
        lines = [line for part in shape.get("parts") or [] for line in _lines(part, dim)]
    elif kind == "box":
        lines = _box(shape["center"], shape["half_size"])
    elif kind == "sphere":
        lines = _sphere(shape["center"], float(shape["radius"]), dim)
    elif kind == "bowl":
        lines = _sphere(shape["center"], float(shape["radius"]) + float(shape["thickness"]), dim)
    elif kind == "mesh":
        lines = _box(shape["center"], [0.5 * float(shape["size"])] * dim)
    elif kind == "cylinder":
        c, r, h = np.asarray(shape["center"], float), float(shape["radius"]), float(shape["half_height"])
        e = np.eye(3)
        k = 1 if shape.get("axis") is None else int(shape["axis"])
        a, e1, e2 = e[k], e[(k + 1) % 3], e[(k + 2) % 3]
        lines = [_circle(c + s * h * a, e1, e2, r) for s in (-1, 1)]
        lines += [np.stack([c - h * a + r * d, c + h * a + r * d]) for d in (e1, -e1, e2, -e2)]
    else:
        return []
    R = _rotation(shape.get("rotation"), dim)
    if R is not None and kind != "compound":
        c = np.asarray(shape["center"], float)
        lines = [c + (line - c) @ R.T for line in lines]
    return lines


def _config(text: str) -> dict:
    """A config document, interpolations resolved where they can be ({} without one)."""
    if not text:
        return {}
    try:
        from omegaconf import OmegaConf

        return cast(dict, OmegaConf.to_container(OmegaConf.create(text), resolve=True))  # a mapping's document
    except Exception:  # an interpolation that cannot be resolved here: the plain document
        import yaml

        try:
            return yaml.safe_load(text) or {}
        except yaml.YAMLError:
            return {}


def regions(rec) -> list[Region]:
    """The kinematic regions of a recording's scene (those it cannot read are left out)."""
    return of_yaml((rec.properties.get("config:yaml") or [""])[0], rec.dim)


def of_yaml(text: str, dim: int | None = None) -> list[Region]:
    """The kinematic regions of a run's config document (the run's ``config.yaml``)."""
    return of_config(_config(text), dim)


def of_config(config: dict, dim: int | None = None) -> list[Region]:
    """The kinematic regions of a composed config (a dict); ``dim``: the
    scene's, else the config's."""
    from mpm.scene import skew

    scene = config.get("scene") or {}
    dim = dim or int(scene.get("dim") or 2)
    out = []
    for i, r in enumerate(scene.get("regions") or []):
        try:
            select = dict(r["select"])
            lines = _lines(select, dim)
            if not lines:
                continue
            G = np.zeros((dim, dim)) if r.get("velocity_gradient") is None else \
                np.asarray(r["velocity_gradient"], float).reshape(dim, dim)
            if r.get("angular_velocity") is not None:
                G = G + skew(r["angular_velocity"], dim)
            pts = np.concatenate(lines)
            center = np.asarray(r["center"], float) if r.get("center") is not None else \
                np.asarray(select["center"], float) if select.get("center") is not None else \
                0.5 * (pts.min(axis=0) + pts.max(axis=0))
            out.append(Region(
                name=str(r.get("name") or f"region{i}"), select=select,
                velocity=np.zeros(dim) if r.get("velocity") is None else np.asarray(r["velocity"], float),
                gradient=G, center=center, start=float(r.get("start") or 0.0),
                end=math.inf if r.get("end") is None else float(r["end"])))
        except (KeyError, TypeError, ValueError):
            continue
    return out


def _style(region: Region, t: float) -> dict:
    return dict(color=EDGE, lw=1.5, ls="-" if region.active(t) else "--", zorder=4)


def draw_2d(ax, regs: list[Region], t: float, a: int = 0, b: int = 1) -> None:
    """The regions' outlines at ``t`` on 2D axes: a 2D scene, or a 3D one projected onto axes (a, b)."""
    dim = None
    for reg in regs:
        dim = dim or len(reg.center)
        for line in reg.outline(t, dim):
            ax.plot(line[:, a], line[:, b], **_style(reg, t))


def draw_3d(ax, regs: list[Region], t: float) -> None:
    """The regions' outlines at ``t`` on matplotlib's 3D axes (its z axis shows the scene's y)."""
    for reg in regs:
        for line in reg.outline(t, 3):
            ax.plot(line[:, 0], line[:, 2], line[:, 1], **_style(reg, t))


def legend_handles(regs: list[Region], t: float) -> list:
    """A legend entry per region, in its line style at ``t``."""
    from matplotlib.lines import Line2D

    return [Line2D([], [], color=EDGE, lw=1.5, ls=_style(r, t)["ls"],
                   label=f"region {r.name}" + ("" if r.active(t) else " (inactive)")) for r in regs]
