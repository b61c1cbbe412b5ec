"""What every material provides to the solver.

A material is a plain dataclass of physical parameters (checked ranges, SI
units) plus factories of Warp functions specialised for a :class:`Types`.

Elastic and fluid models give
* ``stress_energy(F, L, params) -> (P, psi)``: first Piola-Kirchhoff stress
  ``P`` [Pa] of the deformation gradient ``F`` (w.r.t. the rest state), given
  the velocity gradient ``L`` in current coordinates [1/s] (used by viscous
  models only), and the stored energy ``psi`` per unit rest volume [J/m^3].
  One function for both, so a kernel that needs both decomposes ``F`` once;
  kernels that need one of them leave the other to dead-code elimination;
* ``principal(sigma, params, history) -> (P_hat, psi, H)``: the same
  elastic energy in principal stretches (singular values of F), with its
  Hessian H_ij = d^2 psi / d sigma_i d sigma_j, for the stress differential
  of the implicit integrator (mpm.materials.differential); a viscous model
  names the index of eta in ``params`` as ``viscosity_param``;
* ``project(F, params) -> F`` (optional): applied when the reference
  configuration is updated (every step for the Eulerian scheme), e.g. a fluid
  keeps only the volume change of ``F``.

Plastic models (:class:`mpm.materials.plastic.Plastic`) instead give a return
mapping and a stress in principal stretches, run every step by P2G on a
per-particle plastic state (with ``elasticity_hessian`` for the implicit
integrator); see that module for how the state relates to the reference
configuration.

``params`` is the per-body vector returned by :meth:`Material.packed`, so
bodies of one model share compiled code and a parameter sweep never
recompiles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, ClassVar

from ..params import param
from ..types import N_MATERIAL_PARAMS, Types


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lamé parameters (mu, lambda) [Pa] from Young's modulus and Poisson's ratio
    (3D / plane strain)."""
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam


@dataclass
class Material:
    """Base class; ``model`` names the constitutive model (the registry key).

    A subclass is a dataclass of its parameters (``param`` fields, SI units)
    with a ``name``, ``packed()`` (the per-body parameter vector, at most
    N_MATERIAL_PARAMS numbers), ``wave_speed()`` [m/s] and factories
    ``types -> Warp function`` (@functools.cache, specialised per dimension
    and precision, mpm.types.Types):

    * ``stress_energy(t)`` -> ``stress_energy(F, L, params) -> (P [Pa], psi [J/m^3])``
    * ``principal(t)`` -> ``principal(sigma, params, history) -> (P_hat, psi, H)``
    * ``project(t)`` (optional) -> ``project(F, params) -> F``

    (plastic models: mpm.materials.plastic.Plastic's ``flow``,
    ``elasticity``, ``elasticity_hessian``). See this module's docstring and
    docs/extending.md; mpm.materials.register_material checks a class."""

    model: str = ""
    """the constitutive model's name, the key of mpm.MATERIALS (set by the class)"""
    rho: float = param(1000.0, "rest density [kg/m^3]", gt=0.0)

    name: ClassVar[str] = ""
    stress_energy: ClassVar[Callable[[Types], Callable]]
    project: ClassVar[Callable[[Types], Callable] | None] = None
    principal: ClassVar[Callable[[Types], Callable]]
    viscosity_param: ClassVar[int | None] = None  # index of eta [Pa s] in packed(), if viscous
    plastic: ClassVar[bool] = False  # a return mapping runs every step (mpm.materials.plastic)
    needs_velocity_gradient: ClassVar[bool] = False  # does the stress read L?
    stiffens: ClassVar[bool] = False  # does wave_speed(J) grow under compression?
    invertible: ClassVar[bool] = False  # is the energy defined at det F <= 0 (mpm.stepping.detection)?
    flows: ClassVar[bool] = False
    """does the material flow without bound (fluids, plastic solids)? A-ULMPM
    then takes its defaults for flowing bodies (mpm.schemes)"""
    fluid: ClassVar[bool] = False
    """no shear stiffness at all (the weakly compressible fluids): A-ULMPM's
    fluid defaults, measured by the aulmpm_tradeoff experiment"""

    def __post_init__(self):
        if not self.model:
            self.model = self.name

    def packed(self) -> tuple[float, ...]:
        """Per-body parameter vector read by the Warp functions."""
        raise NotImplementedError

    def initial_history(self) -> tuple[float, float]:
        """The two history variables at rest (plastic models: mpm.materials.plastic;
        an elastic model has none, read as zeros)."""
        return (0.0, 0.0)

    def packed_padded(self) -> tuple[float, ...]:
        p = tuple(float(v) for v in self.packed())
        assert len(p) <= N_MATERIAL_PARAMS
        return p + (0.0,) * (N_MATERIAL_PARAMS - len(p))

    def wave_speed(self, J: float = 1.0) -> float:
        """Speed of the fastest small-amplitude wave [m/s] (for the CFL limit)
        at volume ratio J; solids take their value at rest."""
        raise NotImplementedError

    def wave_speed_law(self) -> tuple[float, float, float, float]:
        """(c0, a, b, rho) of :meth:`wave_speed` for the device's step rule
        (mpm.stepping.timestep): c(J) = c0 when b == 0, else sqrt(a J^b / rho) (a
        weakly compressible fluid's speed grows under compression)."""
        return self.wave_speed(), 0.0, 0.0, self.rho

    def kinematic_viscosity(self) -> float:
        """Kinematic viscosity [m^2/s] (for the diffusive time-step limit)."""
        return 0.0

    def problems(self) -> list[tuple[str, str]]:
        """Constraints between parameters that single ranges cannot state:
        ``(field, message)`` pairs (empty when consistent)."""
        return []


@dataclass
class Isotropic(Material):
    """An isotropic solid of Young's modulus E and Poisson's ratio nu, its
    params the Lamé parameters (mu, lambda) [Pa]."""

    E: float = param(1.0e5, "Young's modulus [Pa]", gt=0.0)
    nu: float = param(0.3, "Poisson's ratio [-]", gt=-1.0, lt=0.5)

    def packed(self) -> tuple[float, ...]:
        return lame(self.E, self.nu)

    def wave_speed(self, J: float = 1.0) -> float:
        return elastic_wave_speed(self.E, self.nu, self.rho)


def elastic_wave_speed(E: float, nu: float, rho: float) -> float:
    """P-wave speed sqrt((lambda + 2 mu) / rho) [m/s]."""
    mu, lam = lame(E, nu)
    return math.sqrt((lam + 2.0 * mu) / rho)
