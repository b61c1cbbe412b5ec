"""Time integrators of the grid velocities: what a step solves for.

* ``Explicit``: forward Euler (A-ULMPM paper eq. 23), the stress of the state
  the step starts from; the step is bounded by the wave speed (mpm.stepping.timestep).
* ``Implicit``: backward Euler, the stress of the state the step ends in
  (paper eq. 24-27), solved as the minimisation of the incremental potential
  by Newton's method (mpm.implicit). ``newton_max = 1`` is the paper's
  semi-implicit update: one Newton step, one linear solve.
"""

from dataclasses import dataclass

from .params import Names, param


@dataclass
class Explicit:
    """Forward Euler on the grid velocities."""

    name: str = "explicit"
    """the integrator's name (the key of INTEGRATORS)"""

    def problems(self) -> list[tuple[str, str]]:
        return []


@dataclass
class Implicit:
    """Backward Euler on the grid velocities, by Newton's method with a line
    search, each linear system by Jacobi-preconditioned conjugate gradients
    (mpm.implicit)."""

    name: str = "implicit"
    """the integrator's name (the key of INTEGRATORS)"""
    newton_max: int = param(20, "Newton iterations per step at most (1: the paper's "
                                "semi-implicit update) [-]", ge=1)
    newton_tol: float = param(1.0e-4, "converged when |residual| <= newton_tol |initial residual| [-]",
                              gt=0.0, lt=1.0)
    newton_accept: float = param(10.0, "a solve out of iterations with its residual within this factor of "
                                       "the tolerance, and still falling, is a near miss: retried with half "
                                       "the step while halvings remain, else accepted and counted [-]", ge=1.0)
    cg_max: int = param(400, "conjugate-gradient iterations per Newton iteration at most [-]", ge=1)
    cg_tol: float = param(1.0e-3, "CG stops at |r| <= cg_tol |Newton residual| [-]", gt=0.0, lt=1.0)
    line_search: bool = param(True, "backtracking on the incremental potential (Armijo)")
    psd: bool = param(True, "project each particle's stress differential to semi-definite")
    displacement: float = param(0.5, "adaptive step: a particle moves at most this fraction "
                                     "of a cell per step [-]", gt=0.0)
    halvings: int = param(6, "adaptive step: retries with half the step after a failed "
                             "Newton solve [-]", ge=0)

    def problems(self) -> list[tuple[str, str]]:
        return []


INTEGRATORS = Names("integrator", {"explicit": Explicit, "implicit": Implicit})
"""name -> integrator options class"""
