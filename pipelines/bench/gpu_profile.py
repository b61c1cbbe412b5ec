"""Where a step's time goes, per kernel, with the bytes each kernel moves
and its share of the memory bound: ``python -m pipelines.bench --only
gpu-profile`` (the 3D elastic sphere, EMPM, fixed corotated, quadratic
MLS, at about 1M and 10M particles: pipelines.bench.scale's LARGE;
``--profile-sizes`` picks others, e.g. ``1M`` or a resolution ``64``).

- time: on CUDA each launch is timed on the device by Warp's activity
  timing (wp.timing_begin: CUDA events around every kernel, copy and
  fill, no host synchronisation between them); on the CPU, where a launch
  runs to its end before it returns, on the host. The driver reads back
  every step and uses no CUDA graph, so that every launch is seen; the
  ``step`` row is the wall time per step, the ``host`` row what the device
  rows leave of it (Python, the read-back, the grid layout).
- bytes: each launch's compulsory traffic, every array it takes (its
  array arguments and the arrays in its struct arguments) read or written
  once over the launch's extent, sum of min(elements, launch size) x
  element bytes. A lower bound: atomics, a stencil's neighbours and cache
  misses move more.
- bandwidth: bytes / time, and its share of the device's copy bandwidth
  measured in the same process (a device-to-device wp.copy, read plus
  write).

Each size runs ``rounds`` batches of ``steps`` steps after a started
driver's first batch; the fastest batch counts.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from mpm.launch import Launches, kernel_name

from .runs import QUIET, spec_for
from .scale import LARGE, LARGE_CASE, _driver, advance

COPY_MB = {"cuda": 512, "cpu": 64}  # the copy-bandwidth probe's array [MB]


def _extent(dim) -> int:
    return int(np.prod(dim)) if isinstance(dim, (tuple, list)) else int(dim)


def _arrays(value):
    """The Warp arrays of a launch argument: itself, or the array fields of a struct."""
    if isinstance(value, wp.array):
        yield value
    elif hasattr(value, "_cls") and hasattr(value._cls, "vars"):
        for name in value._cls.vars:
            field = getattr(value, name, None)
            if isinstance(field, wp.array):
                yield field


def launch_bytes(dim, inputs) -> int:
    """The compulsory bytes of a launch of extent ``dim`` over ``inputs`` (module docstring)."""
    n = _extent(dim)
    seen, total = set(), 0
    for value in inputs:
        for a in _arrays(value):
            if a.ptr is None or a.ptr in seen:
                continue
            seen.add(a.ptr)
            total += min(a.size, n) * wp.types.type_size_in_bytes(a.dtype)
    return total


class Traffic:
    """While entered: each kernel launch's count and compulsory bytes by
    kernel (plain wp.launch and the solver's recorded launches,
    mpm.launch.Launches), and on the CPU its host time [ms]; ``names`` maps
    a kernel's CUDA name (Kernel.get_mangled_name) to its readable one."""

    def __init__(self, device: str):
        self.cuda = device.startswith("cuda")
        self.launches: dict[str, int] = {}
        self.bytes: dict[str, int] = {}
        self.ms: dict[str, float] = {}
        self.names: dict[str, str] = {}

    def _seen(self, kernel, dim, inputs, ms: float) -> None:
        name = kernel_name(kernel)
        if self.cuda and name not in self.launches:
            self.names[kernel.get_mangled_name()] = name
        self.launches[name] = self.launches.get(name, 0) + 1
        self.bytes[name] = self.bytes.get(name, 0) + launch_bytes(dim, inputs)
        self.ms[name] = self.ms.get(name, 0.0) + ms

    def __enter__(self):
        self._saved = wp.launch, Launches.__call__
        launch, recorded = self._saved
        inside = []  # a recorded launch's first call goes through wp.launch: count it once
        traffic = self

        def plain(kernel, dim, inputs=(), *args, **kwargs):
            if inside or kwargs.get("record_cmd"):
                return launch(kernel, dim, inputs, *args, **kwargs)
            t0 = time.perf_counter()
            out = launch(kernel, dim, inputs, *args, **kwargs)
            traffic._seen(kernel, dim, list(inputs or ()) + list(kwargs.get("outputs") or ()),
                          1e3 * (time.perf_counter() - t0))
            return out

        def kept(self_, kernel, dim, inputs):
            inside.append(True)
            t0 = time.perf_counter()
            try:
                recorded(self_, kernel, dim, inputs)
            finally:
                inside.pop()
            if dim:
                traffic._seen(kernel, dim, inputs, 1e3 * (time.perf_counter() - t0))

        wp.launch = plain
        Launches.__call__ = kept  # pyright: ignore[reportAttributeAccessIssue]
        return self

    def __exit__(self, *exc):
        wp.launch, Launches.__call__ = self._saved
        return False


def copy_bandwidth(device: str, rounds: int = 5) -> float:
    """[GB/s] a device-to-device copy of COPY_MB megabytes, read plus write; the fastest of ``rounds``."""
    n = COPY_MB["cuda" if device.startswith("cuda") else "cpu"] * 2**20 // 4
    a, b = wp.zeros(n, dtype=float, device=device), wp.empty(n, dtype=float, device=device)
    wp.copy(b, a)
    wp.synchronize_device(device)
    best = float("inf")
    for _ in range(rounds):
        t0 = time.perf_counter()
        wp.copy(b, a)
        wp.synchronize_device(device)
        best = min(best, time.perf_counter() - t0)
    return 2 * 4 * n / best / 1e9


def _device_times(results, names: dict[str, str]) -> dict[str, float]:
    """Warp's CUDA activity timings [ms] summed by readable name: kernels by
    their kernel's name, copies and fills as one row each."""
    out: dict[str, float] = {}
    for r in results:
        if r.filter == wp.TIMING_KERNEL:
            mangled = str(r.name).removeprefix("forward kernel ")
            name = names.get(mangled, mangled)
        elif r.filter == wp.TIMING_MEMCPY:
            name = "copies (wp.copy)"
        elif r.filter == wp.TIMING_MEMSET:
            name = "fills (zero_, fill_)"
        else:
            name = str(r.name)
        out[name] = out.get(name, 0.0) + r.elapsed
    return out


def resolution_of(size: str) -> tuple[str, int]:
    """A size label of LARGE (``1M``, ``10M``) or a sphere resolution (``64``)."""
    if size in LARGE:
        return size, LARGE[size]
    if size.isdigit() and int(size) >= 8:
        return f"res {size}", int(size)
    raise ValueError(f"--profile-sizes: {size!r}; accepted: {', '.join(LARGE)} or a resolution >= 8")


def gpu_profile(sizes=tuple(LARGE), steps: int = 10, rounds: int = 3, overrides=()) -> list[dict]:
    """Per size (:func:`resolution_of`), the step's kernels: launches, ms,
    share of the step, compulsory MB, GB/s and share of the copy bandwidth
    per step (module docstring); then the copies and fills (CUDA), the host
    and the step."""
    rows = []
    for size in sizes:
        label, res = resolution_of(size)
        spec = spec_for(LARGE_CASE + QUIET + [f"scene.resolution={res}", *overrides])
        device = spec.run.device
        cuda = device.startswith("cuda")
        driver = _driver(spec, sync_every=1)
        peak = copy_bandwidth(device)
        best = None
        for _ in range(rounds):
            with Traffic(device) as traffic:
                if cuda:
                    wp.timing_begin(cuda_filter=wp.TIMING_KERNEL | wp.TIMING_MEMCPY | wp.TIMING_MEMSET)
                n, wall = advance(driver, steps, device)
                times = _device_times(wp.timing_end(), traffic.names) if cuda else dict(traffic.ms)
            if best is None or wall / n < best[0]:
                best = (wall / n, {k: v / n for k, v in times.items()}, traffic, n)
        assert best is not None  # rounds >= 1
        per_step, ms, traffic, n = best
        step_ms = 1e3 * per_step
        particles = driver.solver.model.n_particles
        common = {"size": label, "particles": particles, "device": device, "copy_gb_s": peak}
        for name, t in sorted(ms.items(), key=lambda kv: -kv[1]):
            mb = traffic.bytes.get(name, 0) / n / 1e6
            rate = mb / 1e3 / (t / 1e3) if t > 0 and mb else None  # GB/s
            rows.append({**common, "part": name, "launches": traffic.launches.get(name, 0) / n, "ms": t,
                         "share": t / step_ms, "mb": mb if name in traffic.bytes else None, "gb_s": rate,
                         "of_copy": rate / peak if rate is not None else None})
        device_ms = sum(ms.values())
        rows.append({**common, "part": "host (Python, read-back, layout)", "launches": None,
                     "ms": step_ms - device_ms, "share": 1.0 - device_ms / step_ms, "mb": None, "gb_s": None,
                     "of_copy": None})
        mb = sum(traffic.bytes.values()) / n / 1e6
        rows.append({**common, "part": "step", "launches": sum(traffic.launches.values()) / n, "ms": step_ms,
                     "share": 1.0, "mb": mb, "gb_s": mb / step_ms, "of_copy": mb / step_ms / peak,
                     "particle_steps_per_s": particles / per_step})
        del driver
    return rows


def print_gpu_profile(rows: list[dict]) -> None:
    def f(x, fmt):
        return format(x, fmt) if x is not None else "-"

    for size in dict.fromkeys(r["size"] for r in rows):
        part = [r for r in rows if r["size"] == size]
        r0, step = part[0], part[-1]
        print(f"\nwhere the step goes: the 3D sphere, {size} ({r0['particles']:,} particles), EMPM, quadratic MLS, "
              f"{r0['device']}, read-back every step; copy bandwidth {r0['copy_gb_s']:,.1f} GB/s; "
              f"{step['particle_steps_per_s'] / 1e9:.3f} G particle-steps/s")
        print(f"{'part':<44} {'launches':>8} {'ms/step':>9} {'share':>6} {'MB/step':>9} {'GB/s':>8} "
              f"{'of copy':>7}")
        for r in part:
            share = f"{100 * r['share']:.1f}%"
            of_copy = f"{100 * r['of_copy']:.1f}%" if r["of_copy"] is not None else "-"
            print(f"{r['part'][:44]:<44} {f(r['launches'], '.1f'):>8} {r['ms']:>9.3f} {share:>6} "
                  f"{f(r['mb'], ',.1f'):>9} {f(r['gb_s'], ',.1f'):>8} {of_copy:>7}")
