"""Material Point Method solvers on NVIDIA Warp (no Hydra, no Rerun here).

Build a :class:`Scene` (bodies of a shape and a material, walls, kinematic
regions, colliders, loads), turn it into a :class:`Model` and initial
:class:`State` with :func:`build`, and advance it with a :class:`Solver`:
step by step, or under the project's stability policy with a
:class:`Driver`, which reports to :class:`Observer` objects. SI units
throughout (m, s, kg, Pa). :data:`__all__` is the public API; docs/library.md
is its guide and docs/extending.md says how to add a material or a kernel.
"""

from . import analytic, checkpoint, responses
from .checkpoint import CheckpointError
from .colliders import BOUNDARIES as COLLIDER_BOUNDARIES
from .colliders import KINDS as COLLIDER_KINDS
from .colliders import Collider
from .joints import JOINT_TYPES, Joint
from .rigid_contact import RIGID_CONTACTS
from .rigid import RigidBody
from .integrators import INTEGRATORS, Explicit, Implicit
from .kernels import COMPACT, CUBIC, KERNELS, LINEAR, QUADRATIC, Kernel, register_kernel
from .loads import LOAD_KINDS, Load
from .materials import (MATERIALS, NACC, FixedCorotated, Fluid, Material, NeoHookean, Plastic, Sand, Snow,
                        Viscoplastic, Viscous, VonMises, register_material)
from .meshes import MeshShape
from .model import Model, SceneError, State, build
from .responses import Response
from .scene import (CONTACT_NORMALS, CONTACT_TYPES, WALL_TYPES, Body, Bowl, Box, Compound, ContactPair, Cylinder,
                    KinematicRegion, Rotated, Scene, Sphere, rotation_matrix)
from .schemes import AULMPM, EMPM, SCHEMES, TLMPM
from .solver import Solver, SolverOptions
from .stepping.detection import DETECTION_ACTIONS, Detection, Detector
from .stepping.driver import Driver, Event, Observer, Outcome, StepPolicy
from .stepping.plan import plan
from .stepping.status import StepReport
from .stepping.timestep import cfl_dt
from .transfer import TRANSFERS

__all__ = [
    # scenes
    "Scene", "Body", "Box", "Sphere", "Cylinder", "Bowl", "Compound", "MeshShape", "Rotated", "rotation_matrix",
    "KinematicRegion", "ContactPair",
    "Collider", "RigidBody", "Joint", "JOINT_TYPES", "RIGID_CONTACTS",
    "COLLIDER_KINDS", "COLLIDER_BOUNDARIES", "Load", "LOAD_KINDS", "WALL_TYPES",
    "CONTACT_TYPES",
    "CONTACT_NORMALS",
    # materials
    "Material", "MATERIALS", "FixedCorotated", "NeoHookean", "Fluid", "Viscous", "Plastic", "Snow", "Sand",
    "VonMises", "NACC", "Viscoplastic", "register_material",
    # kernels, transfers, schemes, integrators
    "Kernel", "KERNELS", "LINEAR", "QUADRATIC", "CUBIC", "COMPACT", "register_kernel", "TRANSFERS",
    "EMPM", "TLMPM", "AULMPM", "SCHEMES", "Explicit", "Implicit", "INTEGRATORS",
    # building and stepping
    "build", "Model", "State", "SceneError", "Solver", "SolverOptions", "plan",
    "Driver", "StepPolicy", "Detection", "Detector", "DETECTION_ACTIONS", "Observer", "Event", "Outcome",
    "StepReport", "cfl_dt", "Response", "responses", "checkpoint", "CheckpointError",
    # closed-form solutions
    "analytic",
]
