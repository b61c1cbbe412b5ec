"""Run one validated configuration: build, compile, step, log, report.

Hydra-free: ``pipelines.run`` composes the config and calls :func:`execute`.
Whatever happens (completion, instability, Ctrl-C, SIGTERM, an exception),
the recording is finalised and ``metrics.json`` written.
"""

from __future__ import annotations

import json
import math
import signal
import statistics
import time
from pathlib import Path

import numpy as np

import mpm

from . import provenance
from .progress import Progress
from .rerun_sink import RerunSink
from .sinks import RunMeta, Sink
from .validate import RunSpec

EXIT_CODES = {"completed": 0, "failed": 1, "unstable": 3, "interrupted": 130}

SCALAR_GROUPS_2D = {
    "energy": ["kinetic_energy", "elastic_energy", "potential_energy", "total_energy"],
    "momentum": ["momentum_x", "momentum_y", "angular_momentum"],
    "step": ["dt", "max_speed", "step_time_ms"],
    "configuration updates": ["config_updates"],
}


def scalar_groups(dim: int) -> dict:
    groups = dict(SCALAR_GROUPS_2D)
    if dim == 3:
        groups["momentum"] = ["momentum_x", "momentum_y", "momentum_z", "angular_momentum_x",
                              "angular_momentum_y", "angular_momentum_z"]
    return groups


class _Terminate(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (e.g. a cluster pre-empting the job)."""


def _raise_terminate(signum, frame):
    raise _Terminate()


class Drift:
    """Relative drift of conserved quantities between the first and last
    measurement, against the largest scale seen (see mpm.diagnostics)."""

    def __init__(self, names: list[str]):
        self.names = names
        self.p_idx = [i for i, n in enumerate(names) if n.startswith("momentum_") and n != "momentum_scale"]
        self.L_idx = [i for i, n in enumerate(names)
                      if n.startswith("angular_momentum") and n != "angular_momentum_scale"]
        self.first: np.ndarray | None = None
        self.last: np.ndarray | None = None
        self.p_scale = self.L_scale = 0.0

    def add(self, d: np.ndarray) -> None:
        if self.first is None:
            self.first = d.copy()
        self.last = d
        self.p_scale = max(self.p_scale, d[self.names.index("momentum_scale")])
        self.L_scale = max(self.L_scale, d[self.names.index("angular_momentum_scale")])

    def _rel(self, idx: list[int], scale: float) -> float:
        diff = float(np.linalg.norm(self.last[idx] - self.first[idx]))
        return diff / scale if scale > 0 else diff

    def energy(self, d: np.ndarray) -> float:
        return float(sum(d[self.names.index(k)] for k in ("kinetic_energy", "elastic_energy",
                                                          "potential_energy")))

    def summary(self) -> dict:
        if self.first is None:
            return {}
        m0, m1 = self.first[0], self.last[0]
        return {
            "mass_drift": abs(m1 - m0) / m0 if m0 else 0.0,
            "momentum_drift": self._rel(self.p_idx, self.p_scale),
            "angular_momentum_drift": self._rel(self.L_idx, self.L_scale),
            "energy_initial": self.energy(self.first),
            "energy_final": self.energy(self.last),
            "kinetic_energy_final": float(self.last[self.names.index("kinetic_energy")]),
            "elastic_energy_final": float(self.last[self.names.index("elastic_energy")]),
        }


def _median(xs: list[float]) -> float | None:
    return statistics.median(xs) if xs else None


def _meta(spec: RunSpec, model: mpm.Model, properties: dict) -> RunMeta:
    scene = spec.scene
    ppc = [b.ppc or scene.ppc for b in scene.bodies]
    spacing = model.dx / max(ppc) ** (1.0 / scene.dim)
    return RunMeta(
        name=f"{spec.scene_name} / {spec.scheme.name} / {spec.kernel.name}",
        dim=scene.dim, domain=model.domain, wall_cells=scene.wall_cells, dx=model.dx,
        body_names=[b.name for b in scene.bodies], particle_body=model.body.numpy(),
        particle_radius=0.5 * spacing, properties=properties,
        scalar_groups=scalar_groups(scene.dim))


def recording_properties(spec: RunSpec, config_yaml: str, overrides: list[str],
                         choices: dict | None = None) -> dict:
    """How to reproduce the run: resolved config, overrides, group choices,
    git commit and dirty flag, package versions, device, precision, seed."""
    prov = provenance.collect(spec.run.device, spec.run.precision, spec.seed, overrides)
    packages = prov.pop("packages")
    nonempty = lambda v: v or [""]  # noqa: E731 - Rerun needs a non-empty batch
    return {
        "config": {"yaml": config_yaml, "overrides": nonempty(list(overrides)),
                   "choices": nonempty([f"{k}={v}" for k, v in sorted((choices or {}).items())])},
        "provenance": {k: nonempty(v) if isinstance(v, list) else v for k, v in prov.items()},
        "packages": packages,
    }


def execute(spec: RunSpec, out_dir: Path, config_yaml: str = "", overrides: list[str] = (),
            choices: dict | None = None, sink: Sink | None = None) -> dict:
    """Run ``spec``; write the recording and ``metrics.json`` into ``out_dir``.

    ``config_yaml``, ``overrides`` and ``choices`` describe how the spec was
    composed; they are stored in the recording with the provenance."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    properties = recording_properties(spec, config_yaml, list(overrides), choices)
    run, log = spec.run, spec.log
    sink = sink if sink is not None else RerunSink(out_dir / log.recording, log.flush_every)
    metrics: dict = {"status": "failed", "reason": "did not start", "steps": 0, "sim_time": 0.0}
    step_ms: list[float] = []
    log_ms: list[float] = []
    dts: list[float] = []
    step, t = 0, 0.0
    model = state = solver = drift = None
    previous_term = None
    try:
        previous_term = signal.signal(signal.SIGTERM, _raise_terminate)
    except ValueError:  # not the main thread
        pass

    try:
        # ---------------------------------------------------------- build
        model, state = mpm.build(spec.scene, spec.kernel, run.precision, run.device, spec.seed)
        record_dJ = log.every > 0 and log.dJ
        solver = mpm.Solver(model, spec.scheme, mpm.SolverOptions(record_dJ=record_dJ))
        solver.prepare(state)
        metrics.update(particles=model.n_particles, grid_nodes=model.n_nodes)
        metrics["compile_time_s"] = solver.load()
        sink.start(_meta(spec, model, properties))
        names = solver.diagnostic_names()
        drift = Drift(names)

        i_elastic = names.index("elastic_energy")
        pending: list = []  # the scalar row of the last state, waiting for its elastic energy

        def measure(step, t, extra):
            """Measure the state just reached; its elastic energy arrives with
            the next step's P2G (or from finish())."""
            pending[:] = [step, t, solver.measure(state, elastic=False), extra]

        def emit(elastic_energy):
            step_, t_, d, extra = pending
            d[i_elastic] = elastic_energy
            drift.add(d)
            if log.scalars:
                row = dict(zip(names, d.tolist()))
                row["total_energy"] = drift.energy(d)
                row.update(extra)
                sink.scalars(step_, t_, row)
            pending.clear()

        def particles(step, t):
            # copies: on the CPU .numpy() is a view of memory the next step overwrites,
            # and the sink may serialise later
            x = state.x.numpy().copy()
            dJ = state.dJ.numpy().copy() if record_dJ else None
            sink.particles(step, t, x, dJ)

        measure(0, 0.0, {"config_updates": 0.0})
        if log.every:
            particles(0, 0.0)
        sink.event(0, 0.0, f"{spec.scheme.name}: the reference configuration is updated at every "
                   "step (s = n); the per-step count is the scalar config_updates",
                   scheme=spec.scheme.name, updates_every_step=True)

        # ---------------------------------------------------------- step
        steps_end, duration = spec.end
        progress = Progress(steps_end, duration, log.progress)
        max_speed = float(np.max(np.linalg.norm(state.v.numpy(), axis=1)))
        wave, visc = model.wave_speed(), model.kinematic_viscosity()
        metrics["status"], metrics["reason"] = "running", ""
        while (step < steps_end) if steps_end is not None else (t < duration * (1 - 1e-12)):
            if run.dt is not None:
                dt = run.dt
            else:
                dt = min(run.dt_max, mpm.cfl_dt(model.dx, wave, max_speed, run.cfl, visc, model.dim))
            if duration is not None:
                dt = min(dt, duration - t)
            t0 = time.perf_counter()
            solver.step(state, dt)
            monitor = solver.check()
            elapsed = time.perf_counter() - t0
            step += 1
            t += dt
            step_ms.append(1e3 * elapsed)
            dts.append(dt)
            if pending:
                emit(solver.step_energy())
            if monitor.reason:
                metrics["status"] = "unstable"
                metrics["reason"] = f"step {step} (t = {t:.6g} s): {monitor.reason}"
                metrics["unstable_step"] = step
                if log.every:
                    particles(step, t)
                sink.event(step, t, f"unstable: {metrics['reason']}", level="ERROR",
                           nonfinite=monitor.nonfinite, outside=monitor.outside)
                break
            max_speed = monitor.max_speed
            t1 = time.perf_counter()
            last = (step == steps_end) if steps_end is not None else (t >= duration * (1 - 1e-12))
            extra = {"dt": dt, "max_speed": max_speed, "step_time_ms": step_ms[-1],
                     "config_updates": float(step)}
            if log.scalars or last:
                measure(step, t, extra)
            if log.every and (step % log.every == 0 or last):
                particles(step, t)
                log_ms.append(1e3 * (time.perf_counter() - t1))
            progress.update(step, t, step_ms[-1])
        else:
            metrics["status"], metrics["reason"] = "completed", ""
        progress.close()
    except KeyboardInterrupt as e:
        metrics["status"] = "interrupted"
        what = "SIGTERM" if isinstance(e, _Terminate) else "Ctrl-C"
        metrics["reason"] = f"{what} at step {step} (t = {t:.6g} s)"
    except Exception as e:
        metrics["status"] = "failed"
        metrics["reason"] = f"{type(e).__name__}: {e}"
        raise
    finally:
        # no second Ctrl-C may cut the cleanup short
        old_int = signal.getsignal(signal.SIGINT)
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:
            old_int = None
        try:
            if drift is not None and metrics["status"] != "failed":
                # the last state reached: its elastic energy by one more P2G pass
                if not pending:
                    measure(step, t, {"config_updates": float(step)})
                emit(solver.measure(state)[i_elastic])
                if metrics["status"] == "interrupted" and log.every:
                    particles(step, t)
            if metrics["status"] == "interrupted":
                sink.event(step, t, f"interrupted: {metrics['reason']}", level="WARN")
            metrics.update(
                steps=step, sim_time=t,
                dt=(t / step) if step else None, dt_min=min(dts) if dts else None,
                dt_max=max(dts) if dts else None,
                step_time_ms=_median(step_ms), log_time_ms=_median(log_ms),
                config_updates=step, updates_per_1e4_steps=1e4 if step else None,
            )
            if drift is not None:
                metrics.update(drift.summary())
            metrics["wall_time_s"] = time.perf_counter() - t_start
            sink.close()
            _write_metrics(out_dir / "metrics.json", metrics)
        finally:
            if old_int is not None:
                signal.signal(signal.SIGINT, old_int)
            if previous_term is not None:
                signal.signal(signal.SIGTERM, previous_term)
    return metrics


def _write_metrics(path: Path, metrics: dict) -> None:
    def clean(v):
        if isinstance(v, (np.floating, np.integer)):
            v = v.item()
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v

    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({k: clean(v) for k, v in metrics.items()}, indent=2) + "\n")
    tmp.replace(path)
