"""Material Point Method solvers on NVIDIA Warp (no Hydra, no Rerun here).

Build a :class:`Scene`, turn it into a :class:`Model` and initial
:class:`State` with :func:`build`, and advance it with :class:`Solver`:
step by step, or under the project's stability policy with a
:class:`Driver` (mpm.stepping.driver), which reports to :class:`Observer` objects.
"""

from . import analytic
from .colliders import Collider
from .stepping.driver import Driver, Event, Observer, Outcome, StepPolicy
from .integrators import INTEGRATORS, Explicit, Implicit
from .kernels import KERNELS, Kernel
from .materials import MATERIALS, Fluid, FixedCorotated, Material, NeoHookean
from .model import Model, SceneError, State, build
from .scene import WALL_TYPES, Body, Box, Compound, Cylinder, KinematicRegion, Scene, Sphere
from .schemes import AULMPM, EMPM, SCHEMES, TLMPM
from .solver import Solver, SolverOptions
from .stepping.status import StepReport
from .stepping.detection import DETECTION_ACTIONS, Detection, Detector
from .stepping.timestep import cfl_dt

__all__ = [
    "analytic", "Collider", "INTEGRATORS", "Explicit", "Implicit", "KERNELS", "Kernel", "MATERIALS", "Fluid", "FixedCorotated", "Material", "NeoHookean",
    "Model", "SceneError", "State", "build", "WALL_TYPES", "Body", "Box", "Compound", "Cylinder",
    "KinematicRegion",
    "Scene", "Sphere", "AULMPM", "EMPM", "TLMPM", "SCHEMES", "Solver", "SolverOptions",
    "StepReport", "cfl_dt", "DETECTION_ACTIONS", "Detection", "Detector", "Driver", "Event", "Observer",
    "Outcome", "StepPolicy",
]
