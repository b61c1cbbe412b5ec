"""Interpolation kernels, one module each; :data:`KERNELS` maps names to kernels."""

from .base import Kernel
from .compact import COMPACT
from .cubic import CUBIC
from .linear import LINEAR
from .quadratic import QUADRATIC

KERNELS: dict[str, Kernel] = {k.name: k for k in (LINEAR, QUADRATIC, CUBIC, COMPACT)}
"""name -> kernel (the ``kernel`` config group's options)"""

__all__ = ["KERNELS", "Kernel", "LINEAR", "QUADRATIC", "CUBIC", "COMPACT"]
