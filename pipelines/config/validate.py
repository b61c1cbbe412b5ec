"""Turn a composed config into the solver's plain dataclasses
(:class:`RunSpec`), checking every value against its definition
(:mod:`pipelines.config.schema`). Each problem raises :class:`ConfigError`
naming the full config key and the accepted values; nothing is compiled or
allocated here.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from omegaconf import OmegaConf

import mpm
from mpm.integrators import Explicit
from mpm.meshes import MeshShape, file_digest
from mpm.model import sample_bodies

from .fields import ConfigError, check, number, plain
from .overrides import check_kinds, check_literals
from .particles import check_particles
from .physics import make_detect, make_integrator, make_material, make_scheme
from .scene import make_responses, make_scene
from .schema import Config
from .settings import KernelConfig, LogSettings, MapSpec, RunSettings

__all__ = ["ConfigError", "LogSettings", "MapSpec", "RunSettings", "RunSpec", "check_memory", "make_material",
           "memory_estimate", "resolve", "validate"]


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
    detect: mpm.Detection = field(default_factory=mpm.Detection)  # blow-up detection (mpm.stepping.detection)
    stability_map: MapSpec | None = None  # the job is a stability map (pipelines.run.stability_map)
    flip: float = 0.95  # the flip transfer's blend (mpm.SolverOptions.flip)
    material_used: bool = True  # some body takes the material group (else every body brings its own)
    # the particles the check sampled (mpm.model.sample_bodies), handed to mpm.build once (take_samples)
    samples: list | None = field(default=None, repr=False, compare=False)
    responses: list = field(default_factory=list)  # mpm.Response: what the run measures (scene.responses)

    def take_samples(self) -> list | None:
        """The checked particles for ``mpm.build(..., samples=)``, released
        from the spec (build keeps its own arrays; a second build samples)."""
        samples, self.samples = self.samples, None
        return samples

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
    contact = len(scene.bodies) if len(scene.bodies) > 1 and scene.contact in ("frictionless", "friction") else 0
    per_node = s * ((1 + 2 * d) * 2 * G + (1 + d) * contact) + 8  # the grids; contact's M and P per body
    return particles * per_particle + nodes * per_node, particles, nodes


def _memory_key(scene: mpm.Scene, kernel: mpm.Kernel, precision: str) -> str:
    """The setting that makes a run too large: the particles per cell of the
    body with the most particles when particles take most of the memory at
    more than ``PPC_TYPICAL`` per cell, else the grid (or the particles' grid)."""
    need, particles, nodes = memory_estimate(scene, kernel, precision)
    grid_only = memory_estimate(replace(scene, bodies=[]), kernel, precision)[0]
    if need - grid_only > grid_only:  # the particles' share is the larger
        counts = [memory_estimate(replace(scene, bodies=[b]), kernel, precision)[1] for b in scene.bodies]
        i = int(np.argmax(counts))
        body = scene.bodies[i]
        if (body.ppc or scene.ppc) > PPC_TYPICAL:
            return f"scene.bodies[{i}].ppc" if body.ppc else "scene.ppc"
        if scene.particle_resolution is not None:
            return "scene.particle_resolution"
    return "scene.resolution"


PPC_TYPICAL = 27  # particles per cell that the scenes use at most (3^3)


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
        key = _memory_key(scene, kernel, precision)
        raise ConfigError(key, f"the run needs about {need / gib:.3g} GiB ({particles:.3g} particles, "
                               f"{nodes:.3g} grid nodes), more than {MEMORY_FRACTION:.0%} of this machine's "
                               f"{have / gib:.3g} GiB; accepted: a smaller grid or fewer particles per cell")


def _known_keys(cfg) -> None:
    """The top level's keys; a key added with ``+`` that no definition knows
    (``+foo=1``) would be ignored silently: refuse it, naming the accepted
    keys (deeper keys: each group's check)."""
    known = sorted(f.name for f in Config.__dataclass_fields__.values())
    for key in cfg:
        if key not in known and key != "hydra":
            raise ConfigError(key, f"unknown key; accepted: {', '.join(known)}")


@functools.cache
def _scale_keys() -> dict:
    """Every key of the files of ``conf/scale`` (nested mappings merged)."""
    import yaml

    from .schema import CONF

    def merge(into: dict, d: dict) -> dict:
        for k, v in d.items():
            if isinstance(v, dict):
                merge(into.setdefault(k, {}), v)
            else:
                into.setdefault(k, None)
        return into

    known: dict = {}
    for path in sorted((CONF / "scale").glob("*.yaml")):
        merge(known, yaml.safe_load(path.read_text()) or {})
    return known


def _known_scale(value, known: dict, key: str = "scale") -> None:
    """A key under ``scale`` that no file of ``conf/scale`` has would be read
    by nothing: refuse it (``+scale.<name>=...``)."""
    if not isinstance(value, dict):
        return
    for k, v in value.items():
        if k not in known:
            raise ConfigError(f"{key}.{k}", f"unknown key; accepted: {', '.join(sorted(known))}")
        if isinstance(known[k], dict):
            _known_scale(v, known[k], f"{key}.{k}")


def _explicit_only(scene) -> None:
    """ConfigError naming the first elastic collider or rigid body, or elastic contact between bodies (their
    springs act in the explicit step only)."""
    if scene.contact == "elastic":
        raise ConfigError("scene.contact", "elastic under integrator=implicit (its springs act in the explicit step, "
                                           "mpm.body_springs); accepted: frictionless, friction, none or shared, or "
                                           "integrator=explicit")
    shapes = [(f"scene.colliders[{i}].boundary", c) for i, c in enumerate(scene.colliders)]
    shapes += [(f"scene.rigid_bodies[{i}].shape.boundary", b.shape) for i, b in enumerate(scene.rigid_bodies or ())]
    for key, c in shapes:
        if c.boundary == "elastic":
            raise ConfigError(key, "elastic under integrator=implicit (its springs act in the explicit step, "
                                   "mpm.elastic_contact); accepted: sticky, slip or separate, or integrator=explicit")


def resolve(cfg) -> RunSpec:
    """Validate a composed :class:`pipelines.config.schema.Config`."""
    _known_keys(cfg)
    if cfg.get("scale") is not None:
        _known_scale(OmegaConf.to_container(cfg.scale, resolve=False), _scale_keys())
    run = check(RunSettings, plain(cfg.run), "run")
    scheme = make_scheme(cfg.scheme)
    integrator = make_integrator(cfg.integrator) if "integrator" in cfg else Explicit()
    detect = make_detect(cfg.detect) if "detect" in cfg else mpm.Detection()
    points = plain(cfg.get("stability_map"))
    stability_map = None if points is None else check(MapSpec, points, "stability_map")
    kernel = check(KernelConfig, plain(cfg.kernel), "kernel")
    material = make_material(cfg.material, "material")
    seed = number("seed", cfg.seed, int, {"keyed": True, "ge": 0})
    scene, sc = make_scene(cfg.scene, material, seed=seed)
    try:
        mpm.model.check_scene(scene, mpm.KERNELS[kernel.name])
    except mpm.SceneError as e:
        raise ConfigError(f"scene.{e.key}", e.message) from None
    if scene.contact == "shared" and scheme.name != "empm":
        raise ConfigError("scene.contact", "'shared' (one grid for all bodies) needs scheme=empm; "
                                           "accepted with other schemes: frictionless, none")
    if not isinstance(integrator, Explicit):
        _explicit_only(scene)
    if run.graph and (scene.joints or scene.rigid_contact != "none"):
        raise ConfigError("run.graph", "true: a scene with joints or rigid contact reads each step back for "
                                       "Newton's solver (mpm.joints), which a CUDA graph cannot hold; accepted: "
                                       "false or null")
    if run.steps is None and run.duration is None:
        run.duration = sc.duration
    log = check(LogSettings, plain(cfg.log), "log")
    log.resolve_color(scene)
    if run.device in ("auto", "cuda"):
        import warp as wp

        if wp.is_cuda_available():
            run.device = "cuda"
        elif run.device == "cuda":
            raise ConfigError("run.device", "cuda: no CUDA device on this machine; accepted: auto, cpu")
        else:
            run.device = "cpu"
    return RunSpec(scene=scene, scene_name=str(sc.name), scheme=scheme, kernel=mpm.KERNELS[kernel.name],
                   transfer=kernel.transfer, run=run, log=log, seed=seed, integrator=integrator, detect=detect,
                   stability_map=stability_map, flip=kernel.flip,
                   material_used=any(b.material is None for b in sc.bodies),
                   responses=make_responses(sc, scene))


def compose_spec(overrides: list[str]) -> RunSpec:
    """The spec of config ``overrides`` composed as the command line composes
    them (conf/, Hydra's compose API), resolved; for tools outside
    ``pipelines.run``."""
    from hydra import compose, initialize_config_dir

    from . import plugins, schema

    plugins.prepare(overrides)  # MPM_PLUGINS and dotted paths (pipelines.config.plugins)
    schema.register()
    with initialize_config_dir(config_dir=str(schema.CONF), version_base="1.3"):
        return resolve(compose(config_name="config", overrides=list(overrides)))


def validate(cfg, overrides: Sequence[str] = ()) -> tuple[RunSpec, list[str]]:
    """Everything ``pipelines.run`` checks before a run starts: the
    overrides' literals and kinds set by key
    (:func:`pipelines.config.overrides.check_literals`, ``check_kinds``),
    the config (:func:`resolve`), this machine's memory
    (:func:`check_memory`) and the particles
    (:func:`pipelines.config.particles.check_particles`); returns the spec
    and the warnings to print."""
    check_literals(cfg, list(overrides))
    check_kinds(cfg, list(overrides))
    spec = resolve(cfg)
    check_memory(spec)
    spec.samples = sample_bodies(spec.scene, spec.seed)
    return spec, check_particles(spec.scene, spec.seed, samples=spec.samples) + step_warnings(spec)


def step_warnings(spec: RunSpec) -> list[str]:
    """A fixed explicit ``run.dt`` above the step limit of a body at rest
    (mpm.stepping.timestep, CFL 1: the wave speed and the initial speed), said before
    the run whatever the material (a hardening one only stiffens from there)."""
    if spec.run.dt is None or spec.integrator.name != "explicit":
        return []
    from mpm.stepping.timestep import cfl_dt

    scene = spec.scene
    limits = []
    for i, b in enumerate(scene.bodies):
        speed = float(np.linalg.norm(b.velocity)) if b.velocity is not None else 0.0
        limits.append((cfl_dt(scene.dx, b.material.wave_speed(), speed, 1.0, b.material.kinematic_viscosity(),
                              scene.dim), i))
    limit, i = min(limits)
    if spec.run.dt <= limit:
        return []
    body = scene.bodies[i]
    hardens = " (a plastic material: hardening only lowers it)" if body.material.plastic else ""
    return [f"run.dt={spec.run.dt:g} s is {spec.run.dt / limit:.3g} times the explicit step's stability limit, "
            f"the CFL limit dx / (c + |v|) = {limit:.3g} s of body '{body.name or f'body{i}'}' ({body.material.name}) "
            f"at rest{hardens}: expect the run to blow up (stable: run.dt <= {limit:.3g}, or run.dt=null, the "
            f"adaptive step)"]
