"""The registry of interpolation kernels: :data:`KERNELS` maps a kernel's
name to its :class:`Kernel`, and :func:`register_kernel` adds one defined
anywhere (a researcher's own file) after checking it.

A kernel object works without registration (``mpm.build(scene, kernel,
...)``); the ``kernel`` config group (``kernel=<name>``) and lookups by name
need it. The transfers are specialised per kernel object, so a kernel
compiles only in a run that uses it.
"""

from __future__ import annotations

import math
import re
import sys
from numbers import Real

from ..factories import probe
from ..params import Names
from .base import Kernel

NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # a name usable as a config option and a key

KERNELS: dict[str, Kernel] = Names("kernel")
"""name -> kernel: the built-in ones and those registered (the ``kernel`` config group's options)"""
BUILT_IN: dict[str, Kernel] = {}
"""name -> kernel: mpm's own (a registered kernel may not take their names)"""


def defined_at(kernel: Kernel) -> str:
    """Where a kernel's weights factory is defined (``module.qualified_name``):
    the same for a kernel made again by a reloaded module."""
    f = kernel.weights
    return f"{getattr(f, '__module__', '?')}.{getattr(f, '__qualname__', type(f).__name__)}"


def origin(kernel: Kernel) -> str:
    """Where a kernel is, in words: ``module.NAME`` of the module global
    holding it, else where its weights factory is defined."""
    module = sys.modules.get(getattr(kernel.weights, "__module__", None) or "")
    names = [k for k, v in vars(module).items() if v is kernel] if module is not None else []
    return f"{module.__name__}.{names[0]}" if module is not None and names else defined_at(kernel)


def _number(v, low: float, strict: bool) -> bool:
    return (isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(v)
            and (float(v) > low if strict else float(v) >= low))


def kernel_problem(kernel, factories: bool = True) -> str | None:
    """What keeps ``kernel`` from being used (None: nothing): a
    :class:`Kernel` with a name usable as an option, ``support`` >= 1 nodes,
    a finite ``offset``, ``moment`` None or > 0, ``margin`` >= 0 [cells], a
    non-empty tuple of finite ``grids`` offsets [cells], the factories
    ``weights`` and ``gradients``, and ``phase``, ``weights_at`` and
    ``gradients_at`` all or none (mpm.kernels.base)."""
    if not isinstance(kernel, Kernel):
        return f"not an mpm.Kernel ({type(kernel).__name__}); accepted: an mpm.kernels.Kernel(...)"
    if not isinstance(kernel.name, str) or not NAME.fullmatch(kernel.name):
        return f"name {kernel.name!r}; accepted: letters, digits and _ (e.g. \"my_kernel\")"
    if not isinstance(kernel.support, int) or isinstance(kernel.support, bool) or kernel.support < 1:
        return f"support {kernel.support!r}; accepted: an integer >= 1 (nodes per axis)"
    if not _number(kernel.offset, -math.inf, True):
        return f"offset {kernel.offset!r}; accepted: a finite number [cells]"
    if kernel.moment is not None and not _number(kernel.moment, 0.0, True):
        return f"moment {kernel.moment!r}; accepted: None (per particle) or a number > 0 [dx^2]"
    if not _number(kernel.margin, 0.0, False):
        return f"margin {kernel.margin!r}; accepted: a number >= 0 [cells]"
    if not (isinstance(kernel.grids, tuple) and kernel.grids and all(_number(g, -math.inf, True)
                                                                    for g in kernel.grids)):
        return f"grids {kernel.grids!r}; accepted: a non-empty tuple of finite offsets [cells], e.g. (0.0,)"
    missing = [n for n in ("weights", "gradients") if not callable(getattr(kernel, n))]
    if missing:
        return (f"{', '.join(missing)} missing or not callable; accepted: factories types -> Warp function "
                "u -> vector of `support` values (mpm.kernels.base)")
    shared = [n for n in ("phase", "weights_at", "gradients_at") if getattr(kernel, n) is not None]
    if shared and (len(shared) < 3 or not all(callable(getattr(kernel, n)) for n in shared)):
        return f"{', '.join(shared)} given; accepted: phase, weights_at and gradients_at all callable, or none"
    if not isinstance(kernel.gradient_affine, bool):
        return f"gradient_affine {kernel.gradient_affine!r}; accepted: true or false"
    if factories:
        calls = [("weights", (), (1, "a vector of support weights")), ("gradients", (), (1, "the gradients"))]
        if shared:
            calls += [("phase", (False,)), ("phase", (True,)), ("weights_at", (), (1, "the weights")),
                      ("gradients_at", (), (1, "the gradients"))]
        return probe(kernel, calls)
    return None


def register_kernel(kernel: Kernel) -> Kernel:
    """Add ``kernel`` to :data:`KERNELS` under ``kernel.name`` and return it.
    Registering the same kernel again does nothing; a kernel whose weights
    are defined at the same place (a reloaded module) replaces its earlier
    self, but not a built-in one. Raises a one-line ValueError naming the kernel and what is wrong:
    see :func:`kernel_problem`, or a name another kernel holds."""
    return _add(kernel, factories=True)


def _add(kernel: Kernel, factories: bool) -> Kernel:
    """:func:`register_kernel`; the built-in kernels skip calling their
    factories (done by every run that uses them)."""
    problem = kernel_problem(kernel, factories)
    if problem is not None:
        name = getattr(kernel, "name", None) if isinstance(kernel, Kernel) else None
        raise ValueError(f"kernel {name if isinstance(name, str) and name else repr(kernel)}: {problem}")
    held = KERNELS.get(kernel.name)
    if held is not None and held is not kernel and (kernel.name in BUILT_IN or defined_at(held) != defined_at(kernel)):
        raise ValueError(f"kernel {kernel.name}: name {kernel.name!r} is taken by {origin(held)}; accepted: a "
                         f"name not in {', '.join(KERNELS)}")
    KERNELS[kernel.name] = kernel
    if not factories:
        BUILT_IN[kernel.name] = kernel
    return kernel


def built_in(kernel) -> bool:
    """Whether ``kernel`` is one of mpm's own (the object, not a copy:
    ``dataclasses.replace(mpm.QUADRATIC, ...)`` is the user's)."""
    return BUILT_IN.get(getattr(kernel, "name", "")) is kernel
