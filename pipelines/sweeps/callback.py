"""The end of a multirun: :class:`ReportCallback` writes the sweep report
(:func:`pipelines.report.write_report`) and counts the jobs per status
(into :data:`pipelines.run.multiruns.SWEEPS`, from which ``python -m
pipelines.run`` takes a sweep's exit code)."""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

from hydra.experimental.callback import Callback

from ..report import write_report
from ..run.multiruns import SWEEPS


class ReportCallback(Callback):
    """Hydra callback writing the sweep report at the end of a multirun::

        hydra:
          callbacks:
            report:
              _target_: pipelines.sweeps.callback.ReportCallback
    """

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep = Path(config.hydra.sweep.dir)
        report = None
        try:
            report = write_report(sweep)
        except Exception as exc:  # a failed report must not hide the sweep's results
            print(f"warning: sweep report failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        outcomes = sweep_outcomes(sweep)
        SWEEPS.append(outcomes)
        print(f"sweep {sweep}: " + ", ".join(f"{n} {status}" for status, n in sorted(outcomes.items()))
              + (f"; report: {report}" if report is not None else ""), file=sys.stderr)


def sweep_outcomes(sweep_dir: Path) -> dict[str, int]:
    """Jobs per status below ``sweep_dir`` (one per job directory, reused
    results included)."""
    counts: dict[str, int] = defaultdict(int)
    for path in Path(sweep_dir).rglob("metrics.json"):
        try:
            counts[str(json.loads(path.read_text()).get("status") or "unknown")] += 1
        except (OSError, ValueError, AttributeError):
            counts["unreadable"] += 1
    return dict(counts)
