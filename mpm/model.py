"""Model (what does not change during a run) and State (what does).

Particles are stored grouped by material model, then by body, so every
material's kernels run over one contiguous range and every body is a
contiguous range too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from .kernels import KERNELS, Kernel
from .kernels.registry import kernel_problem
from .loads import LoadError, LoadTable, resolve
from .materials import Material
from .params import instance_problem, refusal, violations
from .sampling import PARTICLE_VOLUMES, sample_body, sampling_problem, shape_volume
from .joints import scene_problems as joint_problems
from .rigid_contact import scene_problems as rigid_contact_problems
from .rigid import scene_problems as rigid_problems
from .stencil import stencil_cache
from .scene import BOUNDARY_RULES, CONTACT_NORMALS, CONTACT_TYPES, WALL_TYPES, Scene, skew
from .types import PRECISIONS, Types, make_types


class SceneError(ValueError):
    """A scene that cannot be built; ``key`` names the offending field."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message


@dataclass
class MaterialGroup:
    """Particles ``[start, start + count)`` share the material model ``cls``."""

    cls: type[Material]
    start: int
    count: int


@dataclass
class Model:
    """Static data: grid geometry, walls, gravity, particle mass and volume,
    per-body material parameters."""

    scene: Scene
    """what was built"""
    types: Types
    """the Warp types of its dimension and precision"""
    kernel: Kernel
    """the interpolation kernel"""
    device: str
    """the Warp device ("cpu", "cuda:0")"""
    dx: float
    """the grid's cell [m]"""
    cells: tuple[int, ...]
    """cells per axis; nodes = cells + 1"""
    n_particles: int
    """particles of every body"""
    mass: wp.array
    """m_p [kg]"""
    volume: wp.array
    """V_p^0 [m^3]"""
    body: wp.array
    """body index per particle (int32)"""
    region: wp.array
    """kinematic region per particle: 0 none, r + 1 for scene.regions[r]"""
    body_params: wp.array
    """packed material parameters per body"""
    groups: list[MaterialGroup]
    """the bodies grouped by material model (one P2G each)"""
    body_ranges: list[tuple[int, int]]
    """(start, count) per body"""
    body_volumes: list[dict]
    """per body: the particles' volume [m^d], the shape's, the cells', and which was used"""
    wall_codes: tuple[tuple[int, ...], tuple[int, ...]]
    """(lo, hi) per axis"""
    loads: LoadTable | None = None
    """the external loads on the particles (mpm.loads); None: none"""

    @property
    def dim(self) -> int:
        return self.types.dim

    @property
    def nodes(self) -> tuple[int, ...]:
        return tuple(c + 1 for c in self.cells)

    @property
    def n_nodes(self) -> int:
        return int(np.prod(self.nodes))

    @property
    def strides(self) -> tuple[int, ...]:
        n = self.nodes
        return (n[1], 1) if self.dim == 2 else (n[1] * n[2], n[2], 1)

    @property
    def n_loads(self) -> int:
        return len(self.loads.loads) if self.loads is not None else 0

    @property
    def gravity(self) -> tuple[float, ...]:
        return tuple(self.scene.gravity)

    @property
    def domain(self) -> tuple[float, ...]:
        return tuple(c * self.dx for c in self.cells)

    @property
    def plastic(self) -> bool:
        """Does a body have a plastic model (history variables, return mapping)?"""
        return any(b.material.plastic for b in self.scene.bodies)

    def wave_speed(self) -> float:
        """Fastest elastic/acoustic wave speed of all bodies at rest [m/s]."""
        return max(b.material.wave_speed() for b in self.scene.bodies)


@dataclass
class State:
    """Time-varying particle data.

    ``X`` are the reference positions (at the last configuration update of the
    particle's body), ``F0s`` the deformation gradient at that update and
    ``Fsn`` the deformation since then, so F = Fsn F0s; for plastic models
    F0s keeps the elastic part, F_E = Fsn F0s, and ``history`` the plastic
    variables (mpm.materials.plastic). The stencil cache
    (first node, local coordinate, weights) belongs to the reference
    configuration and is recomputed with it (mpm.reference_update).
    """

    x: wp.array
    """current positions [m]"""
    v: wp.array
    """velocities [m/s]"""
    C: wp.array
    """affine matrices: velocity gradient w.r.t. the reference [1/s]"""
    F0s: wp.array
    """deformation gradient at the last configuration update"""
    Fsn: wp.array
    """deformation gradient since the last configuration update"""
    X: wp.array
    """reference positions [m]"""
    dJ: wp.array
    """|det Fsn - 1| after the last step (written when recorded)"""
    stencils: Any
    """the stencil cache, a Warp struct instance (mpm.stencil.make_stencil_cache)"""
    history: wp.array
    """history variables of plastic models (one unused entry without them)"""
    xc: wp.array | None = None
    """the running error [m] of the compensated sum x += dt v (mpm.g2p), where the
    solver compensates (mpm.SolverOptions.compensate; one unused entry otherwise)"""
    Fc: wp.array | None = None
    """the running error of the compensated sum F^sn += dt grad v (with the Eulerian
    scheme's commit in G2P: of F^0s's sum), where the solver compensates (one
    unused entry otherwise)"""

    def compensated(self, on: bool = True) -> None:
        """Where ``on``: allocate :attr:`xc` and :attr:`Fc` for every particle
        (zero: the sums start exact), unless they are."""
        n = self.x.shape[0]
        if on and (self.xc is None or self.xc.shape[0] != n):
            self.xc = wp.zeros(n, dtype=self.x.dtype, device=self.x.device)
            self.Fc = wp.zeros(n, dtype=self.Fsn.dtype, device=self.x.device)

    def numpy(self) -> dict[str, np.ndarray]:
        out = {k: getattr(self, k).numpy().copy()
               for k in ("x", "v", "C", "F0s", "Fsn", "X", "dJ", "history")}
        out["F"] = out["Fsn"] @ out["F0s"]
        return out


# The smallest singular value an initial deformation may have: an inverted
# (det F <= 0) or nearly degenerate start has no elastic state that a model
# recovers from (fixed corotated, defined for det F < 0, collapses such a
# ball to a point and turns non-finite; RESULTS.md, the extreme suite), and
# the blow-up detection's inversion criterion (mpm.stepping.detection) stops models
# that cannot invert at a stretch of 1e-3.
MIN_INITIAL_STRETCH = 1e-3


def check_contact(scene: Scene) -> None:
    """Raise :class:`SceneError` for a contact setting out of range."""
    if scene.contact not in CONTACT_TYPES:
        raise SceneError("contact", f"{scene.contact!r}; accepted: {', '.join(CONTACT_TYPES)}")
    if not 0.0 < scene.contact_fill <= 1.0:
        raise SceneError("contact_fill", f"{scene.contact_fill}; accepted: 0 < contact_fill <= 1")
    if not (np.isfinite(scene.contact_friction) and scene.contact_friction >= 0.0):
        raise SceneError("contact_friction", f"{scene.contact_friction}; accepted: a finite number >= 0")
    if scene.contact_normal not in CONTACT_NORMALS:
        raise SceneError("contact_normal", f"{scene.contact_normal!r}; accepted: {', '.join(CONTACT_NORMALS)}")
    if not 0.0 <= scene.contact_share < 1.0:
        raise SceneError("contact_share", f"{scene.contact_share}; accepted: 0 <= contact_share < 1")
    n = len(scene.bodies)
    for i, p in enumerate(scene.contact_pairs):
        if not (0 <= p.a < n and 0 <= p.b < n and p.a != p.b):
            raise SceneError(f"contact_pairs[{i}]", f"bodies {p.a}, {p.b}; accepted: two different bodies, "
                                                    f"0 to {n - 1}")
        if not (np.isfinite(p.friction) and p.friction >= 0.0):
            raise SceneError(f"contact_pairs[{i}].friction", f"{p.friction}; accepted: a finite number >= 0")
    if (scene.contact_pairs or scene.contact_friction > 0.0) and scene.contact not in ("friction", "elastic"):
        raise SceneError("contact", f"{scene.contact!r} with a friction coefficient set; accepted: friction, "
                                    "elastic (or contact_friction 0 and no contact_pairs)")
    if not 0.0 < scene.contact_stiffness <= 4.0:
        raise SceneError("contact_stiffness", f"{scene.contact_stiffness}; accepted: 0 < contact_stiffness <= 4")


def _numbers(value, count: int) -> np.ndarray | None:
    """``value`` as ``count`` finite floats (None: it is not)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    return a if a.shape == (count,) and np.all(np.isfinite(a)) else None


def _one_line(value) -> str:
    """A value (a nested list, an array) printed on one line."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    return " ".join(repr(value).split())[:120]


def check_body(i: int, b, d: int) -> None:
    """Raise :class:`SceneError` for body ``i``'s own fields: instances for
    its shape and material, its velocities and initial deformation."""
    key = f"bodies[{i}]"
    if not hasattr(b, "shape") or not hasattr(b, "material"):
        raise SceneError(key, f"{type(b).__name__}; accepted: an mpm.Body(shape, material)")
    problem = instance_problem(b.material, Material, "a material instance", "mpm.FixedCorotated(E=1e5)")
    if problem:
        raise SceneError(f"{key}.material", problem)
    if isinstance(b.shape, type) or not callable(getattr(b.shape, "bounds", None)):
        raise SceneError(f"{key}.shape", refusal(b.shape, "a shape instance", "mpm.Box(center, half_extents)"))
    if b.velocity is not None and _numbers(b.velocity, d) is None:
        raise SceneError(f"{key}.velocity", f"{_one_line(b.velocity)}; accepted: {d} finite numbers [m/s]")
    if b.angular_velocity is not None:
        n = 1 if d == 2 else 3
        w = b.angular_velocity if d == 3 or np.ndim(b.angular_velocity) else [b.angular_velocity]
        if _numbers(w, n) is None:
            raise SceneError(f"{key}.angular_velocity", f"{_one_line(b.angular_velocity)}; accepted: "
                             + ("one finite number [rad/s]" if d == 2 else "3 finite numbers [rad/s]"))
    if b.ppc is not None and (not isinstance(b.ppc, (int, np.integer)) or isinstance(b.ppc, bool) or b.ppc < 1):
        raise SceneError(f"{key}.ppc", f"{_one_line(b.ppc)}; accepted: an integer >= 1, or None (the scene's)")
    if (problem := sampling_problem(b.sampling, b.shape)) is not None:
        raise SceneError(f"{key}.sampling", problem)
    if b.deformation is not None:
        try:
            F = np.asarray(b.deformation, float)
        except (TypeError, ValueError):
            F = np.zeros(0)
        if (F.shape != (d, d) or not np.all(np.isfinite(F)) or np.linalg.det(F) <= 0.0
                or np.linalg.svd(F, compute_uv=False).min() < MIN_INITIAL_STRETCH):
            raise SceneError(f"{key}.deformation",
                             f"{_one_line(b.deformation)}; accepted: {d} rows of {d} finite numbers with det F > 0 "
                             f"and every singular value >= {MIN_INITIAL_STRETCH:g} (no inverted or degenerate start)")


def check_scene(scene: Scene, kernel: Kernel) -> None:
    """Raise :class:`SceneError` for anything that would make the scene unbuildable."""
    if not isinstance(scene, Scene):
        raise SceneError("scene", instance_problem(scene, Scene, "an mpm.Scene", "mpm.Scene(dim=2, ...)"))
    problem = kernel_problem(kernel, factories=False)
    if problem:
        raise SceneError("kernel", problem)
    d = scene.dim
    if d not in (2, 3):
        raise SceneError("dim", f"{d} not supported; accepted: 2, 3")
    if len(scene.domain) != d or any(L <= 0 for L in scene.domain):
        raise SceneError("domain", f"{list(scene.domain)}; accepted: {d} positive lengths")
    if scene.resolution < 4:
        raise SceneError("resolution", f"{scene.resolution}; accepted: an integer >= 4")
    dx = scene.dx
    for a, L in enumerate(scene.domain):
        if abs(L / dx - round(L / dx)) > 1e-9 * L / dx:
            raise SceneError("domain", f"{L} along axis {a} is not a multiple of dx = {dx:g}")
    if _numbers(scene.gravity, d) is None:
        raise SceneError("gravity", f"{_one_line(scene.gravity)}; accepted: {d} finite numbers [m/s^2]")
    if scene.boundary_rule not in BOUNDARY_RULES:
        raise SceneError("boundary_rule", f"{scene.boundary_rule!r}; accepted: {', '.join(BOUNDARY_RULES)}")
    if len(scene.walls) != 2 * d or any(w not in WALL_TYPES for w in scene.walls):
        raise SceneError("walls", f"{list(scene.walls)}; accepted: {2 * d} of {', '.join(WALL_TYPES)}")
    if scene.ppc < 1:
        raise SceneError("ppc", f"{scene.ppc}; accepted: an integer >= 1")
    if scene.particle_volume not in PARTICLE_VOLUMES:
        raise SceneError("particle_volume", f"{scene.particle_volume!r}; accepted: {', '.join(PARTICLE_VOLUMES)}")
    if not 0.0 <= scene.jitter <= 1.0:
        raise SceneError("jitter", f"{scene.jitter}; accepted: 0 <= jitter <= 1")
    if scene.lattice_offset is not None and (len(scene.lattice_offset) != d
                                             or not np.all(np.isfinite(scene.lattice_offset))):
        raise SceneError("lattice_offset", f"{scene.lattice_offset}; accepted: {d} finite numbers [cells]")
    for i, b in enumerate(scene.bodies):
        check_body(i, b, d)
    if not scene.bodies:
        raise SceneError("bodies", "empty; accepted: at least one body")
    check_contact(scene)
    for r, reg in enumerate(scene.regions):
        if not 0 <= reg.body < len(scene.bodies):
            raise SceneError(f"regions[{r}].body", f"{reg.body}; accepted: 0 to {len(scene.bodies) - 1}")
        if not reg.start < reg.end:
            raise SceneError(f"regions[{r}].end", f"{reg.end} <= start {reg.start}")
    for i, load in enumerate(scene.loads):
        for name, message in load.problems(d, len(scene.bodies)):
            raise SceneError(f"loads[{i}].{name}", message)
        if load.at is not None and len(load.at) == d and not all(0.0 <= a <= L for a, L in zip(load.at, scene.domain)):
            raise SceneError(f"loads[{i}].at", f"{list(load.at)} lies outside the domain; accepted: a point in "
                                               + " x ".join(f"[0, {L:g}]" for L in scene.domain) + " [m]")
    for i, c in enumerate(scene.colliders):
        for name, message in c.problems(d):
            raise SceneError(f"colliders[{i}].{name}", message)
    for key, message in rigid_problems(scene) + joint_problems(scene) + rigid_contact_problems(scene):
        raise SceneError(key, message)
    if scene.loads and getattr(scene.solution, "has_body_force", False):
        raise SceneError("loads", "given with a manufactured solution, whose body force they would replace; "
                                  "accepted: no loads with that solution")
    lo = scene.wall_cells * dx
    for i, b in enumerate(scene.bodies):
        key = f"bodies[{i}]"
        for name, value, accepted in violations(b.material):
            raise SceneError(f"{key}.material.{name}", f"{value} out of range; accepted: {accepted}")
        for name, message in b.material.problems():
            raise SceneError(f"{key}.material.{name}", message)
        blo, bhi = (np.asarray(v, float) for v in b.shape.bounds())
        if len(blo) != d:
            raise SceneError(f"{key}.shape", f"has {len(blo)} coordinates; accepted: {d}")
        hi = np.asarray(scene.domain) - lo
        if np.any(hi <= lo):  # the walls leave no interior at all: their thickness is the problem
            axis = int(np.argmax(hi <= lo))
            raise SceneError("wall_cells", f"{scene.wall_cells} cells ({scene.wall_cells * dx:.4g} m) per face "
                                           f"leave no interior along axis {axis} (domain {scene.domain[axis]:g} m); "
                                           f"accepted: wall_cells < {int(np.ceil(min(scene.domain) / (2 * dx)))}")
        if np.any(blo < lo - 1e-12) or np.any(bhi > hi + 1e-12):
            box = lambda a, b: " x ".join(f"[{x:.4g}, {y:.4g}]" for x, y in zip(a, b))  # noqa: E731
            raise SceneError(
                key, f"particles outside the domain: the shape spans {box(blo, bhi)}; accepted: "
                f"within {box([lo] * d, hi)} (the domain minus {scene.wall_cells} wall cells)")


def _rigid_velocity(body, x, dim):
    v = np.zeros_like(x)
    C = np.zeros((len(x), dim, dim))
    if body.velocity is not None:
        v += np.asarray(body.velocity, float)
    if body.angular_velocity is not None:
        r = x - np.asarray(body.shape.center, float)
        W = skew(body.angular_velocity, dim)
        v += r @ W.T
        C[:] = W  # exact velocity gradient of the rigid rotation
    return v, C


@dataclass
class BodySample:
    """One body's particles as :func:`build` places them."""

    x: np.ndarray
    """positions [m], the initial deformation applied"""
    volume: float | np.ndarray
    """each particle's volume [m^d] (per particle (n,) for shells sampling)"""
    F: np.ndarray
    """the initial deformation gradient (d, d)"""
    volumes: dict
    """the body's volume [m^d]: "volume" (used), "shape", "cells", "used" (which)"""


def sample_bodies(scene: Scene, seed: int = 0) -> list[BodySample]:
    """Every body's particles in body order from one generator seeded with
    ``seed`` (sampled in the reference shape, placed deformed); a body may
    hold none (:func:`build` refuses it)."""
    d, dxp = scene.dim, scene.particle_dx
    rng = np.random.default_rng(seed)
    raw = [sample_body(b.shape, b.sampling, d, dxp, b.ppc or scene.ppc, s, scene.jitter, rng, scene.lattice_offset)
           for b, s in zip(scene.bodies, scene.spacings())]
    out = []
    for b, (x, layered) in zip(scene.bodies, raw):
        n, cell = len(x), dxp**d / (b.ppc or scene.ppc)
        V = shape_volume(b.shape, d)
        used = "shape" if V is not None and (scene.particle_volume == "shape" or layered is not None) else "cells"
        each = layered if layered is not None else V / n if V is not None and used == "shape" and n else cell
        F = np.eye(d)
        if b.deformation is not None:
            F = np.asarray(b.deformation, float)
            c = 0.5 * (np.asarray(b.shape.bounds()[0], float) + np.asarray(b.shape.bounds()[1], float))
            x = c + (x - c) @ F.T
        out.append(BodySample(x, each, F,
                              {"volume": V if used == "shape" else n * cell, "shape": V, "cells": n * cell,
                               "used": used}))
    return out


def build(scene: Scene, kernel: Kernel, precision: str = "float32", device: str = "cpu",
          seed: int = 0, samples: list[BodySample] | None = None) -> tuple[Model, State]:
    """Sample the bodies and allocate the model and initial state on ``device``
    (``kernel``: a Kernel, or its name in mpm.KERNELS).
    ``samples``: the bodies' particles already drawn by :func:`sample_bodies`
    for this scene and seed (a config check's), used instead of sampling again."""
    if isinstance(kernel, str):  # a kernel's name (mpm.KERNELS)
        kernel = KERNELS[kernel]
    check_scene(scene, kernel)
    if precision not in PRECISIONS:
        raise SceneError("precision", f"{precision!r}; accepted: {', '.join(PRECISIONS)}")
    t = make_types(scene.dim, precision)
    d, dx = scene.dim, scene.dx

    # material models in order of first appearance; bodies grouped by model
    models = list(dict.fromkeys(type(b.material) for b in scene.bodies))
    order = sorted(range(len(scene.bodies)), key=lambda i: models.index(type(scene.bodies[i].material)))
    samples = sample_bodies(scene, seed) if samples is None else samples
    for i, s in enumerate(samples):
        if len(s.x) == 0:
            raise SceneError(f"bodies[{i}].shape", "holds no particle; accepted: a shape larger than a cell")

    xs, vs, Cs, ms, Vs, ids, hs, Fs = [], [], [], [], [], [], [], []
    body_ranges: list = [None] * len(scene.bodies)  # (start, count) of each body, set below
    volumes: list[dict] = [s.volumes for s in samples]
    groups: list[MaterialGroup] = []
    start = 0
    for i in order:
        b, x, vol, F = scene.bodies[i], samples[i].x, samples[i].volume, samples[i].F
        n = len(x)
        Fs.append(np.broadcast_to(F, (n, d, d)))
        v, C = _rigid_velocity(b, x, d)
        if scene.solution is not None:
            v, C = scene.solution.velocity(x, 0.0), scene.solution.velocity_gradient(x, 0.0)
        xs.append(x)
        vs.append(v)
        Cs.append(C)
        Vs.append(np.full(n, vol))
        ms.append(np.full(n, vol * b.material.rho))
        ids.append(np.full(n, i, np.int32))
        hs.append(np.tile(b.material.initial_history() if b.material.plastic else (0.0, 0.0), (n, 1)))
        body_ranges[i] = (start, n)
        cls = type(b.material)
        if groups and groups[-1].cls is cls:
            groups[-1].count += n
        else:
            groups.append(MaterialGroup(cls, start, n))
        start += n

    x = np.concatenate(xs)
    n = len(x)
    region = np.zeros(n, np.int32)
    for r, reg in enumerate(scene.regions):
        start, count = body_ranges[reg.body]
        inside = reg.select.contains(x[start:start + count])
        if not inside.any():
            raise SceneError(f"regions[{r}].select", "selects no particle of its body")
        region[start:start + count][inside] = r + 1
    V = np.concatenate(Vs)
    loads = None
    if scene.loads:
        try:
            loads = resolve(scene.loads, x, V, np.concatenate(ids), body_ranges, scene.spacings(), dx,
                            [b.name or f"body{i}" for i, b in enumerate(scene.bodies)])
        except LoadError as e:
            raise SceneError(f"loads[{e.index}].{e.key}", e.message) from None
    S = np.float32 if precision == "float32" else np.float64
    codes = {w: WALL_TYPES.index(w) for w in WALL_TYPES}
    wall_codes = (tuple(codes[w] for w in scene.walls[0::2]), tuple(codes[w] for w in scene.walls[1::2]))
    with wp.ScopedDevice(device):
        model = Model(
            scene=scene, types=t, kernel=kernel, device=device, dx=dx, cells=scene.cells,
            n_particles=n,
            mass=wp.array(np.concatenate(ms).astype(S), dtype=t.scalar),
            volume=wp.array(V.astype(S), dtype=t.scalar),
            body=wp.array(np.concatenate(ids), dtype=wp.int32),
            region=wp.array(region, dtype=wp.int32),
            body_params=wp.array(np.array([b.material.packed_padded() for b in scene.bodies], S),
                                 dtype=t.params),
            groups=groups, body_ranges=body_ranges, body_volumes=volumes, wall_codes=wall_codes, loads=loads,
        )
        eye = np.tile(np.eye(d, dtype=S), (n, 1, 1))
        state = State(
            x=wp.array(x.astype(S), dtype=t.vec),
            v=wp.array(np.concatenate(vs).astype(S), dtype=t.vec),
            C=wp.array(np.concatenate(Cs).astype(S), dtype=t.mat),
            F0s=wp.array(np.concatenate(Fs).astype(S), dtype=t.mat),
            Fsn=wp.array(eye, dtype=t.mat),
            X=wp.array(x.astype(S), dtype=t.vec),
            dJ=wp.zeros(n, dtype=t.scalar),
            stencils=stencil_cache(t, kernel, n),
            history=wp.array(np.concatenate(hs).astype(S) if model.plastic else np.zeros((1, 2), S),
                             dtype=t.history),
            xc=wp.zeros(1, dtype=t.vec),  # (mpm.Solver.prepare: every particle's where it compensates)
            Fc=wp.zeros(1, dtype=t.mat),
        )
    return model, state
