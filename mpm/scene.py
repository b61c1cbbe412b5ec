"""Plain description of a scene: domain, walls, gravity and bodies.

Coordinates are in metres; the domain is the box [0, domain[d]] per axis,
covered by a regular grid of spacing ``dx = domain[0] / resolution``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, Sequence, Union

import numpy as np

from .colliders import Collider
from .joints import Joint
from .rigid import RigidBody
from .materials import Material

CONTACT_TYPES = ("frictionless", "friction", "none", "shared", "elastic")
"""between bodies (Scene.contact): frictionless (mpm.contact), friction
(Coulomb, ``Scene.contact_friction`` and ``Scene.contact_pairs``), none
(they pass through each other), shared (EMPM only: one grid for all
bodies) or elastic (springs on the particles that touch, with Coulomb
friction as ``friction``'s: mpm.body_springs)"""
CONTACT_NORMALS = ("difference", "max_gradient", "stiffer")
"""How a body's outward normal at a lattice node is taken (``Scene.contact_normal``):
"difference", normalize(grad(M_others - M_b)), the bisector of the bodies'
own normals; "max_gradient", the normal of the body present whose volume
gradient |grad M_c| / (rho_c dx^d) is the largest (Nairn 2013, Comput.
Model. Eng. Sci. 92, 271-299): a flat face keeps its own normal where the
corner of another body rests on it, unless the corner's gradient is the
larger; "stiffer", the normal of the stiffest body present (the largest
P-wave modulus rho c^2 at rest, c the material's wave speed: a master
surface, as in master-slave contact), bodies of equal stiffness by the
largest volume gradient: a face keeps its normal under a softer body's
corner or curve, which would otherwise turn sliding into approach and
drag."""
BOUNDARY_RULES = ("surface", "nodes")
"""Where walls and colliders act (Scene.boundary_rule): "surface", on the
nodes where a body touches the solid, judged by the two volume fractions
(mpm.surface), so a surface acts where it lies between the nodes;
"nodes", on every node inside the solid (a wall: the first wall_cells
lattice nodes), the rule of earlier versions, kept to reproduce their
results"""
WALL_TYPES = ("sticky", "slip", "open")
"""sticky: grid velocity set to zero; slip: the velocity component into the
wall is removed (tangential motion and separation are free); open: no wall."""


@dataclass(frozen=True)
class Box:
    """Axis-aligned box (a rectangle in 2D)."""

    center: tuple[float, ...]
    """[m]"""
    half_size: tuple[float, ...]
    """half the extent along each axis [m]"""

    def bounds(self):
        c, h = np.asarray(self.center, float), np.asarray(self.half_size, float)
        return c - h, c + h

    def contains(self, x: np.ndarray) -> np.ndarray:
        lo, hi = self.bounds()
        return np.all((x >= lo) & (x <= hi), axis=1)


@dataclass(frozen=True)
class Sphere:
    """Ball (a disc in 2D); a shell (a ring in 2D) when ``inner_radius`` > 0."""

    center: tuple[float, ...]
    """[m]"""
    radius: float
    """[m]"""
    inner_radius: float = 0.0

    def bounds(self):
        c = np.asarray(self.center, float)
        return c - self.radius, c + self.radius

    def contains(self, x: np.ndarray) -> np.ndarray:
        r2 = np.sum((x - np.asarray(self.center)) ** 2, axis=1)
        return (r2 <= self.radius**2) & (r2 >= self.inner_radius**2)


@dataclass(frozen=True)
class Cylinder:
    """Circular cylinder along coordinate axis ``axis`` (3D only); hollow
    (a tube) when ``inner_radius`` > 0."""

    center: tuple[float, ...]
    """[m]"""
    radius: float
    """[m]"""
    half_height: float
    """half the length along ``axis`` [m]"""
    axis: int = 1
    inner_radius: float = 0.0

    def bounds(self):
        c = np.asarray(self.center, float)
        h = np.full(3, self.radius)
        h[self.axis] = self.half_height
        return c - h, c + h

    def contains(self, x: np.ndarray) -> np.ndarray:
        d = x - np.asarray(self.center)
        along = d[:, self.axis]
        radial2 = np.sum(d**2, axis=1) - along**2
        return ((np.abs(along) <= self.half_height) & (radial2 <= self.radius**2)
                & (radial2 >= self.inner_radius**2))


@dataclass(frozen=True)
class Bowl:
    """Spherical cap shell: the points between ``radius`` and ``radius +
    thickness`` from ``center`` that lie below the rim plane ``rim`` [m]
    above the centre along coordinate ``axis`` (the opening); an arc in 2D."""

    center: tuple[float, ...]
    radius: float
    thickness: float
    """the shell's thickness outside ``radius`` [m]"""
    rim: float
    axis: int = 1

    def bounds(self):
        c = np.asarray(self.center, float)
        R = self.radius + self.thickness
        lo, hi = c - R, c + R
        hi[self.axis] = c[self.axis] + min(self.rim, R)
        return lo, hi

    def contains(self, x: np.ndarray) -> np.ndarray:
        d = x - np.asarray(self.center)
        r2 = np.sum(d**2, axis=1)
        return ((r2 >= self.radius**2) & (r2 <= (self.radius + self.thickness) ** 2)
                & (d[:, self.axis] <= self.rim))


@dataclass(frozen=True)
class Compound:
    """Union of shapes, filled as one body (e.g. a bunny hanging from a cord)."""

    parts: tuple
    """the shapes (Box, Sphere, Cylinder, Bowl, mpm.MeshShape, ...)"""

    def bounds(self):
        lo, hi = zip(*(p.bounds() for p in self.parts))
        return np.min(lo, axis=0), np.max(hi, axis=0)

    def contains(self, x: np.ndarray) -> np.ndarray:
        inside = np.zeros(len(x), bool)
        for part in self.parts:
            inside |= part.contains(x)
        return inside

    @property
    def center(self):
        lo, hi = self.bounds()
        return tuple(0.5 * (lo + hi))


def rotation_matrix(angles, dim: int) -> np.ndarray:
    """Rotation by ``angles`` [degrees]: a scalar in 2D (counter-clockwise),
    three in 3D applied about x, then y, then z (R = Rz Ry Rx)."""
    if dim == 2:
        a = np.radians(float(angles))
        return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    ax, ay, az = np.radians(np.asarray(angles, float))
    Rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    Ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    Rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


class _Shape(Protocol):
    """What a turned shape offers: its centre, its bounds and an inside test."""

    @property
    def center(self) -> Sequence[float]: ...

    def bounds(self) -> tuple: ...

    def contains(self, x: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True, eq=False)
class Rotated:
    """``shape`` turned by the rotation matrix ``R`` about its centre
    (``Rotated(shape, rotation_matrix(angles, dim))``)."""

    shape: _Shape
    """the shape turned (any shape of a body)"""
    R: np.ndarray
    """d x d rotation matrix (:func:`rotation_matrix`)"""

    @property
    def center(self):
        return tuple(self.shape.center)

    def bounds(self):
        """Exact for meshes and spheres, else the turned bounding box's bounds."""
        lo, hi = (np.asarray(b, float) for b in self.shape.bounds())
        if isinstance(self.shape, Sphere):
            return lo, hi
        c = np.asarray(self.center, float)
        d = len(lo)
        geometry = getattr(self.shape, "geometry", None)  # mpm.meshes.MeshShape's (points, triangles)
        if geometry is not None:
            pts = geometry[0]
        else:
            pts = np.array([[hi[k] if (i >> k) & 1 else lo[k] for k in range(d)] for i in range(2**d)])
        turned = c + (pts - c) @ self.R.T
        return turned.min(axis=0), turned.max(axis=0)

    def contains(self, x: np.ndarray) -> np.ndarray:
        c = np.asarray(self.center, float)
        return self.shape.contains(c + (x - c) @ self.R)


Shape = Union[Box, Sphere, Cylinder, Bowl, Compound, Rotated]


def skew(w, dim: int) -> np.ndarray:
    """The matrix W with W r = w x r for an angular velocity w [rad/s] (a
    scalar in 2D, a 3-vector in 3D)."""
    if dim == 2:
        return np.array([[0.0, -float(w)], [float(w), 0.0]])
    wx, wy, wz = (float(c) for c in w)
    return np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]])


@dataclass
class KinematicRegion:
    """Particles of body ``body`` whose initial position lies inside ``select``
    move with a prescribed velocity field while ``start <= t < end``:
        v(q, t) = velocity + angular_velocity x (q - c(t)) + G (q - c(t)),
        c(t) = center + velocity (t - start),
    imposed as the velocity of every grid node that draws at least half its
    mass from them (mpm.grid). ``angular_velocity`` [rad/s] is a scalar in 2D,
    a vector in 3D; ``velocity_gradient`` G [1/s] (d x d, in current
    coordinates) adds a homogeneous stretch or shear (a material test at
    prescribed deformation); ``center`` defaults to the centre of ``select``."""

    body: int
    select: Shape
    name: str = ""
    """a name for reports and the recording (default: region<index>)"""
    velocity: Sequence[float] | None = None
    """the translation velocity [m/s] (None: 0)"""
    angular_velocity: float | Sequence[float] | None = None
    center: Sequence[float] | None = None
    start: float = 0.0
    """[s]"""
    end: float = float("inf")
    """[s]; after it the particles move freely"""
    velocity_gradient: Sequence[Sequence[float]] | None = None

    def gradient(self, dim: int) -> np.ndarray:
        """The velocity gradient of the prescribed field [1/s]: the skew matrix
        of the angular velocity plus ``velocity_gradient``."""
        G = np.zeros((dim, dim)) if self.velocity_gradient is None else \
            np.array(self.velocity_gradient, float).reshape(dim, dim)
        if self.angular_velocity is not None:
            G = G + skew(self.angular_velocity, dim)
        return G


@dataclass
class Body:
    """One object: a shape filled with particles of one material.

    ``velocity`` [m/s] and ``angular_velocity`` [rad/s] (a scalar in 2D, a
    vector in 3D, about the shape's centre) set the initial rigid motion.
    ``deformation`` (d x d rows) is an initial deformation gradient F: the
    particles are sampled in the shape (the reference configuration, which
    sets their volume and mass) and placed at x = c + F (X - c), c the
    shape's centre, with F as their elastic deformation (det F < 0: an
    inverted body).
    """

    shape: Shape
    """where its particles are sampled (Box, Sphere, Cylinder, Bowl, Compound, mpm.MeshShape)"""
    material: Material
    """its constitutive model and parameters (mpm.MATERIALS)"""
    name: str = ""
    """a name for reports and the recording (default: body<index>)"""
    velocity: Sequence[float] | None = None
    angular_velocity: float | Sequence[float] | None = None
    ppc: int | None = None
    """particles per cell of this body (default: the scene's ``ppc``)"""
    deformation: Sequence[Sequence[float]] | None = None
    sampling: str = "lattice"
    """how its particles are placed (mpm.sampling.SAMPLINGS): "lattice", the
    grid's sub-lattice cut by the shape; "shells", concentric layers one
    sampling spacing (dx^d / ppc)^(1/d) apart for a Sphere (a ball in 3D, a
    disc in 2D), the outermost half a spacing inside its surface, each
    particle its layer's exact volume over its count (no jitter, no lattice
    offset, whatever ``particle_volume``)"""


@dataclass(frozen=True)
class ContactPair:
    """Two bodies (indices into ``Scene.bodies``) and the Coulomb coefficient
    mu of their contact (``Scene.contact = "friction"``)."""

    a: int
    """the first body [index]"""
    b: int
    """the second body [index]"""
    friction: float
    """Coulomb mu of their contact"""


class Solution(Protocol):
    """A closed-form solution as a scene reads it (mpm.analytic): the velocity
    v(X, t) [m/s] (n, d) and its gradient (n, d, d) [1/s] at points X (n, d) [m]."""

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray: ...

    def velocity_gradient(self, X: np.ndarray, t: float) -> np.ndarray: ...


@dataclass
class Scene:
    """Domain, grid, walls, gravity and bodies of a run. The domain is the
    box [0, domain[a]] along each axis a; the grid has ``resolution`` cells
    along x (dx = domain[0] / resolution) and as many cells of that width
    along the other axes as the domain holds (a multiple of dx)."""

    dim: int
    """2 or 3"""
    domain: tuple[float, ...]
    """the domain's extent per axis [m]"""
    resolution: int
    """grid cells along x"""
    bodies: list[Body]
    """the objects (at least one)"""
    gravity: tuple[float, ...] = (0.0, -9.81)
    """[m/s^2]"""
    walls: tuple[str, ...] = ("slip", "slip", "slip", "slip")
    """wall type per face: (x_lo, x_hi, y_lo, y_hi[, z_lo, z_hi])"""
    wall_cells: int = 3
    """wall thickness [cells]: a wall's face lies this far inside the domain's face (mpm.walls)"""
    boundary_rule: str = "surface"
    """where walls and colliders act (BOUNDARY_RULES): "surface" (where a body touches the solid) or
    "nodes" (on the nodes inside the solid, as earlier versions did)"""
    ppc: int = 4
    """particles per cell (total, not per axis); a perfect d-th power samples a
    regular sub-lattice, anything else uniform random points per cell"""
    jitter: float = 0.0
    """random displacement of lattice samples, as a fraction of their spacing"""
    lattice_offset: Sequence[float] | None = None
    """shift of the regular sampling lattice per axis [sampling cells]: with
    ppc = 1, (0.5, 0.5) puts the particles on grid nodes and (0.5, 0) on
    cell faces (default: sub-cell centres)"""
    contact: str = "frictionless"
    """between bodies: "frictionless" (mpm.contact), "none" (they pass through)
    or "shared" (Eulerian scheme only: all bodies on one grid, as in standard
    MPM, where bodies whose stencils overlap move together)"""
    contact_stiffness: float = 0.5
    """``contact="elastic"``: the springs' stiffness over the softer body's P-wave modulus (mpm.body_springs)"""
    contact_fill: float = 0.5
    """volume fraction of a global node that the bodies present must fill for contact"""
    contact_friction: float = 0.0
    """Coulomb coefficient mu between bodies (``contact="friction"``): every pair's, unless ``contact_pairs``
    names it"""
    contact_pairs: list[ContactPair] = field(default_factory=list)
    """pairs of bodies with their own Coulomb coefficient (``contact="friction"``)"""
    contact_normal: str = "difference"
    """how the bodies' normals at a lattice node are taken (CONTACT_NORMALS): "difference"
    (the bisector of the bodies' own normals), "max_gradient" (the normal of the body with the largest
    volume gradient there) or "stiffer" (the stiffest body's there; equals by the largest gradient)"""
    contact_share: float = 0.0
    """the volume fraction a body must fill at a lattice node to take part in contact there (0: any mass);
    above the fraction a stencil's fringe leaves beside a body (about 0.02), a body's side does not touch
    a face it slides along"""
    regions: list[KinematicRegion] = field(default_factory=list)
    """kinematic boundary regions (anchors, prescribed rotation and translation)"""
    colliders: list[Collider] = field(default_factory=list)
    """rigid colliders other than the walls (mpm.colliders)"""
    rigid_bodies: list[RigidBody] = field(default_factory=list)
    """rigid bodies the material pushes back, advanced by Newton (mpm.rigid; default none)"""
    joints: list[Joint] = field(default_factory=list)
    """joints holding rigid bodies to the world or to one another (mpm.joints; default none)"""
    rigid_contact: str = "none"
    """what rigid bodies meet besides the material (mpm.rigid_contact.RIGID_CONTACTS): "none", "walls" (the
    closed walls' faces) or "all" (the walls and each other)"""
    rigid_contact_stiffness: float = 1.0e5
    """penalty stiffness of a rigid body's contact point [N/m; 2D: per metre of depth] (mpm.rigid_contact)"""
    rigid_contact_damping: float = 1.0e3
    """penalty damping of a rigid body's contact point [N s/m; 2D: per metre of depth] (mpm.rigid_contact)"""
    loads: list = field(default_factory=list)
    """external loads: point loads, tractions, body forces (mpm.loads.Load)"""
    particle_volume: str = "shape"
    """the particles' volumes (and masses, rho V_p): "shape", a body's exact
    volume shared equally among its particles where the shape has one, else
    its cells'; "cells", dx^d / ppc each (mpm.sampling.PARTICLE_VOLUMES)"""
    particle_resolution: int | None = None
    """particles are sampled as if the grid had this many cells along x
    (default: ``resolution``): a fixed particle set for grid-refinement studies"""
    solution: Solution | None = None
    """a closed-form solution (``mpm.analytic``): it sets the initial velocity
    and, for a manufactured solution, the body force"""

    @property
    def dx(self) -> float:
        return self.domain[0] / self.resolution

    @property
    def particle_dx(self) -> float:
        """Sampling cell [m]: each particle stands for particle_dx^dim / ppc."""
        return self.domain[0] / (self.particle_resolution or self.resolution)

    def spacings(self) -> list[float]:
        """Per body, the distance between neighbouring particles at sampling [m], (particle_dx^d / ppc)^(1/d)."""
        return [(self.particle_dx**self.dim / (b.ppc or self.ppc)) ** (1.0 / self.dim) for b in self.bodies]

    @property
    def cells(self) -> tuple[int, ...]:
        return tuple(int(round(L / self.dx)) for L in self.domain)

    def friction_table(self) -> np.ndarray:
        """mu between bodies a and b at [a, b] (symmetric): ``contact_friction``
        unless ``contact_pairs`` names the pair."""
        n = len(self.bodies)
        mu = np.full((n, n), float(self.contact_friction))
        for p in self.contact_pairs:
            mu[p.a, p.b] = mu[p.b, p.a] = p.friction
        return mu
