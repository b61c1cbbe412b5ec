"""What every bench table runs on: a configuration composed like the command
line's, run through :func:`pipelines.run.runner.execute`, and interleaved rounds
that keep each configuration's fastest run (a drift of the machine's speed
hits every configuration alike; its noise only ever adds time)."""

from __future__ import annotations

from pathlib import Path

from ..run import runner
from ..config.validate import compose_spec
from ..recording.sinks import Sink

QUIET = ["log.every=0", "log.scalars=false", "log.progress=false"]  # step only
REPEATS = 5  # timed runs of each configuration; the fastest median is reported
WARM = ["run.steps=3"]  # a warm-up run compiles (or loads) the kernels first


spec_for = compose_spec  # a run's spec from its overrides
RECORDING = {"on": True}  # False (``--no-recording``): every run logs to a sink that drops everything


def execute(spec, out_dir: Path) -> dict:
    """:func:`pipelines.run.runner.execute` with the bench's sink: the run's
    recording, or none (``RECORDING``)."""
    return runner.execute(spec, out_dir, sink=None if RECORDING["on"] else Sink())


def step_ms(m: dict) -> float:
    """Median step time plus median logging time [ms]."""
    return m["step_time_ms"] + (m["log_time_ms"] or 0.0)


def loop_s(m: dict) -> float:
    """Wall time spent stepping a whole run [s]."""
    return m["loop_time_s"]


def interleaved(runs: dict, length: list[str], workdir: Path, rounds: int = REPEATS, by=step_ms,
                warm: list[str] | None = WARM) -> dict:
    """``runs`` (key -> overrides) in turn, ``rounds`` times, each with the
    overrides ``length`` (its steps or duration), after a warm-up run with
    ``warm`` (None: none); per key the metrics of the run least by ``by``."""
    if warm is not None:
        for i, over in enumerate(runs.values()):
            execute(spec_for(list(over) + warm), workdir / f"warm{i}")
    best: dict = {}
    for k in range(rounds):
        for i, (key, over) in enumerate(runs.items()):
            m = execute(spec_for(list(over) + length), workdir / f"{i}_{k}")
            if m["status"] != "completed":
                raise RuntimeError(f"{' '.join(list(over) + length)}: {m['status']}: {m['reason']}")
            if key not in best or by(m) < by(best[key]):
                best[key] = m
    return best


def timed(overrides: list[str], workdir: Path, repeats: int = REPEATS) -> dict:
    """One configuration ``repeats`` times (no warm-up): its fastest run."""
    return interleaved({None: overrides}, [], workdir, repeats, warm=None)[None]
