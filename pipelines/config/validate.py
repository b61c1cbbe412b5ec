"""Turn a composed config into the solver's plain dataclasses
(:class:`RunSpec`), checking every value against its definition
(:mod:`pipelines.config.schema`). Each problem raises :class:`ConfigError`
naming the full config key and the accepted values; nothing is compiled or
allocated here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import mpm
from mpm.integrators import Explicit
from mpm.meshes import MeshShape, file_digest

from .fields import ConfigError, check, number, plain
from .physics import make_detect, make_integrator, make_material, make_scheme
from .scene import make_scene
from .schema import Config
from .settings import KernelConfig, LogSettings, MapSpec, RunSettings

__all__ = ["ConfigError", "LogSettings", "MapSpec", "RunSettings", "RunSpec", "check_memory", "make_material",
           "memory_estimate", "resolve"]


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
    flip: float = 0.95  # the flip transfer's blend (mpm.SolverOptions.flip)
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


def _known_keys(cfg) -> None:
    """The top level's keys; a key added with ``+`` that no definition knows
    (``+foo=1``) would be ignored silently: refuse it, naming the accepted
    keys (deeper keys: each group's check)."""
    known = sorted(f.name for f in Config.__dataclass_fields__.values())
    for key in cfg:
        if key not in known and key != "hydra":
            raise ConfigError(key, f"unknown key; accepted: {', '.join(known)}")


def resolve(cfg) -> RunSpec:
    """Validate a composed :class:`pipelines.config.schema.Config`."""
    _known_keys(cfg)
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
                   material_used=any(b.material is None for b in sc.bodies))
