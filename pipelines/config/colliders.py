"""Rigid colliders (:mod:`mpm.colliders`): one dataclass per ``type``, the
keys every collider has (boundary, friction, container, motion) and each
type's geometry, and the :class:`mpm.Collider` it builds."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, List, Optional, cast

import numpy as np

import mpm
from mpm.colliders import BOUNDARIES
from mpm.meshes import MeshShape

from .fields import ConfigError, Context, Family, coords, given, number, setting, vector
from .shapes import axis_in, mesh_file


def _nonzero(key: str, value, ctx: Context) -> tuple:
    v = vector(key, value, ctx.dim)
    if np.linalg.norm(v) == 0.0:
        raise ConfigError(key, f"{list(v)}; accepted: a non-zero vector")
    return v


def _normals(key: str, value, ctx: Context) -> tuple:
    if not isinstance(value, list) or len(value) != 2:
        raise ConfigError(key, f"{value!r}; accepted: two vectors of {ctx.dim} numbers")
    return tuple(_nonzero(f"{key}[{i}]", n, ctx) for i, n in enumerate(value))


def _axis(key: str, value, ctx: Context):
    """A coordinate axis 0 to d - 1 or a non-zero direction."""
    if isinstance(value, list):
        v = vector(key, value, ctx.dim)
        if np.linalg.norm(v) == 0.0:
            raise ConfigError(key, f"{list(v)}; accepted: a non-zero vector or 0..{ctx.dim - 1}")
        return v
    return number(key, value, int, {"keyed": True, "ge": 0, "le": ctx.dim - 1})


def _about(unit: str):
    """A reader of a rotation in ``unit``: a number about z in 2D, three numbers in 3D."""

    def read(key: str, value, ctx: Context):
        if ctx.dim == 2:
            if isinstance(value, (list, tuple)):
                raise ConfigError(key, f"{value!r}; accepted: a number [{unit}] (about z) in 2D")
            return number(key, value, float)
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            raise ConfigError(key, f"{value!r}; accepted: a list of 3 numbers [{unit}] in 3D")
        return vector(key, value, 3)

    return read


_angular = _about("rad/s")  # an angular velocity
_rotation = _about("rad")  # an orientation as a rotation vector


def _center(doc: str = "centre [m]"):
    return setting(None, doc, size="dim", required=True)


def _positive(doc: str):
    return setting(None, doc, gt=0.0, required=True)


AXIS = "0, 1, 2 or a direction; null: 1 (+y)"


@dataclass
class _Collider:
    """The keys of every collider: ``boundary`` with Coulomb ``friction``,
    ``inside: true`` (the shape is a container), ``velocity`` and
    ``angular_velocity`` about ``pivot`` while start <= t < end."""

    geometry: ClassVar[tuple[str, ...]]  # each type's keys of its shape (build)
    type: str = setting("half_space", "the kind of collider")
    name: str = setting("", "a name for the recording")
    boundary: str = setting("slip", "sticky, slip, separate or elastic (mpm.colliders)", choices=BOUNDARIES)
    friction: float = setting(0.0, "Coulomb friction coefficient of slip, separate and elastic", ge=0.0)
    stiffness: float = setting(0.5, "an elastic collider's springs, times the body's P-wave modulus "
                                    "(mpm.elastic_contact)", gt=0.0, le=4.0)
    damping: float = setting(0.0, "an elastic collider's normal dashpot, a fraction of a particle's critical "
                                  "damping on its spring (mpm.elastic_contact)", ge=0.0, le=1.0)
    inside: bool = setting(False, "the solid is the outside of the shape (a container)")
    velocity: Optional[List[float]] = setting(None, "[m/s] moves the collider while start <= t < end; "
                                                    "null: static", size="dim")
    start: float = setting(0.0, "[s] when the motion starts", ge=0.0)
    end: Optional[float] = setting(None, "[s] when the motion ends; null: never")
    angular_velocity: Optional[Any] = setting(None, "[rad/s] turns the collider about its pivot while "
                                                    "start <= t < end: a number (about z) in 2D, a list of 3 "
                                                    "in 3D; null: no turning", parse=_angular)
    pivot: Optional[List[float]] = setting(None, "[m] the point it turns about, at rest (it moves with velocity); "
                                                 "null: its centre (half_space, wedge: its point)", size="dim")

    def problems(self):
        if self.end is not None and not self.end > self.start:
            return [("end", f"{self.end} out of range; accepted: end > start ({self.start})")]
        return []

    def common(self) -> dict:
        return dict(type=self.type, name=self.name, boundary=self.boundary, friction=self.friction,
                    stiffness=self.stiffness, damping=self.damping, inside=self.inside, velocity=self.velocity,
                    start=self.start,
                    end=float("inf") if self.end is None else self.end,
                    angular_velocity=self.angular_velocity, pivot=self.pivot)

    def build(self, key: str, ctx: Context) -> mpm.Collider:
        geometry = {k: getattr(self, k) for k in self.geometry}
        return mpm.Collider(**self.common(), **{k: v for k, v in geometry.items() if v is not None})


@dataclass
class HalfSpace(_Collider):
    """The solid behind a plane through ``point`` with outward ``normal``."""

    geometry = ("point", "normal")
    type: str = setting("half_space", "the kind of collider")
    point: Optional[List[float]] = setting(None, "a point of the plane [m]", size="dim", required=True)
    normal: Optional[List[float]] = setting(None, "outward normal (any length)", parse=_nonzero, required=True)


@dataclass
class Wedge(_Collider):
    """The intersection of two half-spaces through ``point`` (a ridge)."""

    geometry = ("point", "normals")
    type: str = setting("wedge", "the kind of collider")
    point: Optional[List[float]] = setting(None, "a point of both planes [m]", size="dim", required=True)
    normals: Optional[List[Any]] = setting(None, "two outward normals", parse=_normals, required=True)


@dataclass
class BoxCollider(_Collider):
    """An axis-aligned box."""

    geometry = ("center", "half_size")
    type: str = setting("box", "the kind of collider")
    center: Optional[List[float]] = _center()
    half_size: Optional[List[float]] = setting(None, "half the side along each axis [m]", size="dim", gt=0.0,
                                               required=True)


@dataclass
class SphereCollider(_Collider):
    """A ball (``inside: true``: a spherical container)."""

    geometry = ("center", "radius")
    type: str = setting("sphere", "the kind of collider")
    center: Optional[List[float]] = _center()
    radius: Optional[float] = _positive("radius [m]")


@dataclass
class CylinderCollider(_Collider):
    """A capped cylinder along ``axis``."""

    geometry = ("center", "radius", "half_height", "axis")
    type: str = setting("cylinder", "the kind of collider")
    center: Optional[List[float]] = _center()
    radius: Optional[float] = _positive("radius [m]")
    half_height: Optional[float] = _positive("half the length along the axis [m]")
    axis: Optional[Any] = setting(None, AXIS, parse=_axis)


@dataclass
class Cup(_Collider):
    """An open cylindrical cup: inner bottom centre ``center``, inner
    ``radius`` and ``depth``, wall ``thickness``, opening along ``axis``."""

    geometry = ("center", "radius", "depth", "thickness", "axis")
    type: str = setting("cup", "the kind of collider")
    center: Optional[List[float]] = _center("inner bottom centre [m]")
    radius: Optional[float] = _positive("inner radius [m]")
    depth: Optional[float] = _positive("inner depth [m]")
    thickness: Optional[float] = _positive("wall thickness [m]")
    axis: Optional[Any] = setting(None, AXIS, parse=_axis)


@dataclass
class BowlCollider(_Collider):
    """A spherical cap shell: the sphere ``center``, inner ``radius``,
    ``thickness``, cut by the rim plane ``rim`` above the centre along
    ``axis`` (the opening)."""

    geometry = ("center", "radius", "thickness", "rim", "axis")
    type: str = setting("bowl", "the kind of collider")
    center: Optional[List[float]] = _center()
    radius: Optional[float] = _positive("inner radius [m]")
    thickness: Optional[float] = _positive("wall thickness [m]")
    rim: Optional[float] = setting(None, "the rim plane's height above the centre along the axis [m]; "
                                         "accepted: -(radius + thickness) < rim <= radius", required=True)
    axis: Optional[Any] = setting(None, AXIS, parse=_axis)

    def build(self, key: str, ctx: Context) -> mpm.Collider:
        radius, thickness = given(self.radius), given(self.thickness)
        number(f"{key}.rim", self.rim, float, {"keyed": True, "gt": -(radius + thickness), "le": radius})
        return super().build(key, ctx)


@dataclass
class MeshCollider(_Collider):
    """A closed triangle mesh (3D), placed like a mesh shape."""

    dims = (3,)
    type: str = setting("mesh", "the kind of collider")
    mesh: Optional[str] = setting(None, "an OBJ, PLY, STL or USD path, or warp:<asset>", parse=mesh_file,
                                  required=True)
    center: Optional[List[float]] = _center()
    size: Optional[float] = _positive("largest side of the mesh's bounding box [m]")
    axis: Optional[int] = setting(None, "the mesh's up axis, 0, 1 or 2; null: 1 (y)", ge=0, le=2)

    def build(self, key: str, ctx: Context) -> mpm.Collider:
        shape = MeshShape(given(self.mesh), coords(self.center), given(self.size), axis_in(f"{key}.axis", self.axis, 3))
        return mpm.Collider(**self.common(), mesh=shape)


COLLIDERS = Family("collider", "type", {c.__dataclass_fields__["type"].default: c for c in (
    HalfSpace, Wedge, BoxCollider, SphereCollider, CylinderCollider, Cup, BowlCollider, MeshCollider)},
    unused="not used by a {kind} collider", missing="missing for a {kind} collider", flat_node=True)
ColliderConfig = COLLIDERS.flat("ColliderConfig", __name__, """A rigid collider (mpm.colliders): every key
of every type (null where the type does not use it); the types and their keys are the dataclasses of
:data:`COLLIDERS`.""")


@dataclass
class RigidBodyConfig:
    """A rigid body the material pushes back, advanced by Newton (mpm.rigid):
    its ``shape`` a box, sphere or (3D) cylinder or mesh collider at rest (its
    centre the body's initial centre of mass, a mesh's the centroid of its solid; its boundary and friction what the
    material meets), a ``density`` or a ``mass``, and its initial motion."""

    name: str = setting("", "a name for reports")
    shape: ColliderConfig = setting(ColliderConfig(), "its shape, boundary and friction: a box, sphere or (3D) "
                                                      "cylinder or mesh collider at rest", family=COLLIDERS)
    density: Optional[float] = setting(None, "[kg/m^3]; null: from mass", gt=0.0)
    mass: Optional[float] = setting(None, "[kg] (2D: per metre of depth); null: from density", gt=0.0)
    orientation: Optional[Any] = setting(None, "initial rotation about its centre [rad]: a number (2D) or a "
                                               "rotation vector (3D)", parse=_rotation)
    velocity: Optional[List[float]] = setting(None, "initial velocity of its centre [m/s]", size="dim")
    angular_velocity: Optional[Any] = setting(None, "initial angular velocity [rad/s]: a number (about z) in 2D, "
                                                    "a list of 3 in 3D", parse=_angular)

    def build(self, key: str, ctx: Context) -> mpm.RigidBody:
        shape = cast(Any, self.shape).build(f"{key}.shape", ctx)
        return mpm.RigidBody(shape, density=self.density, mass=self.mass, orientation=self.orientation,
                             velocity=None if self.velocity is None else tuple(self.velocity),
                             angular_velocity=self.angular_velocity, name=self.name)


def _rigid_ref(key: str, value, ctx: Context):
    """A rigid body's index or name (checked against the scene's rigid bodies in mpm.joints); null where
    the field allows it (the world)."""
    if value is None or isinstance(value, str):
        return value
    return number(key, value, int, {"keyed": True, "ge": 0})


@dataclass
class JointConfig:
    """A joint holding a rigid body to the world or to another rigid body,
    enforced by Newton (mpm.joints): its ``child`` and ``parent`` (null: the
    world) a rigid body's index or name, its ``anchor`` a point in world
    coordinates at the initial pose, ``axis`` the 3D revolute's or the prismatic's direction."""

    name: str = setting("", "a name for reports")
    type: str = setting("revolute", "revolute (2D: about z), ball (3D), prismatic (a slide along axis) or fixed",
                        choices=mpm.JOINT_TYPES)
    child: Any = setting(None, "the rigid body it holds: its index or name", parse=_rigid_ref, required=True)
    parent: Any = setting(None, "the rigid body it holds the child to: its index or name; null: the world",
                          parse=_rigid_ref)
    anchor: Optional[List[float]] = setting(None, "the joint's point [m], world coordinates at the initial pose",
                                            size="dim", required=True)
    axis: Optional[List[float]] = setting(None, "3D revolute: the hinge's direction, prismatic: the slide's (dim "
                                                "numbers), world coordinates at the initial pose; null in 2D "
                                                "revolute (about z), for a ball and fixed", size="dim")

    def build(self, key: str, ctx: Context) -> mpm.Joint:
        return mpm.Joint(child=self.child, anchor=tuple(given(self.anchor)), type=self.type, parent=self.parent,
                         axis=None if self.axis is None else tuple(self.axis), name=self.name)
