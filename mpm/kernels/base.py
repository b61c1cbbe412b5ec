"""What an interpolation kernel provides to the transfers.

A kernel is a tensor product of a 1-D function on a regular grid of spacing
dx. For a particle at ``x`` the stencil starts at node
``base = floor(x / dx - offset)`` and spans ``support`` nodes per axis; with
``t = x / dx - base`` the factory ``weights(types)`` returns a Warp function
``t -> (w_0 .. w_{support-1})`` and ``gradients(types)`` its derivative in t
(divide by dx for the spatial gradient).

``moment``: the kernel's second moment, ``sum_i w_ip (x_i - x_p)(x_i - x_p)^T =
moment dx^2 I``; the MLS/APIC moment inverse is then ``K_p = I / (moment dx^2)``
(1/4 for the quadratic B-spline, 1/3 for the cubic).

``margin`` [cells]: a particle closer than this to the domain edge reaches
outside the grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class Kernel:
    name: str
    support: int
    offset: float
    moment: float
    margin: float
    weights: Callable = None
    gradients: Callable = None

    def __repr__(self) -> str:
        return f"Kernel({self.name})"
