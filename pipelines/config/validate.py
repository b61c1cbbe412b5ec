"""Turn a composed config into the solver's plain dataclasses, checking every
value on the way. Each problem raises :class:`ConfigError` naming the full
config key and the accepted values; nothing is compiled or allocated here.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
from dataclasses import dataclass, field
from typing import Any

from omegaconf import DictConfig, OmegaConf

import mpm
from mpm.integrators import INTEGRATORS, Explicit
from mpm.materials import MATERIALS, Material
from mpm.meshes import MESH_SUFFIXES, MeshShape, asset_path, file_digest, mesh_assets
from mpm.params import violations
from mpm.scene import WALL_TYPES
from mpm.schemes import AFFINE, CRITERIA
from mpm.transfer import TRANSFERS

from .schema import BOUNDARIES, COLLIDERS, CONTACTS, DEVICES, PRECISIONS, SHAPES


class ConfigError(ValueError):
    """A configuration value that cannot be used; ``key`` is its full path."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


@dataclass
class RunSettings:
    steps: int | None
    duration: float | None
    dt: float | None
    cfl: float
    dt_max: float
    dt_collapse: float
    reference: str | None  # final_state.npz of a reference run
    precision: str
    device: str
    fuse: bool | None = None  # explicit EMPM: stencils located in the transfers (mpm.SolverOptions.fuse)


@dataclass
class LogSettings:
    every: int | None  # particles every N steps; 0: none; None: log.fps frames per simulated second
    fps: float  # frames per simulated second [1/s]
    color: str  # body, dJ or plastic_strain
    size_warning_mb: float
    dJ: bool
    fracture_every: int
    scalars: bool
    flush_every: int
    progress: bool | None
    recording: str

    @property
    def particles(self) -> bool:
        """Whether particle frames are logged at all."""
        return self.every != 0


@dataclass
class MapSpec:
    """The points of a stability map (pipelines.sweeps.stability)."""

    E: list[float]  # stiffness [Pa]: Young's modulus (a fluid's bulk modulus)
    dt_cfl: list[float]  # fixed step [multiples of the explicit CFL limit]
    steps: int  # steps per point


def make_map(node, key: str = "stability_map") -> MapSpec | None:
    d = _plain(node)
    if d is None:
        return None
    if not isinstance(d, dict) or set(d) != {"E", "dt_cfl", "steps"}:
        raise ConfigError(key, f"{d!r}; accepted: a mapping with E, dt_cfl and steps")
    lists = {}
    for name in ("E", "dt_cfl"):
        values = d[name] if isinstance(d[name], list) else [d[name]]
        if not values:
            raise ConfigError(f"{key}.{name}", "empty; accepted: a list of numbers > 0")
        lists[name] = [_number(f"{key}.{name}[{i}]", v, gt=0.0) for i, v in enumerate(values)]
    return MapSpec(E=lists["E"], dt_cfl=lists["dt_cfl"], steps=_number(f"{key}.steps", d["steps"], int, ge=1))


@dataclass
class RunSpec:
    """Everything a run needs, validated."""

    scene: mpm.Scene
    scene_name: str
    scheme: Any
    kernel: mpm.Kernel
    transfer: str
    run: RunSettings
    log: LogSettings
    seed: int
    integrator: Any = field(default_factory=Explicit)  # mpm.integrators
    detect: mpm.Detection = field(default_factory=mpm.Detection)  # blow-up detection (mpm.stability)
    stability_map: MapSpec | None = None  # the job is a stability map (pipelines.sweeps.stability)
    material_used: bool = True  # some body takes the material group (else every body brings its own)

    @property
    def meshes(self) -> dict[str, str]:
        """Mesh file -> content digest, for every mesh the scene reads."""
        found = []

        def walk(shape):
            if isinstance(shape, MeshShape):
                found.append(shape.source)
            for part in getattr(shape, "parts", ()):
                walk(part)
            if isinstance(shape, mpm.scene.Rotated):
                walk(shape.shape)

        for b in self.scene.bodies:
            walk(b.shape)
        for c in self.scene.colliders:
            if c.mesh is not None:
                walk(c.mesh)
        return {name: file_digest(name) for name in sorted(set(found))}

    @property
    def end(self) -> tuple[int | None, float | None]:
        """(steps, duration): exactly one is set."""
        if self.run.steps is not None:
            return self.run.steps, None
        return None, self.run.duration


def _plain(node) -> Any:
    return OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) or \
        OmegaConf.is_config(node) else node


def _number(key: str, value, kind=float, *, gt=None, ge=None, le=None, optional=False):
    if value is None:
        if optional:
            return None
        raise ConfigError(key, "missing; accepted: a number")
    try:
        if kind is int and (isinstance(value, bool) or float(value) != int(value)):
            raise ValueError
        v = kind(value)
    except (TypeError, ValueError):
        raise ConfigError(key, f"{value!r} is not {'an integer' if kind is int else 'a number'}") from None
    bounds = [f"{key} > {gt}" if gt is not None else None, f"{key} >= {ge}" if ge is not None else None,
              f"{key} <= {le}" if le is not None else None]
    accepted = ", ".join(b for b in bounds if b)
    if not math.isfinite(v):  # inf and nan: a step, a duration or a modulus must be a number
        raise ConfigError(key, f"{value} is not finite; accepted: a finite number"
                               + (f", {accepted}" if accepted else ""))
    if (gt is not None and not v > gt) or (ge is not None and not v >= ge) or \
            (le is not None and not v <= le):
        raise ConfigError(key, f"{value} out of range; accepted: {accepted}")
    return v


def _choice(key: str, value, accepted) -> str:
    if value not in accepted:
        raise ConfigError(key, f"{value!r} unknown; accepted: {', '.join(accepted)}")
    return value


def _vector(key: str, value, dim: int) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != dim:
        raise ConfigError(key, f"{value!r}; accepted: a list of {dim} numbers")
    return tuple(_number(f"{key}[{i}]", v) for i, v in enumerate(value))


# ------------------------------------------------------------------ groups
def make_material(node, key: str) -> Material:
    """A material from a ``material`` group node or an inline mapping."""
    d = _plain(node)
    if not isinstance(d, dict):
        raise ConfigError(key, f"{d!r}; accepted: a mapping with a model key, "
                               f"e.g. {{model: fluid, K: 1.0e5}}")
    d = dict(d)
    model = d.get("model")
    if model not in MATERIALS:
        raise ConfigError(f"{key}.model", f"{model!r} unknown; accepted: {', '.join(MATERIALS)}")
    cls = MATERIALS[model]
    names = [f.name for f in dataclasses.fields(cls)]
    for k in d:
        if k not in names:
            raise ConfigError(f"{key}.{k}", f"not a parameter of {model}; accepted: {', '.join(names)}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    values = {k: _material_value(f"{key}.{k}", v, fields[k]) for k, v in d.items()}
    material = cls(**values)
    for name, value, accepted in violations(material):
        raise ConfigError(f"{key}.{name}", f"{value} out of range; accepted: {accepted}")
    for name, message in material.problems():
        raise ConfigError(f"{key}.{name}", message)
    return material


def _material_value(key: str, value, field: dataclasses.Field):
    """A material parameter: the model name, a flag, or a number (or null
    where the field's type allows it)."""
    if field.name == "model":
        return value
    if isinstance(field.default, bool):
        if not isinstance(value, bool):
            raise ConfigError(key, f"{value!r}; accepted: true, false")
        return value
    return _number(key, value, optional="None" in str(field.type))


def _named(node, key: str, registry: dict):
    """The dataclass of ``registry`` named by ``node.name``, built from the
    node and range-checked."""
    d = dict(_plain(node) or {})
    name = _choice(f"{key}.name", d.get("name"), list(registry))
    obj = registry[name](**d)
    for fname, value, accepted in violations(obj):
        raise ConfigError(f"{key}.{fname}", f"{value} out of range; accepted: {accepted}")
    return obj, d


def make_integrator(node, key: str = "integrator"):
    integrator, _ = _named(node, key, INTEGRATORS)
    for fname, message in integrator.problems():
        raise ConfigError(f"{key}.{fname}", message)
    return integrator


def make_scheme(node, key: str = "scheme"):
    scheme, d = _named(node, key, mpm.SCHEMES)
    if d.get("affine") is not None:
        _choice(f"{key}.affine", d["affine"], AFFINE)
    if d.get("criterion") is not None:
        _choice(f"{key}.criterion", d["criterion"], CRITERIA)
    for fname, message in scheme.problems():
        raise ConfigError(f"{key}.{fname}", message)
    return scheme


SHAPE_KEYS = {"box": ["center", "half_size"], "sphere": ["center", "radius"],
              "cylinder": ["center", "radius", "half_height"], "mesh": ["mesh", "center", "size"],
              "bowl": ["center", "radius", "thickness", "rim"], "compound": ["parts"]}
SHAPE_OPTIONAL = {"cylinder": ["axis", "inner_radius"], "mesh": ["axis"], "sphere": ["inner_radius"],
                  "bowl": ["axis"]}


def _rotation(key: str, value, dim: int, rng):
    """A rotation matrix from an angle (2D), three angles (3D) [degrees] or
    ``random`` (uniform over rotations, drawn from ``rng``)."""
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
        return mpm.scene.rotation_matrix(_number(key, value), 2)
    return mpm.scene.rotation_matrix(_vector(key, value, 3), 3)


def make_shape(node, key: str, dim: int, rng=None):
    """A shape; ``rng`` draws random rotations (None: they are refused)."""
    d = _plain(node)
    if not isinstance(d, dict):
        raise ConfigError(key, f"{d!r}; accepted: a shape mapping with a type key")
    d = dict(d)
    rotation = d.pop("rotation", None)
    shape = _make_shape(d, key, dim, rng)
    if rotation is None:
        return shape
    return mpm.scene.Rotated(shape, _rotation(f"{key}.rotation", rotation, dim, rng))


def _make_shape(d: dict, key: str, dim: int, rng):
    kind = _choice(f"{key}.type", d.get("type"), SHAPES)
    need = SHAPE_KEYS[kind]
    allowed = need + SHAPE_OPTIONAL.get(kind, []) + ["rotation"]
    for k, v in d.items():
        if k != "type" and v is not None and k not in allowed:
            raise ConfigError(f"{key}.{k}", f"not used by a {kind}; accepted: {', '.join(allowed)}")
    for k in need:
        if d.get(k) is None:
            raise ConfigError(f"{key}.{k}", f"missing for a {kind}")
    if kind == "compound":
        if not isinstance(d["parts"], list) or not d["parts"]:
            raise ConfigError(f"{key}.parts", "accepted: a non-empty list of shapes")
        return mpm.Compound(tuple(make_shape(p, f"{key}.parts[{i}]", dim, rng)
                                  for i, p in enumerate(d["parts"])))
    center = _vector(f"{key}.center", d["center"], dim)
    if kind == "box":
        half = _vector(f"{key}.half_size", d["half_size"], dim)
        for i, h in enumerate(half):
            _number(f"{key}.half_size[{i}]", h, gt=0.0)
        return mpm.Box(center, half)
    if kind == "mesh":
        if dim != 3:
            raise ConfigError(f"{key}.type", "mesh is 3D only; accepted in 2D: box, sphere, compound")
        _mesh_file(f"{key}.mesh", d["mesh"])
        up = 1 if d.get("axis") is None else _number(f"{key}.axis", d["axis"], int, ge=0, le=2)
        return MeshShape(d["mesh"], center, _number(f"{key}.size", d["size"], gt=0.0), up)
    radius = _number(f"{key}.radius", d["radius"], gt=0.0)
    if kind == "bowl":
        axis = 1 if d.get("axis") is None else _number(f"{key}.axis", d["axis"], int, ge=0, le=dim - 1)
        thickness = _number(f"{key}.thickness", d["thickness"], gt=0.0)
        rim = _number(f"{key}.rim", d["rim"], gt=-(radius + thickness), le=radius)
        return mpm.scene.Bowl(center, radius, thickness, rim, axis)
    inner = 0.0 if d.get("inner_radius") is None else \
        _number(f"{key}.inner_radius", d["inner_radius"], ge=0.0)
    if inner >= radius:
        raise ConfigError(f"{key}.inner_radius", f"{inner} >= radius {radius}; accepted: below the radius")
    if kind == "sphere":
        return mpm.Sphere(center, radius, inner)
    if dim != 3:
        raise ConfigError(f"{key}.type", "cylinder is 3D only; accepted in 2D: box, sphere, compound")
    axis = 1 if d.get("axis") is None else _number(f"{key}.axis", d["axis"], int, ge=0, le=2)
    return mpm.Cylinder(center, radius, _number(f"{key}.half_height", d["half_height"], gt=0.0), axis,
                        inner)


def _mesh_file(key: str, name) -> str:
    if not isinstance(name, str) or not os.path.exists(asset_path(name)):
        raise ConfigError(key, f"{name!r}: no such file; accepted: an OBJ, PLY, STL or USD path, or "
                               f"warp:<asset> ({', '.join('warp:' + a for a in mesh_assets())})")
    if not name.startswith("warp:") and not name.lower().endswith(MESH_SUFFIXES):
        raise ConfigError(key, f"{name!r}: unknown format; accepted: {', '.join(MESH_SUFFIXES)}")
    return name


COLLIDER_KEYS = {"half_space": ["point", "normal"], "wedge": ["point", "normals"],
                 "box": ["center", "half_size"], "sphere": ["center", "radius"],
                 "cylinder": ["center", "radius", "half_height"],
                 "cup": ["center", "radius", "depth", "thickness"],
                 "bowl": ["center", "radius", "thickness", "rim"], "mesh": ["mesh", "center", "size"]}
COLLIDER_COMMON = ["type", "name", "boundary", "friction", "inside", "velocity", "start", "end"]


def make_collider(node, key: str, dim: int) -> mpm.Collider:
    """A rigid collider (mpm.colliders) from its config mapping."""
    d = _plain(node)
    if not isinstance(d, dict):
        raise ConfigError(key, f"{d!r}; accepted: a collider mapping with a type key")
    kind = _choice(f"{key}.type", d.get("type"), COLLIDERS)
    need = COLLIDER_KEYS[kind]
    allowed = need + (["axis"] if kind in ("cylinder", "cup", "bowl", "mesh") else [])
    for k, v in d.items():
        if k not in COLLIDER_COMMON and v is not None and k not in allowed:
            raise ConfigError(f"{key}.{k}", f"not used by a {kind} collider; accepted: "
                                            f"{', '.join(COLLIDER_COMMON + allowed)}")
    for k in need:
        if d.get(k) is None:
            raise ConfigError(f"{key}.{k}", f"missing for a {kind} collider")
    if kind == "mesh" and dim != 3:
        raise ConfigError(f"{key}.type", "mesh colliders are 3D only; accepted in 2D: "
                                         f"{', '.join(c for c in COLLIDERS if c != 'mesh')}")
    start = _number(f"{key}.start", d.get("start", 0.0), ge=0.0)
    end = _number(f"{key}.end", d.get("end"), gt=start, optional=True)
    common = dict(
        kind=kind, name=d.get("name") or "",
        boundary=_choice(f"{key}.boundary", d.get("boundary", "slip"), BOUNDARIES),
        friction=_number(f"{key}.friction", d.get("friction", 0.0), ge=0.0),
        inside=_flag(f"{key}.inside", d.get("inside", False)),
        velocity=None if d.get("velocity") is None else _vector(f"{key}.velocity", d["velocity"], dim),
        start=start, end=float("inf") if end is None else end)
    geo = {}
    if kind in ("half_space", "wedge"):
        geo["point"] = _vector(f"{key}.point", d["point"], dim)
        normals = [d["normal"]] if kind == "half_space" else d["normals"]
        if kind == "wedge" and (not isinstance(normals, list) or len(normals) != 2):
            raise ConfigError(f"{key}.normals", f"{normals!r}; accepted: two vectors of {dim} numbers")
        vs = []
        for i, n in enumerate(normals):
            nk = f"{key}.normal" if kind == "half_space" else f"{key}.normals[{i}]"
            v = _vector(nk, n, dim)
            if np.linalg.norm(v) == 0.0:
                raise ConfigError(nk, f"{list(v)}; accepted: a non-zero vector")
            vs.append(v)
        if kind == "half_space":
            geo["normal"] = vs[0]
        else:
            geo["normals"] = tuple(vs)
    else:
        geo["center"] = _vector(f"{key}.center", d["center"], dim)
    if kind == "box":
        geo["half_size"] = tuple(_number(f"{key}.half_size[{i}]", h, gt=0.0)
                                 for i, h in enumerate(_vector(f"{key}.half_size", d["half_size"], dim)))
    for name in ("radius", "half_height", "depth", "thickness"):
        if name in need:
            geo[name] = _number(f"{key}.{name}", d[name], gt=0.0)
    if kind == "bowl":
        geo["rim"] = _number(f"{key}.rim", d["rim"], gt=-(geo["radius"] + geo["thickness"]),
                             le=geo["radius"])
    if kind in ("cylinder", "cup", "bowl"):
        axis = d.get("axis", 1)
        if isinstance(axis, list):
            v = _vector(f"{key}.axis", axis, dim)
            if np.linalg.norm(v) == 0.0:
                raise ConfigError(f"{key}.axis", f"{list(v)}; accepted: a non-zero vector or 0..{dim - 1}")
            geo["axis"] = v
        else:
            geo["axis"] = 1 if axis is None else _number(f"{key}.axis", axis, int, ge=0, le=dim - 1)
    if kind == "mesh":
        up = 1 if d.get("axis") is None else _number(f"{key}.axis", d["axis"], int, ge=0, le=2)
        geo["mesh"] = MeshShape(_mesh_file(f"{key}.mesh", d["mesh"]), geo.pop("center"),
                                _number(f"{key}.size", d["size"], gt=0.0), up)
    return mpm.Collider(**common, **geo)


def _flag(key: str, value) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(key, f"{value!r}; accepted: true, false")
    return value


def _matrix(key: str, value, dim: int):
    """A d x d matrix given as d rows, or None."""
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) != dim:
        raise ConfigError(key, f"{value!r}; accepted: {dim} rows of {dim} numbers")
    return tuple(_vector(f"{key}[{i}]", row, dim) for i, row in enumerate(value))


def _angular(key: str, w, dim: int):
    if w is None:
        return None
    return _number(key, w) if dim == 2 else _vector(key, w, 3)


def make_region(d: dict, key: str, dim: int, body_names: list[str]) -> mpm.KinematicRegion:
    body = d.get("body")
    if isinstance(body, str):
        if body not in body_names:
            raise ConfigError(f"{key}.body", f"{body!r} unknown; accepted: {', '.join(body_names)}")
        body = body_names.index(body)
    else:
        body = _number(f"{key}.body", body, int, ge=0, le=len(body_names) - 1)
    start = _number(f"{key}.start", d.get("start", 0.0), ge=0.0)
    end = _number(f"{key}.end", d.get("end"), gt=start, optional=True)
    return mpm.KinematicRegion(
        body=body, select=make_shape(d["select"], f"{key}.select", dim), name=d.get("name") or "",
        velocity=None if d.get("velocity") is None else _vector(f"{key}.velocity", d["velocity"], dim),
        angular_velocity=_angular(f"{key}.angular_velocity", d.get("angular_velocity"), dim),
        velocity_gradient=_matrix(f"{key}.velocity_gradient", d.get("velocity_gradient"), dim),
        center=None if d.get("center") is None else _vector(f"{key}.center", d["center"], dim),
        start=start, end=float("inf") if end is None else end)


SOLUTION_KEYS = {"vibrating_bar": ["amplitude", "mode", "axis"], "vortex": ["amplitude", "omega"],
                 "shear_wave": ["amplitude", "mode", "axis", "normal"]}


def make_solution(d, key: str, dim: int, bodies: list, gravity: tuple):
    """A closed-form solution for the scene's single body (mpm.analytic)."""
    if d is None:
        return None
    if not isinstance(d, dict):
        raise ConfigError(key, f"{d!r}; accepted: a mapping with a type key")
    kind = _choice(f"{key}.type", d.get("type"), list(SOLUTION_KEYS))
    for k in d:
        if k != "type" and k not in SOLUTION_KEYS[kind]:
            raise ConfigError(f"{key}.{k}", f"not a parameter of {kind}; accepted: "
                                            f"{', '.join(SOLUTION_KEYS[kind])}")
    if len(bodies) != 1:
        raise ConfigError(f"{key}.type", f"{kind} describes one body, the scene has {len(bodies)}; "
                                         "accepted: a scene with one body")
    if any(g != 0.0 for g in gravity):
        raise ConfigError("scene.gravity", f"{list(gravity)}: {kind} has no gravity; accepted: zeros")
    body = bodies[0]
    mat = body.material
    amplitude = _number(f"{key}.amplitude", d.get("amplitude"), gt=0.0)
    if kind == "vibrating_bar":
        if not isinstance(body.shape, mpm.Box):
            raise ConfigError("scene.bodies[0].shape.type", "the vibrating bar is a box; accepted: box")
        if mat.name not in ("fixed_corotated", "neo_hookean") or mat.nu != 0.0:
            raise ConfigError("scene.bodies[0].material", f"{mat.name} (nu = {getattr(mat, 'nu', None)}): "
                              "the 1D bar solution needs an elastic solid with nu = 0; accepted: "
                              "fixed_corotated or neo_hookean with nu: 0.0")
        axis = _number(f"{key}.axis", d.get("axis", 0), int, ge=0, le=dim - 1)
        lo, hi = body.shape.bounds()
        return mpm.analytic.VibratingBar(
            lo=float(lo[axis]), length=float(hi[axis] - lo[axis]), wave_speed=(mat.E / mat.rho) ** 0.5,
            amplitude=amplitude, mode=_number(f"{key}.mode", d.get("mode", 1), int, ge=1), axis=axis)
    if kind == "shear_wave":
        if not isinstance(body.shape, mpm.Box):
            raise ConfigError("scene.bodies[0].shape.type", "the shear wave's slab is a box; accepted: box")
        if not isinstance(mat, mpm.materials.Viscous) or mat.viscosity <= 0.0:
            raise ConfigError("scene.bodies[0].material", f"{mat.name}: the shear wave decays by Newtonian "
                              "viscosity; accepted: viscous (or fluid) with viscosity > 0")
        axis = _number(f"{key}.axis", d.get("axis", 0), int, ge=0, le=dim - 1)
        normal = _number(f"{key}.normal", d.get("normal", 1), int, ge=0, le=dim - 1)
        if normal == axis:
            raise ConfigError(f"{key}.normal", f"{normal} equals axis; accepted: another axis")
        lo, hi = body.shape.bounds()
        return mpm.analytic.ShearWave(
            lo=float(lo[normal]), thickness=float(hi[normal] - lo[normal]),
            kinematic_viscosity=mat.viscosity / mat.rho, amplitude=amplitude,
            mode=_number(f"{key}.mode", d.get("mode", 1), int, ge=1), axis=axis, normal=normal)
    if dim != 2:
        raise ConfigError(f"{key}.type", "the vortex is 2D; accepted in 3D: vibrating_bar, shear_wave")
    shape = body.shape
    if not isinstance(shape, mpm.Sphere) or shape.inner_radius <= 0.0:
        raise ConfigError("scene.bodies[0].shape", "the vortex is a ring; accepted: a sphere with "
                                                   "inner_radius > 0")
    if mat.name != "neo_hookean":
        raise ConfigError("scene.bodies[0].material.model", f"{mat.name}: the vortex's body force is "
                                                            "derived for neo_hookean; accepted: neo_hookean")
    return mpm.analytic.Vortex(
        center=tuple(shape.center), inner_radius=shape.inner_radius, outer_radius=shape.radius,
        shear_modulus=mat.E / (2 * (1 + mat.nu)), density=mat.rho, amplitude=amplitude,
        omega=_number(f"{key}.omega", d.get("omega", 3.141592653589793), gt=0.0))


def _check_size(node, key: str) -> None:
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


def make_scene(node, default_material: Material, key: str = "scene",
               seed: int = 0) -> tuple[mpm.Scene, dict]:
    """The scene; ``seed`` draws random shape rotations (and nothing else)."""
    _check_size(node, key)
    d = _plain(node)
    rng = np.random.default_rng([seed, 1])
    dim = _number(f"{key}.dim", d["dim"], int)
    if dim not in (2, 3):
        raise ConfigError(f"{key}.dim", f"{dim}; accepted: 2, 3")
    domain = _vector(f"{key}.domain", d["domain"], dim)
    for i, L in enumerate(domain):
        _number(f"{key}.domain[{i}]", L, gt=0.0)
    walls = d["walls"]
    if isinstance(walls, str):
        walls = [walls] * (2 * dim)
    if not isinstance(walls, list) or len(walls) != 2 * dim:
        raise ConfigError(f"{key}.walls", f"{walls!r}; accepted: one of {', '.join(WALL_TYPES)}, "
                                         f"or a list of {2 * dim} (x_lo, x_hi, y_lo, ...)")
    for i, w in enumerate(walls):
        _choice(f"{key}.walls[{i}]", w, WALL_TYPES)
    bodies = []
    if not d["bodies"]:
        raise ConfigError(f"{key}.bodies", "empty; accepted: at least one body")
    for i, b in enumerate(d["bodies"]):
        bkey = f"{key}.bodies[{i}]"
        material = default_material if b.get("material") is None else \
            make_material(b["material"], f"{bkey}.material")
        w = _angular(f"{bkey}.angular_velocity", b.get("angular_velocity"), dim)
        bodies.append(mpm.Body(
            shape=make_shape(b["shape"], f"{bkey}.shape", dim, rng), material=material,
            name=b.get("name") or f"body{i}",
            velocity=None if b.get("velocity") is None else _vector(f"{bkey}.velocity", b["velocity"], dim),
            angular_velocity=w,
            ppc=_number(f"{bkey}.ppc", b.get("ppc"), int, ge=1, optional=True),
            deformation=_matrix(f"{bkey}.deformation", b.get("deformation"), dim)))
    scene = mpm.Scene(
        dim=dim, domain=domain,
        resolution=_number(f"{key}.resolution", d["resolution"], int, ge=4),
        bodies=bodies,
        gravity=_vector(f"{key}.gravity", d["gravity"], dim),
        walls=tuple(walls),
        wall_cells=_number(f"{key}.wall_cells", d["wall_cells"], int, ge=1),
        ppc=_number(f"{key}.ppc", d["ppc"], int, ge=1),
        jitter=_number(f"{key}.jitter", d["jitter"], ge=0.0, le=1.0),
        lattice_offset=None if d.get("lattice_offset") is None else
        _vector(f"{key}.lattice_offset", d["lattice_offset"], dim),
        contact=_choice(f"{key}.contact", d["contact"], CONTACTS),
        contact_fill=_number(f"{key}.contact_fill", d["contact_fill"], gt=0.0, le=1.0),
        regions=[make_region(r, f"{key}.regions[{i}]", dim, [b.name for b in bodies])
                 for i, r in enumerate(d.get("regions") or [])],
        particle_resolution=_number(f"{key}.particle_resolution", d.get("particle_resolution"), int,
                                    ge=1, optional=True),
        colliders=[make_collider(c, f"{key}.colliders[{i}]", dim)
                   for i, c in enumerate(d.get("colliders") or [])],
    )
    scene.solution = make_solution(d.get("solution"), f"{key}.solution", dim, bodies, scene.gravity)
    return scene, d


def _reference(key: str, path) -> str | None:
    """The final_state.npz of a reference run, given the run's directory or the file."""
    if path is None:
        return None
    p = os.path.join(str(path), "final_state.npz") if os.path.isdir(str(path)) else str(path)
    if not os.path.isfile(p):
        raise ConfigError(key, f"{path!r}: no final_state.npz there; accepted: the directory of a "
                               "finished run (or its final_state.npz)")
    return os.path.abspath(p)


def make_detect(node, key: str = "detect") -> mpm.Detection:
    d = dict(_plain(node) or {})
    unknown = sorted(set(d) - {f.name for f in dataclasses.fields(mpm.Detection)})
    if unknown:
        raise ConfigError(f"{key}.{unknown[0]}", f"unknown; accepted: "
                                                 f"{', '.join(f.name for f in dataclasses.fields(mpm.Detection))}")
    defaults = mpm.Detection()
    numbers = {k: _number(f"{key}.{k}", d.get(k, getattr(defaults, k)))  # ranges: Detection.problems
               for k in ("energy_growth", "speed_factor", "min_J", "min_stretch")}
    det = mpm.Detection(action=_choice(f"{key}.action", d.get("action", defaults.action),
                                       list(mpm.DETECTION_ACTIONS)), **numbers)
    for fname, message in det.problems():
        raise ConfigError(f"{key}.{fname}", message)
    return det


def make_run(node, key: str = "run") -> RunSettings:
    d = _plain(node)
    steps = _number(f"{key}.steps", d["steps"], int, ge=1, optional=True)
    duration = _number(f"{key}.duration", d["duration"], gt=0.0, optional=True)
    if steps is not None and duration is not None:
        raise ConfigError(f"{key}.steps", "set run.steps or run.duration, not both")
    precision = _choice(f"{key}.precision", d["precision"], PRECISIONS)
    device = _choice(f"{key}.device", d["device"], DEVICES)
    return RunSettings(
        steps=steps, duration=duration,
        dt=_number(f"{key}.dt", d["dt"], gt=0.0, optional=True),
        cfl=_number(f"{key}.cfl", d["cfl"], gt=0.0, le=1.0),
        dt_max=_number(f"{key}.dt_max", d["dt_max"], gt=0.0),
        dt_collapse=_number(f"{key}.dt_collapse", d["dt_collapse"], ge=0.0, le=1.0),
        reference=_reference(f"{key}.reference", d.get("reference")),
        precision=precision, device=device, fuse=None if d.get("fuse") is None else bool(d["fuse"]))


MEMORY_FRACTION = 0.8  # of the machine's memory a run may plan to use


def _machine_memory() -> int:
    """Physical memory [bytes] of this machine (0: unknown)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 0


def memory_estimate(scene: mpm.Scene, kernel: mpm.Kernel, precision: str) -> tuple[float, float, float]:
    """(bytes, particles, domain nodes): an upper estimate of what building
    and stepping the scene allocates, before anything is sampled. Particles:
    each body's bounding box filled at ``ppc`` per sampling cell; per particle
    its state, model data and stencil cache (and the float64 samples of the
    build); per domain node the grid fields of every kernel grid, and the
    per-body contact fields when bodies can touch."""
    d = scene.dim
    s = 4 if precision == "float32" else 8
    G, K = kernel.n_grids, kernel.support
    cell = scene.particle_dx ** d
    particles = 0.0
    for b in scene.bodies:
        lo, hi = (np.asarray(v, float) for v in b.shape.bounds())
        particles += float(np.prod(np.maximum(hi - lo, 0.0) + scene.particle_dx)) / cell * (b.ppc or scene.ppc)
    per_particle = s * (3 * d + 4 * d * d + 8 + G * (d + 2 * d * K)) + 4 * (2 + G) + 8 * (4 * d + 2 * d * d)
    nodes = float(np.prod([c + 1 for c in scene.cells]))
    contact = len(scene.bodies) if len(scene.bodies) > 1 and scene.contact == "frictionless" else 0
    per_node = s * ((1 + 2 * d) * 2 * G + (1 + d) * contact) + 8  # the grids; contact's M and P per body
    return particles * per_particle + nodes * per_node, particles, nodes


def check_memory(spec: "RunSpec") -> None:
    """Refuse a run that cannot fit in this machine's memory (its estimate
    and the limit in the message), before anything is sampled or allocated.
    Separate from :func:`resolve`: a config too large for this machine is
    still valid (another machine may run it)."""
    scene, kernel, precision = spec.scene, spec.kernel, spec.run.precision
    need, particles, nodes = memory_estimate(scene, kernel, precision)
    have = _machine_memory()
    if have and need > MEMORY_FRACTION * have:
        gib = 2.0 ** 30
        key = "scene.ppc" if particles * 200 > nodes * 50 and scene.ppc > 64 else "scene.resolution"
        raise ConfigError(key, f"the run needs about {need / gib:.3g} GiB ({particles:.3g} particles, "
                               f"{nodes:.3g} grid nodes), more than {MEMORY_FRACTION:.0%} of this machine's "
                               f"{have / gib:.3g} GiB; accepted: a smaller grid or fewer particles per cell")


def _color(value, scene, dJ: bool) -> str:
    """``log.color``: what colours the particles; ``auto`` resolved."""
    plastic = any(b.material.plastic for b in scene.bodies)
    accepted = ["auto", "body"] + (["dJ"] if dJ else []) + (["plastic_strain"] if plastic else [])
    if value not in accepted:
        why = ("" if value not in ("dJ", "plastic_strain") else
               " (log.dJ is false)" if value == "dJ" else " (no plastic body in this scene)")
        raise ConfigError("log.color", f"{value!r}{why}; accepted: {', '.join(accepted)}")
    if value == "auto":
        return "plastic_strain" if plastic else "dJ" if dJ else "body"
    return value


def _recording_name(value) -> str:
    """``log.recording``: a file name inside the run directory."""
    name = "" if value is None else str(value)
    if not name or "/" in name or "\\" in name or not name.endswith(".rrd") or name == ".rrd":
        raise ConfigError("log.recording", f"{value!r}; accepted: a file name ending in .rrd, without a "
                                           "directory (it is written into the run directory)")
    return name


def _known_keys(cfg) -> None:
    """A key added with ``+`` that no schema knows (``+run.stepz=5``) would
    be ignored silently: refuse it, naming the accepted keys."""
    from .schema import (BodyConfig, ColliderConfig, Config, KernelConfig, LogConfig, RegionConfig, RunConfig,
                         SceneConfig, ShapeConfig)

    sections = [("", cfg, Config), ("run.", cfg.get("run"), RunConfig), ("log.", cfg.get("log"), LogConfig),
                ("kernel.", cfg.get("kernel"), KernelConfig), ("scene.", cfg.get("scene"), SceneConfig)]
    scene = cfg.get("scene")
    if isinstance(scene, DictConfig):  # list elements of the scene: bodies, regions, colliders, their shapes
        for name, schema in (("bodies", BodyConfig), ("regions", RegionConfig), ("colliders", ColliderConfig)):
            for i, item in enumerate(scene.get(name) or []):
                if isinstance(item, DictConfig):
                    sections.append((f"scene.{name}[{i}].", item, schema))
                    for shape in ("shape", "select"):
                        if isinstance(item.get(shape), DictConfig) and shape in schema.__dataclass_fields__:
                            sections.append((f"scene.{name}[{i}].{shape}.", item.get(shape), ShapeConfig))
    for prefix, node, schema in sections:
        if not isinstance(node, DictConfig):
            continue
        known = {f.name for f in dataclasses.fields(schema)}
        for key in node:
            if key not in known and not (prefix == "" and key == "hydra"):
                raise ConfigError(f"{prefix}{key}", f"unknown key; accepted: {', '.join(sorted(known))}")


def resolve(cfg) -> RunSpec:
    """Validate a composed :class:`pipelines.config.schema.Config`."""
    _known_keys(cfg)
    run = make_run(cfg.run)
    scheme = make_scheme(cfg.scheme)
    integrator = make_integrator(cfg.integrator) if "integrator" in cfg else Explicit()
    detect = make_detect(cfg.detect) if "detect" in cfg else mpm.Detection()
    stability_map = make_map(cfg.get("stability_map"))
    kernel_name = _choice("kernel.name", cfg.kernel.name, list(mpm.KERNELS))
    transfer = _choice("kernel.transfer", cfg.kernel.transfer, TRANSFERS)
    material = make_material(cfg.material, "material")
    seed = _number("seed", cfg.seed, int, ge=0)
    scene, sd = make_scene(cfg.scene, material, seed=seed)
    try:
        mpm.model.check_scene(scene, mpm.KERNELS[kernel_name])
    except mpm.SceneError as e:
        raise ConfigError(f"scene.{e.key}", e.message) from None
    if scene.contact == "shared" and scheme.name != "empm":
        raise ConfigError("scene.contact", "'shared' (one grid for all bodies) needs scheme=empm; "
                                           "accepted with other schemes: frictionless, none")
    if run.steps is None and run.duration is None:
        run.duration = _number("scene.duration", sd["duration"], gt=0.0)
    lg = _plain(cfg.log)
    log = LogSettings(
        every=_number("log.every", lg["every"], int, ge=0, optional=True),
        fps=_number("log.fps", lg["fps"], gt=0.0), color=_color(lg["color"], scene, bool(lg["dJ"])),
        size_warning_mb=_number("log.size_warning_mb", lg["size_warning_mb"], gt=0.0),
        dJ=bool(lg["dJ"]), scalars=bool(lg["scalars"]),
        fracture_every=_number("log.fracture_every", lg["fracture_every"], int, ge=1),
        flush_every=_number("log.flush_every", lg["flush_every"], int, ge=1),
        progress=lg["progress"], recording=_recording_name(lg["recording"]))
    if run.device in ("auto", "cuda"):
        import warp as wp

        if wp.is_cuda_available():
            run.device = "cuda"
        elif run.device == "cuda":
            raise ConfigError("run.device", "cuda: no CUDA device on this machine; accepted: auto, cpu")
        else:
            run.device = "cpu"
    return RunSpec(scene=scene, scene_name=str(sd.get("name")), scheme=scheme,
                   kernel=mpm.KERNELS[kernel_name], transfer=transfer, run=run, log=log, seed=seed,
                   integrator=integrator, detect=detect, stability_map=stability_map,
                   material_used=any(b.get("material") is None for b in sd["bodies"]))
