"""A one-line progress bar on a terminal (stderr), shown once a run (or an
export: ``unit="frame"``) has taken more than a couple of seconds."""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, steps: int | None, duration: float | None, enabled: bool | None = None,
                 delay: float = 2.0, every: float = 0.25, unit: str = "step"):
        self.steps, self.duration, self.unit = steps, duration, unit
        self.enabled = self.shown(enabled)
        self.start = time.perf_counter()
        self.delay, self.every = delay, every
        self._last = 0.0
        self._shown = False

    @staticmethod
    def shown(enabled: bool | None) -> bool:
        """log.progress: null means on a terminal."""
        return sys.stderr.isatty() if enabled is None else bool(enabled)

    def update(self, step: int, t: float, ms_per_step: float) -> None:
        """``step`` of ``steps`` (or ``t`` [s] of ``duration``) done, at ``ms_per_step`` [ms] per unit."""
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.start < self.delay or now - self._last < self.every:
            return
        self._last = now
        if self.steps:
            frac = step / self.steps
        else:
            assert self.duration is not None  # exactly one of steps and duration is set (RunSpec.end)
            frac = t / self.duration
        frac = min(max(frac, 0.0), 1.0)
        elapsed = now - self.start
        eta = elapsed * (1 - frac) / frac if frac > 0 else float("nan")
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r[{bar:<30}] {100 * frac:5.1f}% {self.unit} {step} t={t:.4g}s "
                         f"{ms_per_step:.2f} ms/{self.unit} eta {eta:.0f}s ")
        sys.stderr.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            sys.stderr.write("\n")
            sys.stderr.flush()
