"""Kernel launches that convert only the arguments that changed.

``wp.launch`` converts every argument to its C form at every call (a
transfer kernel has 25-30), host time that on a GPU can exceed the kernel's;
on this project's 2-core CPU the 2D ball's step took 0.3-0.5 ms less with
recorded launches (pipelines.bench's profile). A step launches the same
kernels with mostly the same arrays, so :class:`Launches` records each
kernel's launch once (``wp.launch(..., record_cmd=True)``) and afterwards sets
only the arguments that changed (arrays and None by identity; scalars,
vectors and matrices by value; structs every time, since their fields may
have changed) and the launch size.
"""

import time

import warp as wp

from .types import StructInstance


def warp_kernel(f):
    """``wp.kernel`` as this project builds every kernel: in a module of its
    own (a closure specialised per run compiles alone) and without adjoint
    code (nothing differentiates through a step; the adjoints doubled the
    compile time, 14.1 against 7.3 s for the 3D ball's kernels into an empty
    cache)."""
    return wp.kernel(f, enable_backward=False, module="unique")


def load(kernels, device) -> float:
    """Compile (or load from the cache) the modules of ``kernels`` on ``device``; seconds taken."""
    t0 = time.perf_counter()
    modules = list({id(k.module): k.module for k in kernels}.values())
    wp.force_load(device=device, modules=modules, max_workers=2)
    return time.perf_counter() - t0


def kernel_name(kernel) -> str:
    """A specialised kernel's readable name: ``make_g2p.g2p`` for the kernel
    ``g2p`` that ``make_g2p`` builds."""
    return kernel.key.replace("__locals__", ".").lstrip("_")


def _same(a, b) -> bool:
    """Whether ``a`` passes the same value to a kernel as ``b`` did."""
    if a is b:
        return not isinstance(a, StructInstance)
    if isinstance(a, (wp.array, StructInstance)) or a is None or b is None or type(a) is not type(b):
        return False
    if hasattr(a, "value"):  # a Warp scalar
        return a.value == b.value
    if isinstance(a, (int, float, bool)):
        return a == b
    try:  # Warp vectors and matrices
        return tuple(a) == tuple(b)
    except TypeError:
        return False


class Launches:
    """``launches(kernel, dim, inputs)``: wp.launch on ``device``, repacking
    only the arguments that changed since the kernel's last launch."""

    def __init__(self, device):
        self.device = device
        self._recorded: dict = {}  # kernel -> [Launch, its inputs, its dim]

    def __call__(self, kernel, dim: int, inputs: list) -> None:
        if dim == 0:  # nothing to run (wp.launch returns at once too)
            return
        entry = self._recorded.get(kernel)
        if entry is None:
            cmd = wp.launch(kernel, dim, inputs=inputs, device=self.device, record_cmd=True)
            assert cmd is not None  # record_cmd=True returns the Launch
            self._recorded[kernel] = [cmd, list(inputs), dim]
            cmd.launch()
            return
        cmd, last, last_dim = entry
        for i, value in enumerate(inputs):
            if not _same(value, last[i]):
                cmd.set_param_at_index(i, value)
                last[i] = value
        if dim != last_dim:
            cmd.set_dim(dim)
            entry[2] = dim
        cmd.launch()



class Counter:
    """Counts, while entered, this process's kernel launches (``wp.launch``
    and recorded launches) and device-to-host reads (``wp.array.numpy``: on a
    GPU each is a synchronisation; on the CPU a view, counted the same)."""

    def __init__(self):
        self.launches = 0
        self.reads = 0

    def __enter__(self):
        self._saved = (wp.launch, wp.Launch.launch, wp.array.numpy)
        launch, recorded, numpy = self._saved

        def counted_launch(*args, **kwargs):
            if not kwargs.get("record_cmd"):
                self.launches += 1
            return launch(*args, **kwargs)

        def counted_recorded(cmd, *args, **kwargs):
            self.launches += 1
            return recorded(cmd, *args, **kwargs)

        def counted_numpy(array, *args, **kwargs):
            self.reads += 1
            return numpy(array, *args, **kwargs)

        wp.launch = counted_launch
        # methods patched while counting (their stubs declare methods, not attributes)
        wp.array.numpy = counted_numpy  # pyright: ignore[reportAttributeAccessIssue]
        wp.Launch.launch = counted_recorded  # pyright: ignore[reportAttributeAccessIssue]
        return self

    def __exit__(self, *exc):
        wp.launch, wp.Launch.launch, wp.array.numpy = self._saved
        return False
