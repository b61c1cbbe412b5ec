"""Interpolation kernels, one module each; :data:`KERNELS` maps names to kernels."""

from .base import Kernel
from .quadratic import QUADRATIC

KERNELS: dict[str, Kernel] = {k.name: k for k in (QUADRATIC,)}

__all__ = ["KERNELS", "Kernel", "QUADRATIC"]
