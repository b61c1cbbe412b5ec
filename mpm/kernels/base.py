"""What an interpolation kernel provides to the transfers.

A kernel is a tensor product of a 1-D function on one or more regular grids
of spacing dx. Grid g has its nodes at ``(i + grids[g]) dx``: one grid at the
lattice for the B-splines, two grids shifted by -dx/4 and +dx/4 for the
compact kernel (CK-MPM). On each grid the stencil of a particle at ``x``
starts at node ``base = floor(x / dx - grids[g] - offset)`` and spans
``support`` nodes per axis; with ``t = x / dx - grids[g] - base`` the factory
``weights(types)`` returns a Warp function ``t -> (w_0 .. w_{support-1})``
and ``gradients(types)`` its derivative in t (divide by dx for the spatial
gradient). Every grid receives the particle's full mass; what comes back is
averaged over the grids.

``moment``: when the kernel's second moment is the same for every particle,
``1/G sum_g sum_i w_ip (x_i - x_p)(x_i - x_p)^T = moment dx^2 I`` and the
MLS/APIC moment inverse is ``K_p = I / (moment dx^2)`` (1/4 for the quadratic
B-spline, 1/3 for the cubic); ``None`` when it varies with the particle's
position (linear, compact) and ``K_p`` is built and inverted per particle.

``gradient_affine``: the moment matrix is singular somewhere (the linear
kernel on its nodes), so the affine matrix and the force come from the kernel
gradient, C_p = sum_i v_i grad w_ip^T, as the APIC paper does for multilinear
weights; the MLS and APIC transfers then coincide.

``phase``, ``weights_at``, ``gradients_at`` (optional): for a kernel whose
grids share work, ``phase(types, with_gradients)`` gives a Warp function
``u_0 -> P`` evaluated once per axis on grid 0's coordinate, and
``weights_at(types)`` / ``gradients_at(types)`` the functions
``(t, P, g) -> weights`` on grid g (the compact kernel: one sine per axis for
both grids).

``margin`` [cells]: a particle closer than this to the domain edge reaches
outside the grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class Kernel:
    """An interpolation kernel (the module docstring says what each field
    means): a tensor product of a 1-D function on ``grids`` of spacing dx,
    ``support`` nodes per axis from the stencil's first node, with the
    factories ``weights`` and ``gradients`` of its Warp functions. Register
    one of your own with mpm.kernels.register_kernel (docs/extending.md)."""

    name: str
    """the kernel's name (the key of KERNELS)"""
    support: int
    """nodes per axis of a particle's stencil"""
    offset: float
    """the stencil's first node: floor(x / dx - grid - offset) [cells]"""
    moment: float | None
    """the constant second moment in units of dx^2 (None: per particle)"""
    margin: float
    """[cells]: a particle closer to the domain's edge reaches outside the grid"""
    support: int
    offset: float
    moment: float | None
    margin: float
    weights: Callable | None = None
    """types -> Warp function t -> (w_0 .. w_{support-1})"""
    gradients: Callable | None = None
    """types -> Warp function t -> dw/dt (divide by dx for the spatial gradient)"""
    grids: tuple[float, ...] = (0.0,)
    """each grid's shift [cells]: (0,) for the B-splines, (-1/4, 1/4) for the compact kernel"""
    gradient_affine: bool = False
    """C and the force from the kernel gradient (a moment matrix singular somewhere)"""
    phase: Callable | None = None
    """optional: types, with_gradients -> per-axis work the grids share"""
    weights_at: Callable | None = None
    """optional, with phase: types -> (t, P, g) -> weights on grid g"""
    gradients_at: Callable | None = None
    """optional, with phase: types -> (t, P, g) -> gradients on grid g"""

    @property
    def n_grids(self) -> int:
        return len(self.grids)

    def stencil_nodes(self, dim: int) -> int:
        """Nodes a particle touches, all grids together."""
        return self.n_grids * self.support**dim

    def __repr__(self) -> str:
        return f"Kernel({self.name})"
