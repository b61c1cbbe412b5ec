"""The ``scene`` group: the domain, its bodies, kinematic regions, colliders
and closed-form solution, each defined once here (shapes and colliders in
their own modules), and the :class:`mpm.Scene` they build. A scene's file in
``conf/scene/`` holds values only."""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Dict, List, Optional, cast

import numpy as np
from omegaconf import MISSING, OmegaConf

import mpm
from mpm.loads import LOAD_KINDS, Load
from mpm.materials import Material
from mpm.responses import QUANTITIES, REDUCTIONS
from mpm.sampling import PARTICLE_VOLUMES, SAMPLINGS
from mpm.scene import BOUNDARY_RULES, CONTACT_NORMALS, CONTACT_TYPES, WALL_TYPES

from .colliders import ColliderConfig, COLLIDERS, JointConfig, RigidBodyConfig
from .fields import ConfigError, Context, Family, check, choice, given, number, plain, setting, vector
from .physics import MATERIAL
from .shapes import SHAPES, ShapeConfig, fixed_shape

CONF = Path(__file__).resolve().parents[2] / "conf"
__all__ = ["BodyConfig", "ColliderConfig", "LoadConfig", "RegionConfig", "SceneConfig", "ShapeConfig", "make_scene"]


def angular(key: str, w, ctx: Context):
    """[rad/s]: a scalar in 2D, a 3-vector in 3D."""
    return number(key, w) if ctx.dim == 2 else vector(key, w, 3)


def matrix(key: str, value, ctx: Context):
    """A d x d matrix given as d rows."""
    d = ctx.dim
    if not isinstance(value, (list, tuple)) or len(value) != d:
        raise ConfigError(key, f"{value!r}; accepted: {d} rows of {d} numbers")
    return tuple(vector(f"{key}[{i}]", row, d) for i, row in enumerate(value))


def walls(key: str, value, ctx: Context) -> tuple:
    """One wall type for every face, or one per face (x_lo, x_hi, y_lo, ...)."""
    n = 2 * ctx.dim
    values = [value] * n if isinstance(value, str) else value
    if not isinstance(values, list) or len(values) != n:
        raise ConfigError(key, f"{value!r}; accepted: one of {', '.join(WALL_TYPES)}, "
                               f"or a list of {n} (x_lo, x_hi, y_lo, ...)")
    return tuple(choice(f"{key}[{i}]", w, WALL_TYPES) for i, w in enumerate(values))


def body_ref(key: str, value, ctx: Context):
    """A body's index or name (checked against the scene's bodies later); null
    where the field allows it (a load on every body)."""
    if value is None:
        return None
    return value if isinstance(value, str) else number(key, value, int, {"keyed": True, "ge": 0})


def body_pair(key: str, value, ctx: Context):
    """Two bodies, each an index or a name (checked against the scene's bodies later)."""
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(key, f"{plain(value)}; accepted: two bodies, each an index or a name")
    return [body_ref(f"{key}[{i}]", v, ctx) for i, v in enumerate(value)]


@dataclass
class ContactPairConfig:
    """Two bodies and the Coulomb coefficient of their contact (scene.contact=friction)."""

    bodies: List[Any] = setting([], "the two bodies: indices or names", parse=body_pair)
    friction: float = setting(0.0, "Coulomb mu of their contact", ge=0.0)


@dataclass
class ResponseConfig:
    """A physical response the run measures (mpm.responses): ``quantity`` of
    ``body``'s particles (null: every body's), reduced over the run by
    ``reduce``; metrics.json ``responses`` and the sweep report's response plots."""

    name: str = setting(MISSING, "the response's name (metrics.json, the sweep report)")
    quantity: str = setting("center_y", "per state: " + "; ".join(f"{k}, {v}" for k, v in QUANTITIES.items()),
                            choices=tuple(QUANTITIES))
    body: Optional[Any] = setting(None, "a body's index or name; null: every body", parse=body_ref)
    reduce: str = setting("max", "over the run: " + "; ".join(f"{k}, {v}" for k, v in REDUCTIONS.items()),
                          choices=tuple(REDUCTIONS))


@dataclass
class BodyConfig:
    """One body: a shape filled with particles of one material."""

    name: str = setting("", "the body's name; empty: body<i>")
    shape: ShapeConfig = setting(ShapeConfig(), "the shape the particles fill", family=SHAPES)
    material: Optional[Any] = setting(None, "null: the material group; a mapping with a model key: the "
                                            "body's own material", family=MATERIAL)
    velocity: Optional[List[float]] = setting(None, "initial velocity [m/s]", size="dim")
    angular_velocity: Optional[Any] = setting(None, "initial spin about the shape's centre [rad/s]: a scalar "
                                                    "(2D) or a 3-vector (3D)", parse=angular)
    ppc: Optional[int] = setting(None, "particles per cell; null: the scene's", ge=1)
    deformation: Optional[Any] = setting(None, "initial deformation gradient F, d rows of d numbers (det F < 0: "
                                               "inverted)", parse=matrix)
    sampling: str = setting("lattice", "how the particles are placed: lattice (the grid's sub-lattice, any shape) or "
                                       "shells (concentric layers, a sphere shape only)", choices=SAMPLINGS)


@dataclass
class RegionConfig:
    """A kinematic boundary region: the particles of ``body`` whose initial
    position is inside ``select`` move with ``velocity``, ``angular_velocity``
    and ``velocity_gradient`` about ``center`` while start <= t < end."""

    name: str = setting("", "a name for the recording")
    body: Any = setting(0, "the body: its index or name", parse=body_ref)
    select: ShapeConfig = setting(ShapeConfig(), "the initial positions it takes (no random rotation)",
                                  parse=fixed_shape)
    velocity: Optional[List[float]] = setting(None, "[m/s]", size="dim")
    angular_velocity: Optional[Any] = setting(None, "[rad/s]: a scalar (2D) or a 3-vector (3D)", parse=angular)
    velocity_gradient: Optional[Any] = setting(None, "[1/s] d rows of d numbers: a homogeneous stretch or shear",
                                               parse=matrix)
    center: Optional[List[float]] = setting(None, "[m]; null: the centre of select, moving with the velocity",
                                            size="dim")
    start: float = setting(0.0, "[s] when the motion starts", ge=0.0)
    end: Optional[float] = setting(None, "[s] when it ends; null: never")

    def problems(self):
        if self.end is not None and not self.end > self.start:
            return [("end", f"{self.end} out of range; accepted: end > start ({self.start})")]
        return []


def profile_table(key: str, value, ctx: Context):
    """Rows [t - start (s), factor]: times >= 0 and non-decreasing."""
    if not isinstance(value, (list, tuple)) or not value:
        raise ConfigError(key, f"{value!r}; accepted: a list of [t - start (s), factor] rows")
    rows = [vector(f"{key}[{i}]", row, 2) for i, row in enumerate(value)]
    for i, (a, b) in enumerate(zip(rows, rows[1:])):
        if b[0] < a[0]:
            raise ConfigError(f"{key}[{i + 1}]", f"time {b[0]} before the row above's {a[0]}; accepted: "
                                                 "non-decreasing times")
    if rows[0][0] < 0.0:
        raise ConfigError(f"{key}[0]", f"time {rows[0][0]}; accepted: >= 0 (after start)")
    return rows


@dataclass
class LoadConfig:
    """An external load (mpm.loads): a point load, a traction on a face or a
    body force on a region, scaled in time by its profile (constant, a ramp
    or a table) while start <= t < end."""

    name: str = setting("", "a name for the recording")
    kind: str = setting("point", "point (a total force [N]; 2D: N per m of depth), traction (force per area "
                                 "[Pa] on a face) or body (force per volume [N/m^3])", choices=LOAD_KINDS)
    force: List[float] = setting([0.0, 0.0], "the force, traction or force density at factor 1", size="dim")
    body: Any = setting(None, "the body: its index or name; null: every body", parse=body_ref)
    select: Optional[ShapeConfig] = setting(None, "the initial positions it takes (traction: the face is its "
                                                  "outermost layer along normal; body: null takes the whole "
                                                  "body)", parse=fixed_shape)
    at: Optional[List[float]] = setting(None, "[m] a point load on the count particles nearest this point",
                                        size="dim")
    count: int = setting(1, "the particles a point load at 'at' is shared by", ge=1)
    normal: Optional[List[float]] = setting(None, "a traction's face: its outward normal", size="dim")
    area: Optional[float] = setting(None, "a traction's face area [m^2; 2D: m] its particles' areas are scaled "
                                          "to; null: sum V_p / s (exact for a face spanning whole sampling "
                                          "spacings)", gt=0.0)
    start: float = setting(0.0, "[s] when the load starts", ge=0.0)
    end: Optional[float] = setting(None, "[s] when it ends; null: never")
    ramp: float = setting(0.0, "[s] a linear rise from 0 to the full load; 0: sudden", ge=0.0)
    table: Optional[Any] = setting(None, "rows [t - start (s), factor] interpolated linearly, held at both "
                                         "ends (instead of ramp)", parse=profile_table)

    def problems(self):
        if self.end is not None and not self.end > self.start:
            return [("end", f"{self.end} out of range; accepted: end > start ({self.start})")]
        return []


# ------------------------------------------------------------------ closed-form solutions (mpm.analytic)
def _one_elastic_box(kind: str, body) -> None:
    if not isinstance(body.shape, mpm.Box):
        raise ConfigError("scene.bodies[0].shape.type", f"the {kind} is a box; accepted: box")


@dataclass
class VibratingBar:
    """The 1D vibrating bar: a box of an elastic solid with nu = 0, no gravity."""

    type: str = setting("vibrating_bar", "the kind of solution")
    amplitude: Optional[float] = setting(None, "velocity amplitude [m/s]", gt=0.0, required=True)
    mode: int = setting(1, "the mode", ge=1)
    axis: int = setting(0, "the bar's axis", ge=0, le=2)

    def build(self, key: str, body, dim: int):
        mat = body.material
        _one_elastic_box("vibrating bar", body)
        if mat.name not in ("fixed_corotated", "neo_hookean") or mat.nu != 0.0:
            raise ConfigError("scene.bodies[0].material", f"{mat.name} (nu = {getattr(mat, 'nu', None)}): "
                              "the 1D bar solution needs an elastic solid with nu = 0; accepted: "
                              "fixed_corotated or neo_hookean with nu: 0.0")
        axis = number(f"{key}.axis", self.axis, int, {"keyed": True, "ge": 0, "le": dim - 1})
        lo, hi = body.shape.bounds()
        return mpm.analytic.VibratingBar(lo=float(lo[axis]), length=float(hi[axis] - lo[axis]),
                                         wave_speed=(mat.E / mat.rho) ** 0.5, amplitude=given(self.amplitude),
                                         mode=self.mode, axis=axis)


@dataclass
class ShearWave:
    """A decaying shear wave in a slab of a Newtonian viscous fluid."""

    type: str = setting("shear_wave", "the kind of solution")
    amplitude: Optional[float] = setting(None, "velocity amplitude [m/s]", gt=0.0, required=True)
    mode: int = setting(1, "the mode", ge=1)
    axis: int = setting(0, "the velocity's axis", ge=0, le=2)
    normal: int = setting(1, "the slab's normal axis", ge=0, le=2)

    def build(self, key: str, body, dim: int):
        mat = body.material
        _one_elastic_box("shear wave's slab", body)
        if not isinstance(mat, mpm.materials.Viscous) or mat.viscosity <= 0.0:
            raise ConfigError("scene.bodies[0].material", f"{mat.name}: the shear wave decays by Newtonian "
                              "viscosity; accepted: viscous (or fluid) with viscosity > 0")
        within = {"keyed": True, "ge": 0, "le": dim - 1}
        axis = number(f"{key}.axis", self.axis, int, within)
        normal = number(f"{key}.normal", self.normal, int, within)
        if normal == axis:
            raise ConfigError(f"{key}.normal", f"{normal} equals axis; accepted: another axis")
        lo, hi = body.shape.bounds()
        return mpm.analytic.ShearWave(lo=float(lo[normal]), thickness=float(hi[normal] - lo[normal]),
                                      kinematic_viscosity=mat.viscosity / mat.rho,
                                      amplitude=given(self.amplitude),
                                      mode=self.mode, axis=axis, normal=normal)


@dataclass
class Vortex:
    """The 2D vortex in a neo-Hookean ring (a manufactured solution)."""

    dims = (2,)
    type: str = setting("vortex", "the kind of solution")
    amplitude: Optional[float] = setting(None, "angular amplitude [rad]", gt=0.0, required=True)
    omega: float = setting(math.pi, "angular frequency [rad/s]", gt=0.0)

    def build(self, key: str, body, dim: int):
        shape, mat = body.shape, body.material
        if not isinstance(shape, mpm.Sphere) or shape.inner_radius <= 0.0:
            raise ConfigError("scene.bodies[0].shape", "the vortex is a ring; accepted: a sphere with "
                                                       "inner_radius > 0")
        if mat.name != "neo_hookean":
            raise ConfigError("scene.bodies[0].material.model", f"{mat.name}: the vortex's body force is "
                                                                "derived for neo_hookean; accepted: neo_hookean")
        center = cast("tuple[float, float]", tuple(shape.center))  # 2D only (dims)
        return mpm.analytic.Vortex(center=center, inner_radius=shape.inner_radius,
                                   outer_radius=shape.radius, shear_modulus=mat.E / (2 * (1 + mat.nu)),
                                   density=mat.rho, amplitude=given(self.amplitude), omega=self.omega)


SOLUTION = Family("solution", "type", {c.__dataclass_fields__["type"].default: c
                                       for c in (VibratingBar, Vortex, ShearWave)})


@dataclass
class SceneConfig:
    """Domain [0, domain[d]] per axis, a grid of ``resolution`` cells along x."""

    name: str = setting(MISSING, "the scene's name")
    dim: int = setting(2, "2 or 3", choices=(2, 3))
    domain: List[float] = setting([1.0, 1.0], "the domain's extent per axis [m]", size="dim", gt=0.0)
    resolution: int = setting(64, "grid cells along x", ge=4)
    duration: float = setting(1.0, "simulated time when run.steps and run.duration are null [s]", gt=0.0)
    gravity: List[float] = setting([0.0, -9.81], "[m/s^2]", size="dim")
    walls: Any = setting("slip", f"one of {', '.join(WALL_TYPES)}, or one per face (x_lo, x_hi, y_lo, ...)",
                         parse=walls)
    wall_cells: int = setting(3, "wall thickness [cells]: a wall's face lies this far inside the domain's face",
                              ge=1)
    boundary_rule: str = setting("surface", "where walls and colliders act: surface (where a body touches the "
                                            "solid) or nodes (on the nodes inside it, as earlier versions did)",
                                 choices=BOUNDARY_RULES)
    ppc: int = setting(4, "particles per cell", ge=1)
    jitter: float = setting(0.0, "random displacement of the lattice samples [fraction of their spacing]",
                            ge=0.0, le=1.0)
    lattice_offset: Optional[List[float]] = setting(None, "shift of the sampling lattice [cells]; ppc 1 with "
                                                          "0.5: particles on the nodes", size="dim")
    particle_volume: str = setting("shape", "the particles' volumes: shape (a body's exact volume shared "
                                            "equally; its cells' where the shape has no closed form) or cells "
                                            "(dx^d / ppc each)", choices=PARTICLE_VOLUMES)
    contact: str = setting("frictionless", "between bodies: frictionless, friction (Coulomb: contact_friction, "
                                           "contact_pairs), none, shared (one grid; EMPM) or elastic (springs on the "
                                           "particles that touch, Coulomb as friction's)", choices=CONTACT_TYPES)
    contact_stiffness: float = setting(0.5, "contact=elastic: the springs' stiffness over the softer body's "
                                            "P-wave modulus", gt=0.0, le=4.0)
    contact_fill: float = setting(0.5, "the node volume fraction the bodies must fill for contact",
                                  gt=0.0, le=1.0)
    contact_friction: float = setting(0.0, "Coulomb mu between bodies (contact=friction or elastic): every "
                                           "pair's unless contact_pairs names it", ge=0.0)
    contact_pairs: List[ContactPairConfig] = setting([], "pairs of bodies with their own Coulomb mu "
                                                         "(contact=friction): [{bodies: [a, b], friction: mu}]")
    contact_normal: str = setting("difference", "the bodies' normals at a contact node: difference (the bisector "
                                                "of their own), max_gradient (the body with the largest volume "
                                                "gradient's) or stiffer (the stiffest body's)", choices=CONTACT_NORMALS)
    contact_share: float = setting(0.0, "the node volume fraction a body must fill there to take part in "
                                        "contact (0: any mass; 0.1 leaves out a stencil's fringe)", ge=0.0, lt=1.0)
    responses: List[ResponseConfig] = setting([], "the physical responses the run measures (a ball's rebound, a "
                                                    "front): [{name: ..., quantity: ..., body: ..., reduce: ...}]")
    bodies: List[BodyConfig] = setting([], "the bodies", nonempty="at least one body")
    regions: List[RegionConfig] = setting([], "kinematic boundary regions")
    loads: List[LoadConfig] = setting([], "external loads: point loads, tractions, body forces")
    colliders: List[ColliderConfig] = setting([], "rigid colliders", family=COLLIDERS)
    rigid_bodies: List[RigidBodyConfig] = setting([], "rigid bodies the material pushes back, advanced by Newton")
    joints: List[JointConfig] = setting([], "joints holding rigid bodies to the world or to one another (Newton)")
    rigid_contact: str = setting("none", "what rigid bodies meet besides the material: none, walls (the closed "
                                         "walls' faces) or all (the walls and each other)",
                                 choices=mpm.RIGID_CONTACTS)
    rigid_contact_stiffness: float = setting(1.0e5, "penalty stiffness of a rigid body's contact point [N/m; 2D: "
                                                    "per metre of depth]", gt=0.0)
    rigid_contact_damping: float = setting(1.0e3, "penalty damping of a rigid body's contact point [N s/m; 2D: "
                                                  "per metre of depth]", ge=0.0)
    size: str = setting("default", "a key of sizes: its values replace resolution, ppc, ...")
    sizes: Dict[str, Any] = setting({}, "name -> {resolution: ..., ppc: ...}")
    particle_resolution: Optional[int] = setting(None, "sample the particles as on this grid (a fixed particle "
                                                       "set under grid refinement)", ge=1)
    solution: Optional[Any] = setting(None, "closed-form solution: a mapping with a type key "
                                            f"({', '.join(SOLUTION.variants)})", family=SOLUTION)


def check_size(node, key: str = "scene") -> None:
    """``scene.size`` must name one of ``scene.sizes`` (checked before the
    scene's interpolations, which read the chosen size, are resolved)."""
    if not OmegaConf.is_config(node):
        return
    size = node.get("size", "default")
    sizes = node.get("sizes") or {}
    names = list(sizes.keys()) if sizes else ["default"]
    if size not in names:
        raise ConfigError(f"{key}.size", f"{size!r} unknown for scene {node.get('name')}; "
                                         f"accepted: {', '.join(names)}")
    if sizes and OmegaConf.is_dict(sizes[size]):  # a key of the chosen size that no scene reads: ignored
        used = size_keys() | set(re.findall(SIZE_KEY, OmegaConf.to_yaml(node)))
        for k in sizes[size].keys():
            if k not in used:
                raise ConfigError(f"{key}.sizes.{size}.{k}", f"unknown key: no scene reads it; accepted: "
                                                           f"{', '.join(sorted(used))}")


SIZE_KEY = r"\$\{scene\.size\}\.(\w+)\}"  # a scene's value read from its chosen size


@functools.cache
def size_keys() -> set[str]:
    """The keys of a size that the files of conf/scene read."""
    return {k for path in (CONF / "scene").glob("*.yaml") for k in re.findall(SIZE_KEY, path.read_text())}


def make_scene(node, default_material: Material, key: str = "scene", seed: int = 0) -> tuple[mpm.Scene, SceneConfig]:
    """The scene and its checked config; ``seed`` draws random shape
    rotations (and nothing else)."""
    check_size(node, key)
    d = plain(node)
    if not isinstance(d, dict):
        raise ConfigError(key, f"{d!r}; accepted: a scene mapping")
    dim = choice(f"{key}.dim", number(f"{key}.dim", d.get("dim", 2), int), (2, 3))
    ctx = Context(dim=dim, rng=np.random.default_rng([seed, 1]))
    sc = check(SceneConfig, d, key, ctx)
    bodies = [mpm.Body(shape=b.shape.build(f"{key}.bodies[{i}].shape", ctx),
                       material=default_material if b.material is None else b.material,
                       name=b.name or f"body{i}", velocity=b.velocity, angular_velocity=b.angular_velocity,
                       ppc=b.ppc, deformation=b.deformation, sampling=b.sampling)
              for i, b in enumerate(sc.bodies)]
    names = [b.name for b in bodies]
    def body_index(key: str, body):
        if body is None:
            return None
        if isinstance(body, str):
            return names.index(choice(key, body, names))
        return number(key, body, int, {"keyed": True, "ge": 0, "le": len(bodies) - 1})

    regions = []
    for i, r in enumerate(sc.regions):
        rkey = f"{key}.regions[{i}]"
        if r.body is None:
            raise ConfigError(f"{rkey}.body", f"missing; accepted: a body's index (0 to {len(bodies) - 1}) or name "
                                              f"({', '.join(names)})")
        body = body_index(f"{rkey}.body", r.body)
        assert body is not None  # r.body is not None
        regions.append(mpm.KinematicRegion(
            body=body, select=r.select.build(f"{rkey}.select", replace(ctx, rng=None)), name=r.name,
            velocity=r.velocity, angular_velocity=r.angular_velocity, velocity_gradient=r.velocity_gradient,
            center=r.center, start=r.start, end=math.inf if r.end is None else r.end))
    scene = mpm.Scene(dim=dim, domain=tuple(sc.domain), resolution=sc.resolution, bodies=bodies,
                      gravity=tuple(sc.gravity),
                      walls=sc.walls, wall_cells=sc.wall_cells, boundary_rule=sc.boundary_rule, ppc=sc.ppc,
                      jitter=sc.jitter,
                      lattice_offset=sc.lattice_offset, particle_volume=sc.particle_volume, contact=sc.contact,
                      contact_fill=sc.contact_fill, contact_friction=sc.contact_friction,
                      contact_stiffness=sc.contact_stiffness,
                      contact_normal=sc.contact_normal, contact_share=sc.contact_share,
                      contact_pairs=[_pair(f"{key}.contact_pairs[{i}]", p, body_index)
                                     for i, p in enumerate(sc.contact_pairs)],
                      regions=regions, particle_resolution=sc.particle_resolution,
                      colliders=[c.build(f"{key}.colliders[{i}]", ctx) for i, c in enumerate(sc.colliders)],
                      rigid_bodies=[b.build(f"{key}.rigid_bodies[{i}]", ctx) for i, b in enumerate(sc.rigid_bodies)],
                      joints=[j.build(f"{key}.joints[{i}]", ctx) for i, j in enumerate(sc.joints)],
                      rigid_contact=sc.rigid_contact, rigid_contact_stiffness=sc.rigid_contact_stiffness,
                      rigid_contact_damping=sc.rigid_contact_damping,
                      loads=[_load(f"{key}.loads[{i}]", ld, body_index, ctx) for i, ld in enumerate(sc.loads)])
    scene.solution = _solution(sc.solution, f"{key}.solution", scene)
    return scene, sc


def make_responses(sc: SceneConfig, scene: mpm.Scene, key: str = "scene") -> list[mpm.Response]:
    """The scene's responses (``sc.responses``), bodies as indices."""
    names = [b.name for b in scene.bodies]
    out, seen = [], set()
    for i, r in enumerate(sc.responses):
        rkey = f"{key}.responses[{i}]"
        if not r.name or r.name in seen:
            raise ConfigError(f"{rkey}.name", f"{r.name!r}; accepted: a name no other response has")
        seen.add(r.name)
        body = r.body
        if isinstance(body, str):
            body = names.index(choice(f"{rkey}.body", body, names))
        elif body is not None:
            body = number(f"{rkey}.body", body, int, {"keyed": True, "ge": 0, "le": len(names) - 1})
        out.append(mpm.Response(r.name, r.quantity, body, r.reduce))
    return out


def _pair(key: str, p: ContactPairConfig, body_index) -> mpm.ContactPair:
    """The contact pair of ``p``, its bodies as indices."""
    if len(p.bodies) != 2:
        raise ConfigError(f"{key}.bodies", f"{plain(p.bodies)}; accepted: two bodies, each an index or a name")
    a, b = (body_index(f"{key}.bodies[{i}]", v) for i, v in enumerate(p.bodies))
    if a == b:
        raise ConfigError(f"{key}.bodies", f"{plain(p.bodies)}: one body twice; accepted: two different bodies")
    return mpm.ContactPair(a, b, p.friction)


def _load(key: str, ld: LoadConfig, body_index, ctx: Context) -> Load:
    """The load of ``ld`` (its consistency is checked with the scene's: mpm.model.check_scene)."""
    return Load(kind=ld.kind, force=ld.force, body=body_index(f"{key}.body", ld.body),
                select=None if ld.select is None else ld.select.build(f"{key}.select", replace(ctx, rng=None)),
                at=ld.at, count=ld.count, normal=ld.normal, area=ld.area, start=ld.start,
                end=math.inf if ld.end is None else ld.end, ramp=ld.ramp, table=ld.table, name=ld.name)


def _solution(solution, key: str, scene: mpm.Scene):
    if solution is None:
        return None
    if len(scene.bodies) != 1:
        raise ConfigError(f"{key}.type", f"{solution.type} describes one body, the scene has {len(scene.bodies)}; "
                                         "accepted: a scene with one body")
    if any(g != 0.0 for g in scene.gravity):
        raise ConfigError("scene.gravity", f"{list(scene.gravity)}: {solution.type} has no gravity; accepted: zeros")
    return solution.build(key, scene.bodies[0], scene.dim)
