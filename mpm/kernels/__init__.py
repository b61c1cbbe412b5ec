"""Interpolation kernels, one module each; :data:`KERNELS` maps names to
kernels. A kernel defined elsewhere joins them with :func:`register_kernel`
(mpm.kernels.registry; docs/extending.md)."""

from .base import Kernel
from .compact import COMPACT
from .cubic import CUBIC
from .linear import LINEAR
from .quadratic import QUADRATIC
from .registry import KERNELS, _add, kernel_problem, register_kernel

for _kernel in (LINEAR, QUADRATIC, CUBIC, COMPACT):
    _add(_kernel, factories=False)
del _kernel, _add

__all__ = ["KERNELS", "Kernel", "LINEAR", "QUADRATIC", "CUBIC", "COMPACT", "kernel_problem", "register_kernel"]
