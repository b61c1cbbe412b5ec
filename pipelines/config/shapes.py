"""Shapes of bodies and region selections: one dataclass per ``type``, each
with its keys, and the solver's shape it builds (:mod:`mpm.scene`,
:class:`mpm.meshes.MeshShape`). ``rotation`` [degrees] turns any shape about
its centre: an angle in 2D, three angles about x, y, z in 3D, or ``random``
(drawn from the run's seed)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, List, Optional

import numpy as np

import mpm
from mpm.meshes import MESH_SUFFIXES, MeshError, MeshShape, asset_path, load_mesh, mesh_assets

from .fields import ConfigError, Context, Family, coords, given, number, setting, vector

ROTATION = "[deg] an angle (2D), three angles about x, y, z (3D), or random (drawn from the run's seed)"


def rotation(key: str, value, ctx: Context):
    """A rotation matrix from an angle (2D), three angles (3D) [degrees] or
    ``random`` (uniform over rotations, drawn from ``ctx.rng``)."""
    dim, rng = ctx.dim, ctx.rng
    if isinstance(value, str):
        if value != "random":
            raise ConfigError(key, f"{value!r}; accepted: an angle in degrees (2D), three (3D), or random")
        if rng is None:
            raise ConfigError(key, "random rotation is not available here; accepted: angles in degrees")
        if dim == 2:
            return mpm.scene.rotation_matrix(360.0 * rng.random(), 2)
        q = rng.normal(size=4)  # a uniformly random unit quaternion
        w, x, y, z = q / np.linalg.norm(q)
        return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    if dim == 2:
        return mpm.scene.rotation_matrix(number(key, value), 2)
    return mpm.scene.rotation_matrix(vector(key, value, 3), 3)


def mesh_file(key: str, name, ctx: Context | None = None) -> str:
    """A mesh file that exists, in a format the meshes module reads, and
    that it reads as a closed triangle mesh enclosing a volume."""
    accepted = (f"an OBJ, PLY, STL or USD path, or warp:<asset> "
                f"({', '.join('warp:' + a for a in mesh_assets())})")
    if not isinstance(name, str) or not os.path.exists(asset_path(name)):
        raise ConfigError(key, f"{name!r}: no such file; accepted: {accepted}")
    if os.path.isdir(asset_path(name)):
        raise ConfigError(key, f"{name!r}: a directory; accepted: {accepted}")
    if not name.startswith("warp:") and not name.lower().endswith(MESH_SUFFIXES):
        raise ConfigError(key, f"{name!r}: unknown format; accepted: {', '.join(MESH_SUFFIXES)}")
    try:
        load_mesh(name)
    except MeshError as e:
        raise ConfigError(key, f"{e}; accepted: a closed triangle mesh enclosing a volume, {accepted}") from None
    return name


def axis_in(key: str, axis: int | None, dim: int) -> int:
    """A coordinate axis of the scene (null: 1, along y)."""
    if axis is None:
        return 1
    if axis > dim - 1:
        raise ConfigError(key, f"{axis} out of range; accepted: {key} >= 0, {key} <= {dim - 1}")
    return axis


def _rotated(shape, R):
    return shape if R is None else mpm.scene.Rotated(shape, R)


def _center(doc: str = "centre [m]"):
    return setting(None, doc, size="dim", required=True)


def _rotation():
    return setting(None, ROTATION, parse=rotation)


@dataclass
class Box:
    """An axis-aligned box (before ``rotation``)."""

    type: str = setting("box", "the kind of shape")
    center: Optional[List[float]] = _center()
    half_size: Optional[List[float]] = setting(None, "half the side along each axis [m]", size="dim", gt=0.0,
                                               required=True)
    rotation: Optional[Any] = _rotation()

    def build(self, key: str, ctx: Context):
        return _rotated(mpm.Box(coords(self.center), coords(self.half_size)), self.rotation)


@dataclass
class Sphere:
    """A sphere (a disc in 2D), hollow inside ``inner_radius``."""

    type: str = setting("sphere", "the kind of shape")
    center: Optional[List[float]] = _center()
    radius: Optional[float] = setting(None, "radius [m]", gt=0.0, required=True)
    inner_radius: Optional[float] = setting(None, "hollow inside this radius [m]; null: solid", ge=0.0)
    rotation: Optional[Any] = _rotation()

    def build(self, key: str, ctx: Context):
        return _rotated(mpm.Sphere(coords(self.center), given(self.radius), _inner(key, self)), self.rotation)


def _inner(key: str, shape) -> float:
    inner = shape.inner_radius or 0.0
    if inner >= shape.radius:
        raise ConfigError(f"{key}.inner_radius", f"{inner} >= radius {shape.radius}; accepted: below the radius")
    return inner


@dataclass
class Cylinder:
    """A capped cylinder along ``axis`` (3D), hollow inside ``inner_radius``."""

    dims = (3,)
    type: str = setting("cylinder", "the kind of shape")
    center: Optional[List[float]] = _center()
    radius: Optional[float] = setting(None, "radius [m]", gt=0.0, required=True)
    half_height: Optional[float] = setting(None, "half the length along the axis [m]", gt=0.0, required=True)
    axis: Optional[int] = setting(None, "0, 1 or 2; null: 1 (along y)", ge=0, le=2)
    inner_radius: Optional[float] = setting(None, "hollow inside this radius [m]; null: solid", ge=0.0)
    rotation: Optional[Any] = _rotation()

    def build(self, key: str, ctx: Context):
        inner = _inner(key, self)
        return _rotated(mpm.Cylinder(coords(self.center), given(self.radius), given(self.half_height),
                                     axis_in(f"{key}.axis", self.axis, 3), inner), self.rotation)


@dataclass
class Bowl:
    """A spherical cap shell: the sphere ``center``, inner ``radius`` and
    wall ``thickness``, cut by the rim plane ``rim`` above the centre along
    ``axis`` (the opening)."""

    type: str = setting("bowl", "the kind of shape")
    center: Optional[List[float]] = _center("the sphere's centre [m]")
    radius: Optional[float] = setting(None, "inner radius [m]", gt=0.0, required=True)
    thickness: Optional[float] = setting(None, "wall thickness [m]", gt=0.0, required=True)
    rim: Optional[float] = setting(None, "the rim plane's height above the centre along the axis [m]; "
                                         "accepted: -(radius + thickness) < rim <= radius", required=True)
    axis: Optional[int] = setting(None, "the opening's axis, 0 to d - 1; null: 1 (y)", ge=0, le=2)
    rotation: Optional[Any] = _rotation()

    def build(self, key: str, ctx: Context):
        radius, thickness = given(self.radius), given(self.thickness)
        rim = number(f"{key}.rim", self.rim, float, {"keyed": True, "gt": -(radius + thickness), "le": radius})
        return _rotated(mpm.scene.Bowl(coords(self.center), radius, thickness, rim,
                                       axis_in(f"{key}.axis", self.axis, ctx.dim)), self.rotation)


@dataclass
class Mesh:
    """A closed triangle mesh (3D) scaled so that the largest side of its
    bounding box is ``size``, centred at ``center``, ``axis`` up."""

    dims = (3,)
    type: str = setting("mesh", "the kind of shape")
    mesh: Optional[str] = setting(None, "an OBJ, PLY, STL or USD path, or warp:<asset> (warp:bunny)",
                                  parse=mesh_file, required=True)
    center: Optional[List[float]] = _center()
    size: Optional[float] = setting(None, "largest side of the mesh's bounding box [m]", gt=0.0, required=True)
    axis: Optional[int] = setting(None, "the mesh's up axis, 0, 1 or 2; null: 1 (y)", ge=0, le=2)
    rotation: Optional[Any] = _rotation()

    def build(self, key: str, ctx: Context):
        return _rotated(MeshShape(given(self.mesh), coords(self.center), given(self.size),
                                  axis_in(f"{key}.axis", self.axis, 3)), self.rotation)


def parts(key: str, value, ctx: Context) -> list:
    if not isinstance(value, list) or not value:
        raise ConfigError(key, f"{value!r}; accepted: a non-empty list of shapes, each a mapping with a type key "
                               f"({', '.join(SHAPES.variants)}), e.g. [{{type: box, center: [...], half_size: [...]}}]")
    return [SHAPES.check(p, f"{key}[{i}]", ctx) for i, p in enumerate(value)]


@dataclass
class Compound:
    """The union of ``parts``, each a shape mapping."""

    type: str = setting("compound", "the kind of shape")
    parts: Optional[List[Any]] = setting(None, "the shapes, each a mapping with a type key", parse=parts,
                                         required=True)
    rotation: Optional[Any] = _rotation()

    def build(self, key: str, ctx: Context):
        return _rotated(mpm.Compound(tuple(p.build(f"{key}.parts[{i}]", ctx)
                                           for i, p in enumerate(given(self.parts)))), self.rotation)


SHAPES = Family("shape", "type", {c.__dataclass_fields__["type"].default: c
                                  for c in (Box, Sphere, Cylinder, Bowl, Mesh, Compound)},
                unused="not used by a {kind}", missing="missing for a {kind}", flat_node=True)
ShapeConfig = SHAPES.flat("ShapeConfig", __name__, """A shape: every key of every type (null where the
type does not use it); the types and their keys are the dataclasses of :data:`SHAPES`.""")


def fixed_shape(key: str, value, ctx: Context):
    """A shape without random rotations (a region's selection)."""
    return SHAPES.check(value, key, Context(dim=ctx.dim))
