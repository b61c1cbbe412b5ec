"""Run one validated configuration: build, compile, step, log, report.

Hydra-free: ``pipelines.run`` composes the config and calls :func:`execute`,
which steps the scene with ``mpm``'s driver (mpm.stepping.driver: the stable step,
collapse and blow-up detection) and records what it reports through a
:class:`pipelines.run.recorder.Recorder`, writing checkpoints as
``run.checkpoint_every`` asks (pipelines.run.checkpoints). Whatever happens
(completion, instability, Ctrl-C, SIGTERM or SIGUSR1: a checkpoint first, an
exception), the recording is finalised and ``metrics.json`` written.
"""

from __future__ import annotations

import json
import math
import signal
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np

import mpm
from mpm.precision import compensates, for_policy
from mpm.stepping.driver import SYNC_EVERY_CUDA
from mpm.stepping.plan import plan as step_plan

from . import checkpoints, provenance
from ..config import plugins
from ..config.validate import RunSpec
from ..recording.sinks import Sink
from .progress import Progress
from .recorder import Recorder


RUN_PROPERTIES = ("command", "host", "started")  # differ between identical runs


def recording_properties(spec: RunSpec, config_yaml: str, overrides: list[str],
                         choices: dict | None = None) -> dict:
    """How to reproduce the run: resolved config, overrides, group choices,
    git commit and dirty flag, package versions, device, precision, seed,
    where the materials and kernels defined outside ``mpm`` come from
    (``plugins``) and the modules ``MPM_PLUGINS`` named (``mpm_plugins``);
    and (``run``: the timings file's) when, where and with which command it ran."""
    prov = provenance.collect(spec.run.device, spec.run.precision, spec.seed, overrides)
    prov["plugins"] = [f"{k} = {v}" for k, v in plugins.origins(spec.scene, spec.kernel).items()]
    prov["mpm_plugins"] = plugins.env_modules()
    packages = prov.pop("packages")
    when = {k: prov.pop(k) for k in RUN_PROPERTIES}
    nonempty = lambda v: v or [""]  # noqa: E731 - Rerun needs a non-empty batch
    return {
        "run": when,
        "config": {"yaml": config_yaml, "overrides": nonempty(list(overrides)),
                   "choices": nonempty([f"{k}={v}" for k, v in sorted((choices or {}).items())])},
        "provenance": {k: nonempty(v) if isinstance(v, list) else v for k, v in prov.items()},
        "packages": packages,
    }


def sync_every(spec: RunSpec) -> int:
    """Steps between two read-backs (mpm.stepping.driver): run.sync_every, else 10 on
    CUDA and 1 on the CPU; 1 under the implicit integrator (its Newton loop
    reads back) and with a closed-form solution (its body force is set on
    the host, its errors are measured every step)."""
    host_steps = spec.integrator.name == "implicit" or spec.scene.solution is not None
    k = spec.run.sync_every
    if k is None:
        k = SYNC_EVERY_CUDA if spec.run.device == "cuda" else 1
    return 1 if host_steps else int(k)


def precision_check(spec: RunSpec) -> tuple[dict, str]:
    """Can the run's precision resolve the scene? mpm.precision's estimate with
    the run's step settings: metrics.json's ``precision_check`` entry (r_F and r_x,
    whether they resolve the scene, whether G2P keeps compensated sums:
    ``run.compensate``, null: where they do not, in float32) and a line to
    print before compiling ("" where they do)."""
    run = spec.run
    r = for_policy(spec.scene, run.precision, run, spec.integrator)  # (the library's rule: mpm.Driver)
    on = compensates(run.compensate, run.precision, r)
    entry = {"r_F": r.r_F, "r_x": r.r_x, "resolved": r.resolved, "compensate": bool(on)}
    if r.resolved:
        return entry, ""
    what = (f"{run.precision} cannot resolve a step's motion (mpm.precision: r_F = {r.r_F:.2g}, threshold "
            f"{r.threshold:g}; r_x = {r.r_x:.2g}, threshold {r.position_threshold:g})")
    if on:
        return entry, f"note: {what}: G2P keeps compensated sums of x and F (run.compensate)"
    return entry, (f"warning: {what} and run.compensate=false: the deformation drifts; "
                   f"set run.precision=float64 or run.compensate=true")


def solver_options(spec: RunSpec) -> mpm.SolverOptions:
    """What the solver compiles for this run: dJ only when it is logged, the
    detection's measurements only when it is on, the batched steps' early
    exits only when the host reads back less than every step, compensated
    sums where the precision cannot resolve the scene (:func:`precision_check`)."""
    detect = spec.detect.action != "off"
    return mpm.SolverOptions(record_dJ=spec.log.particles and spec.log.dJ, transfer=spec.transfer, flip=spec.flip,
                             integrator=spec.integrator, track_energy=detect, fuse=spec.run.fuse,
                             track_J=detect and any(not b.material.invertible for b in spec.scene.bodies),
                             batched=sync_every(spec) > 1, compensate=precision_check(spec)[0]["compensate"])


def step_policy(spec: RunSpec) -> mpm.StepPolicy:
    """How the run's steps are chosen and when it ends (mpm.stepping.driver)."""
    run = spec.run
    steps, duration = spec.end
    return mpm.StepPolicy(steps=steps, duration=duration, dt=run.dt, cfl=run.cfl, dt_max=run.dt_max,
                          dt_collapse=run.dt_collapse)


def plan(spec: RunSpec) -> str:
    """``run.plan=true``: the stages of a step and the kernels they launch,
    the run's size, and what it logs; nothing is compiled or run."""
    model, state = mpm.build(spec.scene, spec.kernel, spec.run.precision, spec.run.device, spec.seed,
                             samples=spec.take_samples())
    solver = mpm.Solver(model, spec.scheme, solver_options(spec))
    driver = mpm.Driver(solver, state, step_policy(spec), spec.detect, sync_every=sync_every(spec),
                        graph=spec.run.graph, measure=spec.log.scalars)
    log = spec.log
    frames = ("none" if not log.particles else f"every {log.every} steps" if log.every is not None
              else f"{log.fps:g} per simulated second")
    lines = [f"{spec.scene_name}: {model.n_particles} particles, {len(spec.scene.bodies)} body(ies), "
             f"{model.dim}D, {spec.run.precision} on {spec.run.device}; {solver.scheme.name}, "
             f"{spec.kernel.name} kernel ({spec.transfer}), {spec.integrator.name} integrator",
             "step:"]
    for i, (stage, kernels) in enumerate(step_plan(solver, driver), 1):
        lines.append(f"  {i}. {stage}" + (f": {', '.join(kernels)}" if kernels else ""))
    lines.append(f"logging: particle frames {frames}" + (" with dJ" if solver.options.record_dJ else "")
                 + (", scalars every step" if log.scalars else ", no scalars")
                 + f", fracture every {log.fracture_every} steps; detection {spec.detect.action}")
    lines.append(f"kernels compiled: {len({id(k.module) for k in driver.kernels()})}")
    return "\n".join(lines)


class _Terminate(KeyboardInterrupt):
    """SIGTERM or SIGUSR1 (a cluster pre-empting the job): a checkpoint, then the end, once stepping."""

    def __init__(self, name: str = "SIGTERM"):
        super().__init__(name)
        self.name = name
        self.signum = signal.Signals[name]


class Interrupts:
    """Ctrl-C, SIGTERM and SIGUSR1. Outside the step loop they raise at once; inside
    it they are remembered and raised at the next step boundary
    (:meth:`check`): Python ignores an exception raised while a finaliser
    runs (a Warp array's ``__del__``, say, which the loop triggers every step),
    so a signal raised wherever it lands can be lost. A second signal while
    one is pending raises at once."""

    def __init__(self):
        self.deferred = False
        self.pending: KeyboardInterrupt | None = None

    def handler(self, signum, frame):
        exc = KeyboardInterrupt() if signum == signal.SIGINT else _Terminate(signal.Signals(signum).name)
        if self.deferred and self.pending is None:
            self.pending = exc
            return
        raise exc

    def check(self) -> None:
        if self.pending is not None:
            exc, self.pending = self.pending, None
            raise exc


def execute(spec: RunSpec, out_dir: Path, config_yaml: str = "", overrides: Sequence[str] = (),
            choices: dict | None = None, sink: Sink | None = None, identity: dict | None = None,
            resume: mpm.checkpoint.Checkpoint | None = None) -> dict:
    """Run ``spec``; write the recording and ``metrics.json`` into ``out_dir``.

    ``config_yaml``, ``overrides`` and ``choices`` describe how the spec was
    composed; they are stored in the recording with the provenance.
    ``identity`` (e.g. the config hash) goes into metrics.json as given.
    ``resume``: continue from this checkpoint (pipelines.run.checkpoints.choose), logging into
    ``<recording>.resumed-<step>.rrd`` with the first recording's id, the parts joined at the end."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    properties = recording_properties(spec, config_yaml, list(overrides), choices)
    joined: list[str] = []  # a resumed run's parts of the recording, this run's last: joined at the end
    parts: list = []
    if sink is None:
        from ..recording.rerun_sink import RerunSink  # imported here: a run given a sink needs no rerun-sdk

        recording = spec.log.recording
        if resume is None:
            checkpoints.drop_segments(out_dir, recording)
        else:
            parts = checkpoints.resume_segments(out_dir, recording, resume)
        name = recording if resume is None else checkpoints.segment(recording, resume.step)
        sink = RerunSink(out_dir / name, spec.log.flush_every,
                         recording_id=resume.meta.get("recording_id") if resume is not None else None)
        joined = [p[0] for p in parts] + [name] if resume is not None else []
    run = Recorder(spec, out_dir, properties, sink)
    interrupts = Interrupts()
    run.metrics.update(identity or {})
    # what a run killed without warning leaves (python -m pipelines.replay <dir> --repair marks it killed)
    write_metrics(out_dir / "metrics.json", {**run.metrics, "status": "running",
                                             "reason": "started, not finished"})
    ckpts = checkpoints.Checkpoints(out_dir, spec.run.checkpoint_every, identity or {},
                                    getattr(sink, "recording_id", None), parts)
    previous = {}
    try:
        for signum in (signal.SIGTERM, getattr(signal, "SIGUSR1", None), signal.SIGINT):
            if signum is not None:  # (no SIGUSR1 on Windows)
                previous[signum] = signal.signal(signum, interrupts.handler)
    except ValueError:  # not the main thread
        pass
    previous_int = previous.pop(signal.SIGINT, None)
    stepping = False  # in the step loop: a pre-emption leaves a checkpoint
    preempted_by = None  # the signal, handed on at the end to whoever listened before (submitit's requeue)
    try:
        run.metrics["precision_check"], note = precision_check(spec)
        if note:
            print(note, file=sys.stderr)
        run.build(step_policy(spec), solver_options(spec), sync_every(spec), spec.run.graph)
        sink.start(run.meta())
        driver = run.driver
        assert driver is not None  # made by run.build()
        if resume is None:
            driver.start()
        else:
            t0, loaded = time.perf_counter(), run.metrics.get("compile_time_s")
            driver.resume(resume.path)
            checkpoints.restore_recorder(run, resume.meta["recorder"])  # (the first process's metrics)
            run.metrics.setdefault("resumed_at", []).append(driver.step)
            run.metrics["resume_s"] = time.perf_counter() - t0  # [s] reading and restoring the checkpoint
            run.metrics["resume_compile_s"] = loaded  # [s] this process's compilation (or cache load)
        run.metrics["checkpoints"] = ckpts.describe()
        if Progress.shown(spec.log.progress):
            print(ckpts.describe(), file=sys.stderr, flush=True)
        interrupts.deferred = stepping = True  # Ctrl-C, SIGTERM and SIGUSR1 end the run at a step boundary
        try:
            while driver.running:
                interrupts.check()
                driver.advance()
                if ckpts.due(driver):
                    ckpts.write(driver, run)
        finally:
            interrupts.deferred = False
        if driver.outcome.status == "completed":
            run.metrics["status"], run.metrics["reason"] = "completed", ""
    except KeyboardInterrupt as e:
        what = e.name if isinstance(e, _Terminate) else "Ctrl-C"
        run.metrics["status"] = "interrupted"
        run.metrics["reason"] = f"{what} at step {run.step} (t = {run.t:.6g} s)"
        if isinstance(e, _Terminate) and stepping and run.driver is not None and run.driver.running:
            path = ckpts.write(run.driver, run)  # pre-empted: a checkpoint to resume from
            run.metrics["status"], preempted_by = "preempted", e.signum
            run.metrics["reason"] += f"; checkpoint {path}: run.resume=true hydra.run.dir={out_dir} continues"
    except Exception as e:
        run.metrics["status"] = "failed"
        run.metrics["reason"] = f"{type(e).__name__}: {e}"
        raise
    finally:
        # no second Ctrl-C may cut the cleanup short
        old_int = previous_int if previous_int is not None else signal.getsignal(signal.SIGINT)
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:
            old_int = None
        try:
            try:
                run.finish()
            except Exception as e:  # never leave a "completed" that did not complete
                run.metrics["status"] = "failed"
                run.metrics["reason"] = f"while finishing: {type(e).__name__}: {e}"
                raise
            finally:
                run.metrics["wall_time_s"] = time.perf_counter() - t_start
                run.metrics.update(ckpts.summary())
                sink.close()
                note = checkpoints.join_segments(out_dir, spec.log.recording, joined) if joined else ""
                if note:
                    print(note, file=sys.stderr)
                write_metrics(out_dir / "metrics.json", run.metrics)
                # the parts removed once the run has ended (after metrics.json: a run killed before, or
                # pre-empted again, goes on from them)
                if joined and not note and run.metrics.get("status") in ("completed", "unstable"):
                    checkpoints.drop_segments(out_dir, spec.log.recording)
        finally:
            if old_int is not None:
                signal.signal(signal.SIGINT, old_int)
            for signum, handler in previous.items():
                signal.signal(signum, handler)
    if preempted_by is not None and callable(listener := previous.get(preempted_by)):
        listener(preempted_by, None)  # e.g. submitit's: requeue the job, whose command then resumes
    return run.metrics


def write_metrics(path: Path, metrics: dict) -> None:
    """metrics.json, atomically, non-finite numbers as null."""
    def clean(v):
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        if isinstance(v, (np.floating, np.integer)):
            v = v.item()
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v

    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({k: clean(v) for k, v in metrics.items()}, indent=2) + "\n")
    tmp.replace(path)
