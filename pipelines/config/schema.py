"""Structured configs: the schema of every config group, registered with
Hydra's ConfigStore so that a misspelt key fails at composition.

Materials and schemes use the solver's own dataclasses (``mpm.materials``,
``mpm.schemes``) as their schemas; the scene, run and log settings are
defined here because they describe a run, not the physics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from mpm.colliders import BOUNDARIES, KINDS as COLLIDERS
from mpm.integrators import INTEGRATORS
from mpm.stability import Detection
from mpm.materials import MATERIALS
from mpm.scene import CONTACT_TYPES as CONTACTS
from mpm.schemes import SCHEMES

PRECISIONS = ("float32", "float64")
DEVICES = ("auto", "cpu", "cuda")
SHAPES = ("box", "sphere", "cylinder", "bowl", "mesh", "compound")
__all__ = ["BOUNDARIES", "COLLIDERS", "CONTACTS", "DEVICES", "PRECISIONS", "SHAPES", "register"]


@dataclass
class KernelConfig:
    """Interpolation kernel and the transfer that uses it."""

    name: str = "quadratic"
    transfer: str = "mls"  # mls | apic | pic


@dataclass
class ShapeConfig:
    """A shape: ``box`` (center, half_size), ``sphere`` (center, radius; a
    disc in 2D), ``cylinder`` (3D: center, radius, half_height, axis),
    ``bowl`` (a spherical cap shell: sphere center, inner radius, thickness,
    rim height above the centre along ``axis``, the opening),
    ``mesh`` (3D: a closed triangle mesh ``mesh`` - an OBJ/PLY/STL/USD path or
    ``warp:bunny`` - scaled to ``size``, centred at center, ``axis`` up) or
    ``compound`` (the union of ``parts``, each a shape mapping). ``rotation``
    [degrees] turns any shape about its centre: an angle in 2D, three angles
    about x, y, z in 3D, or ``random`` (drawn from the run's seed)."""

    type: str = "box"
    center: Optional[List[float]] = None  # [m]
    half_size: Optional[List[float]] = None  # [m]
    radius: Optional[float] = None  # [m]
    half_height: Optional[float] = None  # [m]
    axis: Optional[int] = None  # 0, 1 or 2 (default 1: along y)
    inner_radius: Optional[float] = None  # [m] cylinder or sphere: hollow inside this radius
    mesh: Optional[str] = None
    size: Optional[float] = None  # [m] largest side of the mesh's bounding box
    thickness: Optional[float] = None  # [m] bowl wall
    rim: Optional[float] = None  # [m] bowl: rim plane above the sphere's centre
    rotation: Optional[Any] = None  # [deg] angle (2D), [x, y, z] angles (3D) or "random"
    parts: Optional[List[Any]] = None


@dataclass
class ColliderConfig:
    """A rigid collider (mpm.colliders): ``type`` one of half_space (point,
    normal), wedge (point, normals), box (center, half_size), sphere (center,
    radius), cylinder (center, radius, half_height, axis), cup (center,
    radius, depth, thickness, axis), bowl (center, radius, thickness, rim,
    axis) or mesh (3D: mesh, center, size, axis); ``inside: true`` makes the
    shape a container. ``boundary`` sticky | slip | separate with Coulomb
    ``friction``; ``velocity`` [m/s] moves it while start <= t < end [s]."""

    type: str = "half_space"
    name: str = ""
    boundary: str = "slip"
    friction: float = 0.0
    inside: bool = False
    point: Optional[List[float]] = None  # [m]
    normal: Optional[List[float]] = None
    normals: Optional[List[Any]] = None
    center: Optional[List[float]] = None  # [m]
    half_size: Optional[List[float]] = None  # [m]
    radius: Optional[float] = None  # [m]
    half_height: Optional[float] = None  # [m]
    depth: Optional[float] = None  # [m]
    thickness: Optional[float] = None  # [m]
    rim: Optional[float] = None  # [m]
    axis: Optional[Any] = None  # 0, 1, 2 or a direction (default 1: +y)
    mesh: Optional[str] = None
    size: Optional[float] = None  # [m]
    velocity: Optional[List[float]] = None  # [m/s]
    start: float = 0.0  # [s]
    end: Optional[float] = None  # [s]; null: forever


@dataclass
class BodyConfig:
    """One body. ``material: null`` takes the ``material`` config group; a
    mapping with a ``model`` key gives the body its own material."""

    name: str = ""
    shape: ShapeConfig = field(default_factory=ShapeConfig)
    material: Optional[Any] = None
    velocity: Optional[List[float]] = None  # [m/s]
    angular_velocity: Optional[Any] = None  # [rad/s]: scalar (2D) or 3-vector (3D)
    ppc: Optional[int] = None  # particles per cell, overrides the scene's
    deformation: Optional[Any] = None  # initial deformation gradient F (d x d rows; det < 0: inverted)


@dataclass
class RegionConfig:
    """A kinematic boundary region: the particles of ``body`` (index or name)
    whose initial position is inside ``select`` move with ``velocity`` [m/s],
    ``angular_velocity`` [rad/s] and ``velocity_gradient`` [1/s] (d x d rows:
    a homogeneous stretch or shear) about ``center`` (default: the centre of
    ``select``, moving with the velocity) while start <= t < end [s]."""

    name: str = ""
    body: Any = 0
    select: ShapeConfig = field(default_factory=ShapeConfig)
    velocity: Optional[List[float]] = None
    angular_velocity: Optional[Any] = None
    velocity_gradient: Optional[Any] = None
    center: Optional[List[float]] = None
    start: float = 0.0
    end: Optional[float] = None  # null: forever


@dataclass
class SceneConfig:
    """Domain [0, domain[d]] per axis, a grid of ``resolution`` cells along x."""

    name: str = MISSING
    dim: int = 2
    domain: List[float] = field(default_factory=lambda: [1.0, 1.0])  # [m]
    resolution: int = 64  # grid cells along x
    duration: float = 1.0  # default simulated time [s]
    gravity: List[float] = field(default_factory=lambda: [0.0, -9.81])  # [m/s^2]
    walls: Any = "slip"  # one of sticky|slip|open, or one per face (x_lo, x_hi, y_lo, ...)
    wall_cells: int = 3  # wall thickness [cells]
    ppc: int = 4  # particles per cell
    jitter: float = 0.0  # random displacement of lattice samples [fraction of spacing]
    lattice_offset: Optional[List[float]] = None  # shift of the sampling lattice [cells]; ppc 1 + 0.5: on nodes
    contact: str = "frictionless"  # between bodies: frictionless | none | shared (one grid, EMPM)
    contact_fill: float = 0.5  # node volume fraction the bodies must fill for contact
    bodies: List[BodyConfig] = field(default_factory=list)
    regions: List[RegionConfig] = field(default_factory=list)
    colliders: List[ColliderConfig] = field(default_factory=list)
    size: str = "default"  # a key of sizes: its values replace resolution, ppc, ...
    sizes: Dict[str, Any] = field(default_factory=dict)  # name -> {resolution: ..., ppc: ...}
    particle_resolution: Optional[int] = None  # sample particles as on this grid (fixed particle set)
    solution: Optional[Any] = None  # closed-form solution: {type: vibrating_bar|vortex, ...}


@dataclass
class RunConfig:
    """How long and how to step."""

    steps: Optional[int] = None  # number of steps (exclusive with duration)
    duration: Optional[float] = None  # simulated time [s]; null: the scene's
    dt: Optional[float] = None  # fixed time step [s]; null: adaptive (explicit: CFL; implicit: displacement)
    cfl: float = 0.4  # CFL number of the adaptive step
    dt_max: float = 1.0e-3  # largest adaptive step [s]
    dt_collapse: float = 1.0e-4  # unstable when the adaptive step falls below this fraction of the first
    precision: str = "float32"  # float32 | float64
    # auto (cuda when Warp finds a GPU, else cpu) | cpu | cuda; the environment's MPM_DEVICE, if set
    device: str = "${oc.env:MPM_DEVICE,auto}"
    force: bool = False  # in a sweep: run even if a job with the same config hash finished
    plan: bool = False  # print the stages and kernels of a step and exit (nothing compiled or run)
    # explicit EMPM locates stencils in P2G/G2P, G2P updates the reference (same results); null: where it pays
    fuse: Optional[bool] = None
    reference: Optional[str] = None  # a run directory (or its final_state.npz) to measure the error against


@dataclass
class LogConfig:
    """What goes into the recording."""

    every: Optional[int] = None  # particles every N steps; 0: none; null: log.fps frames per simulated second
    fps: float = 60.0  # particle frames per simulated second (when log.every is null)
    # particle colour: auto (plastic_strain with a plastic body, else dJ) | dJ | plastic_strain | body
    color: str = "auto"
    size_warning_mb: float = 1000.0  # warn before a run whose recording would be larger [MB]
    dJ: bool = True  # the per-particle dJ field with the particles
    fracture_every: int = 20  # steps between evaluations of the fracture measure (and at the end)
    scalars: bool = True  # physics scalars every step
    flush_every: int = 500  # steps between batched scalar sends
    progress: Optional[bool] = None  # progress bar; null: on a terminal
    recording: str = "recording.rrd"  # file name inside the run directory


@dataclass
class Config:
    scheme: Any = MISSING
    integrator: Any = MISSING
    kernel: KernelConfig = MISSING
    material: Any = MISSING
    scene: SceneConfig = MISSING
    run: RunConfig = field(default_factory=RunConfig)
    log: LogConfig = field(default_factory=LogConfig)
    detect: Detection = field(default_factory=Detection)  # blow-up detection (mpm.stability)
    seed: int = 0
    scale: Any = None  # sizes of the named experiments (conf/scale), read by conf/experiment
    stability_map: Optional[Any] = None  # {E, dt_cfl, steps}: the job is a stability map (pipelines.sweeps.stability)
    expected: Optional[str] = None  # the outcome a case of the extreme suite should have (conf/extreme)


def register() -> None:
    """Register the schemas; group files name them in their defaults lists."""
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=Config)
    cs.store(group="kernel", name="kernel_schema", node=KernelConfig)
    cs.store(group="scene", name="scene_schema", node=SceneConfig)
    for name, cls in MATERIALS.items():
        cs.store(group="material", name=f"{name}_schema", node=cls)
    for name, cls in SCHEMES.items():
        cs.store(group="scheme", name=f"{name}_schema", node=cls)
    for name, cls in INTEGRATORS.items():
        cs.store(group="integrator", name=f"{name}_schema", node=cls)
