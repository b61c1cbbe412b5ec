"""Rigid bodies that the material pushes back: their description and checks.

A :class:`RigidBody` is a solid of one of the shapes box, sphere or
(3D) cylinder or closed triangle mesh, given as a
:class:`mpm.colliders.Collider` at rest (its ``center`` the body's initial
centre of mass, a mesh's the centroid of the solid it encloses; its
``boundary`` and ``friction`` the rule the material meets on its surface,
as a collider's),
with a ``density`` [kg/m^3] or a ``mass`` [kg] (2D: per metre of depth,
the shape taken one metre deep, as the material's masses are), an initial
``orientation``, ``velocity`` and ``angular_velocity``. ``Scene.rigid_bodies``
lists them (default none). On the device each body is a collider placed at
its current pose, whose surface moves at v + omega x r; the impulse the grid
rule (under the implicit integrator: the solve's constraints, the body's
velocity held during the solve) and the keep-out give the material at its
surface is summed as a force and a torque about its centre of mass, and
Newton (the ``newton`` package, imported only when a scene has rigid
bodies) advances the body with minus that, plus gravity, over the same step
(mpm.rigid_coupling). 2D bodies are planar: forces in the plane and torques
about z keep them there.
"""

from __future__ import annotations

import functools
import importlib.util
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from .colliders import Collider, as_vector3

SHAPES = ("box", "sphere", "cylinder", "mesh")
"""the shapes a rigid body may take (cylinder and mesh: 3D only)"""
SHAPES_2D = ("box", "sphere")


@dataclass(frozen=True)
class RigidBody:
    """One rigid body (module docstring): ``shape`` a Collider of type box,
    sphere, cylinder or mesh at rest (no velocity or angular_velocity of its
    own), ``density`` or ``mass`` (one of them), the initial
    ``orientation`` (2D: an angle [rad] about z; 3D: a rotation vector
    [rad]) about its centre, ``velocity`` [m/s] and ``angular_velocity``
    [rad/s] (2D: a number about z; 3D: a vector)."""

    shape: Collider
    """its shape, boundary and friction (a box, sphere or, in 3D, cylinder or mesh Collider)"""
    density: float | None = None
    """[kg/m^3] (None: from ``mass``)"""
    mass: float | None = None
    """[kg] (2D: per metre of depth; None: from ``density``)"""
    orientation: float | Sequence[float] | None = None
    """initial rotation about its centre: 2D an angle [rad], 3D a rotation vector (None: none)"""
    velocity: Sequence[float] | None = None
    """initial velocity of its centre of mass [m/s] (None: at rest)"""
    angular_velocity: float | Sequence[float] | None = None
    """initial angular velocity [rad/s]: 2D a number about z, 3D a vector (None: none)"""
    name: str = ""
    """a name for reports (default: the shape's type and index)"""

    def volume(self, dim: int) -> float:
        """[m^3] (2D: [m^2], the area, one metre deep)."""
        c = self.shape
        if c.type == "box":
            return float(np.prod(2.0 * np.asarray(c.half_size, float)))
        if c.type == "sphere":
            return np.pi * c.radius**2 if dim == 2 else 4.0 / 3.0 * np.pi * c.radius**3
        if c.type == "mesh":
            return self._solid[0]
        return np.pi * c.radius**2 * 2.0 * c.half_height

    @functools.cached_property
    def _solid(self) -> tuple[float, np.ndarray]:
        """A mesh body's (volume [m^3], centroid [m]) (mpm.meshes.solid_properties), computed once."""
        from .meshes import solid_properties

        assert self.shape.mesh is not None  # problems() checks
        return solid_properties(*self.shape.mesh.geometry)

    def total_mass(self, dim: int) -> float:
        """[kg] ``mass``, or ``density`` times the volume."""
        return float(self.mass) if self.mass is not None else float(self.density or 0.0) * self.volume(dim)

    def center(self) -> np.ndarray:
        """Its initial centre of mass [m] (the shape's centre; a mesh's centroid)."""
        if self.shape.type == "mesh":
            return self._solid[1]
        return np.asarray(self.shape.center, float)

    def solid(self) -> Collider:
        """Its shape as the collider the material meets, turning about the
        centre of mass (a mesh's centroid: its ``pivot``; the other shapes'
        centre already is)."""
        if self.shape.type == "mesh":
            return replace(self.shape, pivot=tuple(float(x) for x in self.center()))
        return self.shape

    def reach(self, dim: int) -> float:
        """[m] how far its surface reaches from its centre of mass (a box's
        half diagonal, a sphere's radius, a cylinder's rim, a mesh's farthest
        vertex)."""
        c = self.shape
        if c.type == "box":
            return float(np.linalg.norm(np.asarray(c.half_size, float)))
        if c.type == "sphere":
            return float(c.radius)
        if c.type == "cylinder":
            return float(np.hypot(c.radius, c.half_height))
        assert c.mesh is not None  # problems() checks
        return float(np.linalg.norm(c.mesh.geometry[0] - self.center(), axis=1).max())

    def surface_speed(self, dim: int) -> float:
        """[m/s] the fastest its surface moves at the start: |v| + |omega| reach."""
        v = np.asarray(self.velocity if self.velocity is not None else 0.0, float)
        return float(np.linalg.norm(v) + np.linalg.norm(self.spin(dim)) * self.reach(dim))

    def turned(self, dim: int) -> np.ndarray:
        """The initial orientation as a rotation vector (3 numbers; 2D about z)."""
        return as_vector3(self.orientation, dim)

    def spin(self, dim: int) -> np.ndarray:
        """The initial angular velocity as a 3-vector [rad/s]."""
        return as_vector3(self.angular_velocity, dim)

    def problems(self, dim: int, domain: Sequence[float]) -> list[tuple[str, str]]:
        """(field, message) for a shape, mass or motion that cannot be used."""
        c = self.shape
        if not isinstance(c, Collider) or c.type not in (SHAPES if dim == 3 else SHAPES_2D):
            kinds = ", ".join(SHAPES if dim == 3 else SHAPES_2D)
            return [("shape", f"{getattr(c, 'type', c)!r}; accepted in {dim}D: {kinds}")]
        out = [("shape." + k, m) for k, m in c.problems(dim)]
        if c.velocity is not None or c.angular_velocity is not None or c.inside or c.pivot is not None:
            out.append(("shape", "a moving, turning or inside-out shape; accepted: the body at rest (velocity, "
                                 "angular_velocity on the rigid body; no pivot: it turns about its centre "
                                 "of mass), inside false"))
        if (self.density is None) == (self.mass is None):
            out.append(("density", "give one of density [kg/m^3] or mass [kg]; accepted: exactly one"))
        for key in ("density", "mass"):
            value = getattr(self, key)
            if value is not None and not (np.isfinite(value) and value > 0.0):
                out.append((key, f"{value}; accepted: a finite number > 0"))
        if c.type != "mesh":
            sizes = [c.radius] if c.type != "box" else list(c.half_size or ())
            if c.type == "cylinder":
                sizes.append(c.half_height)
            if not all(np.isfinite(s) and s > 0.0 for s in sizes):
                out.append(("shape", f"{c.type} of size {sizes}; accepted: sizes > 0 [m]"))
        shape_ok = not any(k.startswith("shape") for k, _ in out)
        centre = c.center if c.type != "mesh" else (self.center() if shape_ok else None)
        if centre is not None and len(centre) == dim and not all(0.0 <= x <= L for x, L in zip(centre, domain)):
            key = "shape.center" if c.type != "mesh" else "shape.center (the mesh's centroid)"
            out.append((key, f"{[float(x) for x in centre]} lies outside the domain; accepted: a point in "
                             + " x ".join(f"[0, {L:g}]" for L in domain) + " [m]"))
        scalar = "a number [rad, rad/s] in 2D" if dim == 2 else "3 numbers [rad, rad/s] in 3D"
        for key, accepted, shape in (("velocity", f"{dim} finite numbers [m/s]", (dim,)),
                                     ("orientation", scalar, () if dim == 2 else (3,)),
                                     ("angular_velocity", scalar, () if dim == 2 else (3,))):
            value = getattr(self, key)
            if value is None:
                continue
            try:
                v = np.asarray(value, float)
            except (TypeError, ValueError):
                v = np.full(1, np.nan)
            if v.shape != shape or not np.all(np.isfinite(v)):
                out.append((key, f"{value!r}; accepted: {accepted}, finite"))
        return out


def scene_problems(scene) -> list[tuple[str, str]]:
    """(key, message) for the scene's rigid bodies: each one's problems, and
    the ``newton`` package missing where there is any."""
    bodies = getattr(scene, "rigid_bodies", None) or []
    out = [(f"rigid_bodies[{i}].{k}", m) for i, b in enumerate(bodies)
           for k, m in (b.problems(scene.dim, scene.domain) if isinstance(b, RigidBody)
                        else [("type", f"{type(b).__name__}; accepted: mpm.RigidBody")])]
    if bodies and importlib.util.find_spec("newton") is None:
        out.append(("rigid_bodies", "need the newton package, which is not installed; accepted: "
                                    "pip install 'newton>=1.8,<1.9', or no rigid bodies"))
    return out


def solids(scene) -> list[Collider]:
    """The scene's colliders, then each rigid body's shape (the packed
    records on the device in this order: rigid body b is collider
    ``len(scene.colliders) + b``)."""
    return list(scene.colliders) + [b.solid() for b in getattr(scene, "rigid_bodies", None) or []]
