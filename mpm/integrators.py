"""Time integrators of the grid velocities: what a step solves for.

* ``Explicit``: forward Euler (A-ULMPM paper eq. 23), the stress of the state
  the step starts from; the step is bounded by the wave speed (mpm.stepping.timestep).
* ``Implicit``: backward Euler, the stress of the state the step ends in
  (paper eq. 24-27), solved as the minimisation of the incremental potential
  by Newton's method (mpm.implicit). ``newton_max = 1`` is the paper's
  semi-implicit update: one Newton step, one linear solve.

Angular momentum (APIC/MLS transfers; Jiang et al. 2015, 2017): the step
changes it by dt/G sum_i x_i x f_i (x_i the nodes, G the kernel's grids).
Forward Euler's force, that of the nodes at x_i, is torque-free about them:
angular momentum is kept to round-off (EMPM with the quadratic or cubic
kernel; with the linear or compact kernel it loses some under either
integrator, C_p being spread again from the moved particle, where the
kernel's second moment differs, and under TLMPM, whose nodes are the reference lattice's, it is
kept to 2e-8 to 1e-4 over 0.15 s: RESULTS.md). Backward Euler's, that of the moved
nodes x_i + dt v~_i, is torque-free about those, so a step changes it by

    dL = -dt^2/G sum_i v~_i x f_i = dt/G sum_i m_i v~_i x v*_i

(v* the predictor, v~ the solution): a body spinning steadily at w loses
(w dt)^2 of its angular momentum a step, the fraction ~ w^2 T dt over a
time T, first order in dt, at any Newton tolerance. This is backward
Euler's, not a defect: the transfers, C, the position update and the
stress keep it (each step's change is this dL to the Newton residual;
tests/mpm/test_implicit_angular.py, examples/spinning_block.py; a block at
10 rad/s loses 6.4 % in 0.15 s at 5 ms steps). Jiang et al. (2017) keep it
with the midpoint rule instead.
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
