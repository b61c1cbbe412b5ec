"""The multiruns of this process: the jobs per status of each
(:data:`SWEEPS`), appended by the end-of-multirun callback
(:class:`pipelines.sweeps.callback.ReportCallback`); ``python -m
pipelines.run`` takes a sweep's exit code from them."""

from __future__ import annotations

SWEEPS: list[dict[str, int]] = []  # per multirun of this process: jobs per status (pipelines.run's exit code)
