"""Rigid colliders: static or moving solids other than the domain's walls.

A collider is a solid described by a signed distance phi(q) (negative inside
the solid) and its outward normal n(q) = grad phi. It acts on the grid at
the nodes where a body touches it, judged at the node's current position
q_i by the volume fractions of the solid and of the body there
(mpm.surface; ``Scene.boundary_rule`` "nodes": on every node inside it,
phi(q_i) < 0, as earlier versions did), after the walls and before the
kinematic regions (mpm.grid), so it works for every scheme and kernel; a
particle the grid lets into the solid is put back on its surface
(mpm.keep_out). With the collider's velocity u and the body's relative
velocity v_r = v - u at the surface point below the node (the node's own,
extrapolated by its velocity gradient where friction or a sticky collider
needs it, mpm.surface), v_n = v_r . n:

* ``sticky``:   v = u;
* ``slip``:     the normal part of v_r is removed (no separation either);
* ``separate``: as slip, but only when v_n < 0 (the body moves into the
  solid); a body moving away is left free (the boundary for bodies that
  roll or bounce);

and slip and separate apply Coulomb friction to the tangential part
v_t = v_r - v_n n: |v_t| shrinks by mu |v_n| and stops at zero,
    v = u + max(0, 1 - mu |v_n| / |v_t|) v_t;
the node's velocity changes by what the rule changes v by.

A collider may move with a constant ``velocity`` u [m/s] while
``start <= t < end`` [s]; its shape is then displaced by
u (clamp(t, start, end) - start). Over the same window it may also turn at
a constant ``angular_velocity`` omega [rad/s] (2D: a number, about z; 3D: a
vector) about a ``pivot`` [m] (default: the shape's ``center``, the
``point`` of a half-space or wedge, the mesh's centre) that moves with the
translation: at time t the shape is its rest shape turned by the angle
omega (clamp(t, start, end) - start) about the pivot, then displaced. Its
signed distance at q is the rest shape's at q mapped back (turned back about
the moved pivot), its normal the rest normal turned forward, and the
velocity of its surface at a point q_s is u + omega x (q_s - pivot(t)),
taken at the surface point q - phi n below a node or particle
(mpm.collider_motion). Only scenes with a turning collider compile the
rotation. Shapes (every one 2D and 3D except the mesh):

  half_space  the solid behind a plane through ``point`` with outward ``normal``
  wedge       the intersection of two half-spaces through ``point`` (a ridge)
  box         axis-aligned box ``center``, ``half_size``
  sphere      ball ``center``, ``radius`` (``inside: true``: a spherical container)
  cylinder    capped cylinder ``center``, ``radius``, ``half_height`` along ``axis``
  cup         open cylindrical cup: inner bottom centre ``center``, inner
              ``radius`` and ``depth``, wall ``thickness``, opening along ``axis``
  bowl        spherical cap shell: sphere ``center``, inner ``radius``,
              ``thickness``, cut by the rim plane ``rim`` [m] above the centre
              along ``axis`` (the opening)
  mesh        a closed triangle mesh (3D), placed as mpm.meshes.MeshShape

``inside: true`` turns any shape into a container (the solid is everything
outside it). The kernels compile only the shapes a scene has
(mpm.collider_device). A rigid body (mpm.rigid) is a box, sphere or
cylinder collider that its body moves: its record is rewritten from the
body's pose every step (mpm.rigid_coupling).
"""

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from .meshes import MeshShape

KINDS = ("half_space", "wedge", "box", "sphere", "cylinder", "cup", "bowl", "mesh")
"""the collider shapes (Collider.type); the module docstring says what each takes"""
TURNING = "turning"
"""the key the kernels add to the shapes present when a collider turns
(mpm.collider_device.kinds_of): only then is the rotation compiled"""
RIGID = "rigid"
"""the key the kernels add where a scene has rigid bodies (mpm.rigid): the
rotation is compiled with each record's current pose, and each collider's
angular impulse about its centre is summed"""
ELASTIC = "elastic"
"""the key the kernels add where a collider acts through springs (mpm.elastic_contact): only
then does the grid rule skip such colliders"""
BOUNDARIES = ("sticky", "slip", "separate", ELASTIC)
"""what a node inside a collider does (Collider.boundary; module docstring); elastic: the
particles that touch it, through springs (mpm.elastic_contact)"""
INSIDE_DEPTH = 1.0
"""a particle counts as inside a collider when deeper than this many cells:
under the surface rule none is inside at all after a step (mpm.keep_out);
under the node rule the nodes inside a collider stop particles within
about a cell of its surface (a fast splash particle in a container reached
0.3-0.85 cells deep, tests/mpm/test_colliders.py), so deeper ones have gone
through it"""


def _unit(v) -> tuple[float, ...]:
    v = np.asarray(v, float)
    return tuple(v / np.linalg.norm(v))


def rotation_of(angle, dim: int) -> np.ndarray:
    """The rotation by the rotation vector ``angle`` [rad] (3 numbers; 2D:
    its z component), as a dim x dim matrix."""
    angle = np.asarray(angle, float)
    if dim == 2:
        c, s = np.cos(angle[2]), np.sin(angle[2])
        return np.array([[c, -s], [s, c]])
    theta = float(np.linalg.norm(angle))
    if theta == 0.0:
        return np.eye(3)
    k = angle / theta
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * K + (1.0 - np.cos(theta)) * K @ K


def as_vector3(value, dim: int) -> np.ndarray:
    """A rotation given as in a scene (2D: one number about z; 3D: a vector;
    None: none) as a 3-vector."""
    if value is None:
        return np.zeros(3)
    if dim == 2:
        return np.array([0.0, 0.0, float(value)])
    return np.asarray(value, float)


def axis_vector(axis, dim: int) -> tuple[float, ...]:
    """A coordinate axis (0, 1, 2) or a direction vector, as a unit vector."""
    if isinstance(axis, (int, np.integer)):
        e = np.zeros(dim)
        e[int(axis)] = 1.0
        return tuple(e)
    return _unit(axis)


@dataclass(frozen=True)
class Collider:
    """One rigid collider of shape ``type`` (:data:`KINDS`; the module
    docstring says what each takes). Lengths in metres; ``normal``,
    ``normals`` and ``axis`` need not be unit length (``axis`` may also be a
    coordinate index). Build one with the constructor of its type
    (``Collider.half_space(point, normal, friction=0.3)``, ...), which take
    the keys every collider has as keywords: ``boundary`` ("slip"; also
    "sticky", "separate", :data:`BOUNDARIES`), ``friction`` (Coulomb mu, 0),
    ``name`` (""), ``inside`` (False; True: a container, the solid is the
    outside of the shape) and the motion ``velocity`` [m/s] (None: at rest)
    and ``angular_velocity`` [rad/s] about ``pivot`` [m] (None: no turning)
    while ``start`` (0 s) <= t < ``end`` (inf s). The same keys, with
    ``type``, describe a collider in a scene file (``scene.colliders``)."""

    type: str
    """the shape: half_space, wedge, box, sphere, cylinder, cup, bowl or mesh (KINDS)"""
    boundary: str = "slip"
    """what a node inside does: sticky, slip or separate (BOUNDARIES; module docstring); elastic:
    it acts on the particles that touch it, through springs (mpm.elastic_contact)"""
    friction: float = 0.0
    """Coulomb coefficient mu [-] of slip, separate and elastic"""
    stiffness: float = 0.5
    """an elastic collider's springs: this times the body's P-wave modulus times dx^(d-2) per particle
    (mpm.elastic_contact)"""
    damping: float = 0.0
    """an elastic collider's normal dashpot: this fraction zeta [-] of a particle's critical damping on its
    spring, 2 zeta sqrt(k m_p) (mpm.elastic_contact)"""
    name: str = ""
    """a name for the recording (default: the type and index)"""
    inside: bool = False
    """the solid is the outside of the shape (a container)"""
    point: Sequence[float] | None = None
    """a point of the plane(s) [m] (half_space, wedge)"""
    normal: Sequence[float] | None = None
    """the half-space's outward normal (any length)"""
    normals: Sequence[Sequence[float]] | None = None
    """the wedge's two outward normals"""
    center: Sequence[float] | None = None
    """the shape's centre [m] (box, sphere, cylinder, bowl; the cup's inner bottom centre)"""
    half_size: Sequence[float] | None = None
    """the box's half extents [m]"""
    radius: float = 0.0
    """[m] (sphere, cylinder; cup and bowl: inner)"""
    half_height: float = 0.0
    """the cylinder's half length along its axis [m]"""
    depth: float = 0.0
    """the cup's inner depth [m]"""
    thickness: float = 0.0
    """the wall thickness [m] (cup, bowl)"""
    rim: float = 0.0
    """the bowl's rim plane, its height above the centre along the axis [m]"""
    axis: int | Sequence[float] = 1
    """the axis of a cylinder, cup or bowl (the opening): 0, 1, 2 or a direction; default +y"""
    mesh: "MeshShape | None" = None
    """a closed triangle mesh placed in the scene (mpm.meshes.MeshShape, 3D)"""
    velocity: Sequence[float] | None = None
    """constant velocity [m/s] while start <= t < end (None: at rest)"""
    start: float = 0.0
    """when the motion starts [s]"""
    end: float = float("inf")
    """when it stops [s]"""
    angular_velocity: float | Sequence[float] | None = None
    """constant angular velocity [rad/s] while start <= t < end: 2D a number
    (about z, counter-clockwise), 3D a vector (None: no turning)"""
    pivot: Sequence[float] | None = None
    """the point [m] it turns about, at rest (None: the shape's centre, the
    half-space's or wedge's point, the mesh's centre); it moves with ``velocity``"""

    @classmethod
    def half_space(cls, point, normal, **keys) -> "Collider":
        """The solid behind the plane through ``point`` [m] with outward
        ``normal``: a floor, a wall or a slope."""
        return cls("half_space", point=tuple(point), normal=tuple(normal), **keys)

    @classmethod
    def wedge(cls, point, normals, **keys) -> "Collider":
        """The intersection of two half-spaces through ``point`` [m] with the
        outward ``normals`` (a ridge)."""
        return cls("wedge", point=tuple(point), normals=tuple(tuple(n) for n in normals), **keys)

    @classmethod
    def box(cls, center, half_size, **keys) -> "Collider":
        """An axis-aligned box, ``center`` and ``half_size`` [m]."""
        return cls("box", center=tuple(center), half_size=tuple(half_size), **keys)

    @classmethod
    def sphere(cls, center, radius: float, **keys) -> "Collider":
        """A ball (a disc in 2D), ``center`` and ``radius`` [m]; ``inside=True``:
        a spherical container."""
        return cls("sphere", center=tuple(center), radius=radius, **keys)

    @classmethod
    def cylinder(cls, center, radius: float, half_height: float, axis=1, **keys) -> "Collider":
        """A capped cylinder, ``center``, ``radius`` and ``half_height`` [m]
        along ``axis`` (default +y)."""
        return cls("cylinder", center=tuple(center), radius=radius, half_height=half_height, axis=axis, **keys)

    @classmethod
    def cup(cls, center, radius: float, depth: float, thickness: float, axis=1, **keys) -> "Collider":
        """An open cylindrical cup: inner bottom ``center``, inner ``radius``
        and ``depth``, wall ``thickness`` [m], opening along ``axis`` (default +y)."""
        return cls("cup", center=tuple(center), radius=radius, depth=depth, thickness=thickness, axis=axis, **keys)

    @classmethod
    def bowl(cls, center, radius: float, thickness: float, rim: float, axis=1, **keys) -> "Collider":
        """A spherical-cap shell: sphere ``center``, inner ``radius``,
        ``thickness``, cut by the rim plane ``rim`` [m] above the centre along
        ``axis`` (the opening, default +y)."""
        return cls("bowl", center=tuple(center), radius=radius, thickness=thickness, rim=rim, axis=axis, **keys)

    @classmethod
    def from_mesh(cls, mesh, **keys) -> "Collider":
        """A closed triangle mesh (3D), placed as an mpm.meshes.MeshShape."""
        return cls("mesh", mesh=mesh, **keys)

    def problems(self, dim: int) -> list[tuple[str, str]]:
        """(field, message) for a type, boundary or geometry that cannot be used."""
        if self.type not in KINDS:
            return [("type", f"{self.type!r}; accepted: {', '.join(KINDS)}")]
        out = []
        if self.boundary not in BOUNDARIES:
            out.append(("boundary", f"{self.boundary!r}; accepted: {', '.join(BOUNDARIES)}"))
        need = {"half_space": ("point", "normal"), "wedge": ("point", "normals"), "box": ("center", "half_size"),
                "sphere": ("center",), "cylinder": ("center",), "cup": ("center",), "bowl": ("center",),
                "mesh": ("mesh",)}[self.type]
        out += [(k, f"missing for a {self.type}; accepted: {'a mesh' if k == 'mesh' else f'{dim} numbers'}")
                for k in need if getattr(self, k) is None]
        if self.type == "mesh" and dim != 3:
            out.append(("type", f"mesh in {dim}D; accepted: mesh colliders in 3D only"))
        if not (self.friction >= 0.0):
            out.append(("friction", f"{self.friction}; accepted: a number >= 0"))
        if not (0.0 < self.stiffness <= 4.0):
            out.append(("stiffness", f"{self.stiffness}; accepted: 0 < stiffness <= 4 (the springs' step "
                                     "stays within the wave's)"))
        if not (0.0 <= self.damping <= 1.0):
            out.append(("damping", f"{self.damping}; accepted: 0 <= damping <= 1 (a fraction of the critical)"))
        return out + self._motion_problems(dim)

    def _motion_problems(self, dim: int) -> list[tuple[str, str]]:
        """The velocity, angular velocity and pivot: sized for ``dim``, finite."""
        out = []
        spin = "a number (about z) [rad/s] in 2D" if dim == 2 else "3 numbers [rad/s] in 3D"
        for key, value, accepted, scalar in (("velocity", self.velocity, f"{dim} finite numbers [m/s]", False),
                                            ("angular_velocity", self.angular_velocity, f"{spin}, finite", dim == 2),
                                            ("pivot", self.pivot, f"{dim} finite numbers [m]", False)):
            if value is None:
                continue
            try:
                v = np.asarray(value, float)
            except (TypeError, ValueError):
                out.append((key, f"{value!r}; accepted: {accepted}"))
                continue
            if (v.ndim != 0 if scalar else v.shape != (3 if key == "angular_velocity" else dim,)):
                out.append((key, f"{value!r}; accepted: {accepted}"))
            elif not np.all(np.isfinite(v)):
                out.append((key, f"{value!r} is not finite; accepted: {accepted}"))
        return out

    @property
    def turns(self) -> bool:
        """Whether it has an angular velocity (zero counts: the scene compiles the rotation)."""
        return self.angular_velocity is not None

    def omega(self, dim: int) -> np.ndarray:
        """The angular velocity [rad/s] as a 3-vector (2D: about z; zero when not turning)."""
        return as_vector3(self.angular_velocity, dim)

    def rest_pivot(self, dim: int) -> tuple[float, ...]:
        """The point it turns about, at rest [m] (``pivot`` or its default)."""
        if self.pivot is not None:
            return tuple(float(x) for x in self.pivot)
        if self.type in ("half_space", "wedge") and self.point is not None:
            return tuple(float(x) for x in self.point)
        if self.type == "mesh" and self.mesh is not None:
            return tuple(float(x) for x in self.mesh.center)
        return tuple(float(x) for x in self.center) if self.center is not None else (0.0,) * dim

    def speed(self, domain: Sequence[float] | None = None) -> float:
        """The fastest its surface moves over ``domain`` [m] (the box from the
        origin; None: the translation alone) [m/s]: |u| and, turning,
        |omega| times the farthest corner of the domain from the pivot."""
        u = float(np.linalg.norm(self.velocity)) if self.velocity is not None else 0.0
        if not self.turns or domain is None:
            return u
        dim = len(domain)
        corners = np.array(np.meshgrid(*[(0.0, L) for L in domain])).reshape(dim, -1).T
        reach = float(np.linalg.norm(corners - np.asarray(self.rest_pivot(dim)), axis=1).max())
        return u + float(np.linalg.norm(self.omega(dim))) * reach

    def rotation(self, t: float, dim: int) -> np.ndarray:
        """The rotation matrix of the shape at time ``t`` [s] (identity when not turning)."""
        angle = self.omega(dim) * (min(max(t, self.start), self.end) - self.start)
        return rotation_of(angle, dim)

    def offset(self, t: float) -> np.ndarray | float:
        """Displacement of the shape at time ``t`` [s] (0.0 for a collider at rest)."""
        if self.velocity is None:
            return 0.0
        return np.asarray(self.velocity, float) * (min(max(t, self.start), self.end) - self.start)

    def pose(self, t: float, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """(R, b): a point q of the rest shape is at R q + b at time ``t`` [s]
        (R the rotation about the pivot, b = p + s(t) - R p)."""
        R = self.rotation(t, dim)
        p = np.asarray(self.rest_pivot(dim))
        return R, p + self.offset(t) - R @ p

    def place(self, q: np.ndarray, t: float) -> np.ndarray:
        """Points ``q`` [m] of the rest shape moved to where they are at time ``t`` [s]."""
        q = np.asarray(q, float)
        R, b = self.pose(t, q.shape[-1])
        return q @ R.T + b

    def record(self, dim: int) -> dict:
        """The packed fields of mpm.collider_device.make_collider_data (numbers only)."""
        z = (0.0,) * dim
        r = dict(kind=KINDS.index(self.type), boundary=BOUNDARIES.index(self.boundary),
                 friction=self.friction, stiffness=self.stiffness, damping=self.damping, invert=int(self.inside),
                 p=z, n0=z, n1=z, h=z,
                 r=self.radius, a=0.0, w=self.thickness, u=tuple(self.velocity or z),
                 window=(self.start, min(self.end, 1e30)), omega=tuple(self.omega(dim)), pivot=self.rest_pivot(dim))
        if self.type in ("half_space", "wedge"):
            assert self.point is not None, "checked by problems()"
            r["p"] = tuple(self.point)
            if self.type == "half_space":
                r["n0"] = _unit(self.normal)
            else:
                assert self.normals is not None, "checked by problems()"
                r["n0"], r["n1"] = _unit(self.normals[0]), _unit(self.normals[1])
        else:
            r["p"] = tuple(self.center) if self.center is not None else z
        if self.type == "box":
            assert self.half_size is not None, "checked by problems()"
            r["h"] = tuple(self.half_size)
        if self.type in ("cylinder", "cup", "bowl"):
            r["n0"] = axis_vector(self.axis, dim)
            r["a"] = {"cylinder": self.half_height, "cup": self.depth, "bowl": self.rim}[self.type]
        return r
