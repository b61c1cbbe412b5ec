"""Run one validated configuration: build, compile, step, log, report.

Hydra-free: ``pipelines.run`` composes the config and calls :func:`execute`.
Whatever happens (completion, instability, Ctrl-C, SIGTERM, an exception),
the recording is finalised and ``metrics.json`` written.
"""

from __future__ import annotations

import collections
import json
import math
import signal
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np

import mpm
from mpm import analytic
from mpm.diagnostics import relative_drift, spilled_fraction

from . import provenance
from .progress import Progress
from ..recording.rerun_sink import RerunSink
from ..recording.sinks import RunMeta, Sink
from ..config.validate import RunSpec


IMPLICIT_SCALARS = ["newton_iterations", "cg_iterations", "newton_residual"]


def scalar_groups(dim: int, marked: list[str], error: bool = False, implicit: bool = False) -> dict:
    """Time-series views of the recording's blueprint: scalar names, or entity
    paths (the wall-clock timings, in the timings file)."""
    momentum = (["momentum_x", "momentum_y", "angular_momentum"] if dim == 2 else
                ["momentum_x", "momentum_y", "momentum_z", "angular_momentum_x",
                 "angular_momentum_y", "angular_momentum_z"])
    groups = {
        "energy": ["kinetic_energy", "elastic_energy", "potential_energy", "total_energy"],
        "momentum": momentum,
        "step": ["dt", "dt_fresh", "max_speed"],
        "wall clock [ms]": ["/timings/step_time_ms", "/timings/update_ms"],
        "configuration updates": ["config_updates", "fracture", "fragments"] + marked,
    }
    if error:
        groups["error"] = ["error/displacement", "error/velocity"]
    if implicit:
        groups["implicit solve"] = IMPLICIT_SCALARS
    return groups


class _Terminate(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (e.g. a cluster pre-empting the job)."""


class Interrupts:
    """Ctrl-C and SIGTERM. Outside the step loop they raise at once; inside
    it they are remembered and raised at the next step boundary
    (:meth:`check`): Python ignores an exception raised while a finaliser
    runs (a Warp array's ``__del__``, say, which the loop triggers every step),
    so a signal raised wherever it lands can be lost. A second signal while
    one is pending raises at once."""

    def __init__(self):
        self.deferred = False
        self.pending: type[KeyboardInterrupt] | None = None

    def handler(self, signum, frame):
        exc = _Terminate if signum == signal.SIGTERM else KeyboardInterrupt
        if self.deferred and self.pending is None:
            self.pending = exc
            return
        raise exc()

    def check(self) -> None:
        if self.pending is not None:
            exc, self.pending = self.pending, None
            raise exc()


class Drift:
    """Relative drift of conserved quantities between the first and last
    measurement: against the first value, or the largest scale seen when the
    first is near zero (mpm.diagnostics.relative_drift; angular momentum is
    about the centre of mass)."""

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
        return relative_drift(self.first[idx], self.last[idx], scale)

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


def peak_rss_mb() -> float | None:
    """The process's peak resident memory [MB] so far (None where the OS does not say)."""
    try:
        import resource
    except ImportError:  # not a Unix
        return None
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1e6 if sys.platform == "darwin" else kb / 1e3  # macOS counts bytes


def _median(xs: list[float]) -> float | None:
    return statistics.median(xs) if xs else None


RUN_PROPERTIES = ("command", "host", "started")  # differ between identical runs


def recording_properties(spec: RunSpec, config_yaml: str, overrides: list[str],
                         choices: dict | None = None) -> dict:
    """How to reproduce the run: resolved config, overrides, group choices,
    git commit and dirty flag, package versions, device, precision, seed; and
    (``run``: the timings file's) when, where and with which command it ran."""
    prov = provenance.collect(spec.run.device, spec.run.precision, spec.seed, overrides)
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


def solver_options(spec: RunSpec) -> mpm.SolverOptions:
    """What the solver compiles for this run: dJ only when it is logged, the
    detection's measurements only when it is on."""
    detect = spec.detect.action != "off"
    return mpm.SolverOptions(record_dJ=spec.log.particles and spec.log.dJ, transfer=spec.transfer,
                             integrator=spec.integrator, track_energy=detect, fuse=spec.run.fuse,
                             track_J=detect and any(not b.material.invertible for b in spec.scene.bodies))


def plan(spec: RunSpec) -> str:
    """``run.plan=true``: the stages of a step and the kernels they launch,
    the run's size, and what it logs; nothing is compiled or run."""
    model, _ = mpm.build(spec.scene, spec.kernel, spec.run.precision, spec.run.device, spec.seed)
    solver = mpm.Solver(model, spec.scheme, solver_options(spec))
    log = spec.log
    frames = ("none" if not log.particles else f"every {log.every} steps" if log.every is not None
              else f"{log.fps:g} per simulated second")
    lines = [f"{spec.scene_name}: {model.n_particles} particles, {len(spec.scene.bodies)} body(ies), "
             f"{model.dim}D, {spec.run.precision} on {spec.run.device}; {solver.scheme.name}, "
             f"{spec.kernel.name} kernel ({spec.transfer}), {spec.integrator.name} integrator",
             "step:"]
    for i, (stage, kernels) in enumerate(solver.plan(), 1):
        lines.append(f"  {i}. {stage}" + (f": {', '.join(kernels)}" if kernels else ""))
    lines.append(f"logging: particle frames {frames}" + (" with dJ" if solver.options.record_dJ else "")
                 + (", scalars every step" if log.scalars else ", no scalars")
                 + f", fracture every {log.fracture_every} steps; detection {spec.detect.action}")
    lines.append(f"kernels compiled: {len(solver.kernels())}")
    return "\n".join(lines)


class Run:
    """One run: the solver, the sink and the bookkeeping between them."""

    def __init__(self, spec: RunSpec, out_dir: Path, properties: dict, sink: Sink):
        self.spec, self.out_dir, self.properties, self.sink = spec, out_dir, properties, sink
        self.metrics: dict = {"status": "failed", "reason": "did not start", "steps": 0,
                              "sim_time": 0.0}
        self.step, self.t = 0, 0.0
        self.step_ms: list[float] = []
        self.log_ms: list[float] = []
        self.update_ms: list[float] = []
        self.dts: list[float] = []
        self.solver = self.state = self.drift = None
        self.built = False  # build() completed: finish() may summarise the run
        self._landing = False  # the last step was shortened to land on the duration
        self.fracture = None  # (overall, per body) at the last evaluation
        self.fracture_step = -1
        self._pieces = None  # (fracture per body, fragments per body) at the last count
        self.inside_max = None  # per collider: the most particles seen inside it
        self.solution = None  # closed-form solution of the scene, if any (mpm.analytic)
        self.error_last: dict | None = None
        self._error_step = -1
        self._pending: list = []  # the last state's scalar row, waiting for its elastic energy
        self.detector: mpm.Detector | None = None  # blow-up detection (mpm.stability)
        self._energies = (0.0, 0.0)  # kinetic and potential energy [J] of the last state reached
        self._dt0: float | None = None  # the first adaptive step [s]
        self.interrupts = Interrupts()
        self._stable_dt = math.inf
        self._fresh_dt = math.inf  # the step a freshly updated reference would allow [s]
        self.dt_binding: collections.Counter = collections.Counter()  # steps per binding term
        self.reference_factors: list[float] = []  # per step: dt / fresh dt of the binding body

    # ------------------------------------------------------------ build
    def build(self) -> None:
        spec, run, log = self.spec, self.spec.run, self.spec.log
        self.model, self.state = mpm.build(spec.scene, spec.kernel, run.precision, run.device, spec.seed)
        self.solver = mpm.Solver(self.model, spec.scheme, solver_options(spec))
        self.implicit = self.solver.implicit
        self.newton: list[tuple[int, int, float]] = []  # per step: Newton and CG iterations, residual
        self.halvings = 0  # implicit steps retried with half the step
        self._dt_scale = 1.0  # the adaptive implicit step's factor after halvings (recovers x2 per step)
        self.scheme = self.solver.scheme  # defaults resolved
        self.metrics.update(particles=self.model.n_particles, domain_nodes=self.model.n_nodes,
                            scene=spec.scene_name, resolution=spec.scene.resolution, dx=self.model.dx,
                            precision=run.precision, device=run.device)
        # a first run compiles its kernels (Warp caches them): say so when it takes a while
        notice = threading.Timer(1.0, lambda: print("compiling kernels (first run only; Warp caches them) ...",
                                                    file=sys.stderr, flush=True))
        if Progress.shown(log.progress):
            notice.start()
        try:
            self.metrics["compile_time_s"] = self.solver.load()
        finally:
            notice.cancel()
        self.solver.prepare(self.state)
        self.X0 = self.solver.X0  # initial positions [m], float64
        self.mass0 = self.model.mass.numpy().astype(np.float64)  # [kg] (removed particles' mass becomes 0)
        self.solution = spec.scene.solution
        self.error_max = {"displacement": 0.0, "velocity": 0.0}
        self.names = self.solver.diagnostic_names()
        self.drift = Drift(self.names)
        bodies = [b.name for b in spec.scene.bodies]
        def per_body(name: str) -> list[str]:  # one scalar, or one per body
            return [name] if len(bodies) == 1 else [f"{name}/{b}" for b in bodies]

        self.marked_names = per_body("marked_fraction")
        self.stretch_names = per_body("min_stretch")
        self.updates = np.zeros(len(bodies), np.int64)
        self.update_steps = 0  # steps at which at least one body was updated
        self.built = True

    def meta(self) -> RunMeta:
        scene, model = self.spec.scene, self.model
        ppc = [b.ppc or scene.ppc for b in scene.bodies]
        return RunMeta(
            name=f"{self.spec.scene_name} / {self.scheme.name} / {self.spec.kernel.name} "
                 f"({self.spec.transfer})",
            dim=scene.dim, domain=model.domain, wall_cells=scene.wall_cells, dx=model.dx,
            body_names=[b.name for b in scene.bodies], particle_body=model.body.numpy(),
            particle_radius=0.5 * scene.particle_dx / max(ppc) ** (1.0 / scene.dim),
            color=self.spec.log.color,
            properties={k: v for k, v in self.properties.items() if k != "run"},
            run_properties={"run": self.properties["run"]}, colliders=list(scene.colliders),
            scalar_groups=scalar_groups(scene.dim, (self.marked_names if self.scheme.tracks_marks() else [])
                                        + (self.stretch_names if self.scheme.name != "empm" else []),
                                        self.solution is not None or self.spec.run.reference is not None,
                                        self.implicit))

    # ------------------------------------------------------------ logging
    def measure(self, extra: dict) -> None:
        """Measure the state just reached; its elastic energy arrives with the
        next step's P2G (or from :meth:`finish`)."""
        self._pending[:] = [self.step, self.t, self.solver.measure(self.state, elastic=False), extra]

    def emit(self, elastic_energy: float) -> None:
        step, t, d, extra = self._pending
        d[self.names.index("elastic_energy")] = elastic_energy
        self.drift.add(d)
        if self.spec.log.scalars:
            row = dict(zip(self.names, d.tolist()))
            row["total_energy"] = self.drift.energy(d)
            row.update(extra)
            self.sink.scalars(step, t, row)
        self._pending.clear()

    def particles(self) -> None:
        """Particles, dJ and the plastic fields of the current state."""
        # copies: on the CPU .numpy() is a view of memory the next step
        # overwrites, and the sink may serialise later
        x = self.state.x.numpy().copy()
        dJ = self.state.dJ.numpy().copy() if self.solver.options.record_dJ else None
        fields = self.plastic_fields()
        index = self.solver.kept  # the particles left inside, once some were removed at open walls
        if index is not None:
            x, dJ = x[index], (dJ[index] if dJ is not None else None)
            fields = {k: v[index] for k, v in fields.items()}
        self.sink.particles(self.step, self.t, x, dJ, fields, index)

    def frame_due(self, last: bool) -> bool:
        """Whether this step's particles are logged: every ``log.every`` steps,
        or (log.every null) at the first step at or past each multiple of
        1 / log.fps in simulated time; the last step always."""
        every = self.spec.log.every
        if every is not None:
            return every > 0 and (self.step % every == 0 or last)
        if self.t >= self._next_frame * (1.0 - 1e-9) or last:
            self._next_frame = (math.floor(self.t * self.spec.log.fps * (1.0 + 1e-9)) + 1) / self.spec.log.fps
            return True
        return False

    def recording_mb(self, dt: float) -> tuple[float, int, int]:
        """Estimated size of the recording [MB], its particle frames and steps,
        from the first step ``dt`` [s] (an adaptive step may shrink later)."""
        log, (steps_end, duration) = self.spec.log, self.spec.end
        steps = steps_end if steps_end is not None else math.ceil(duration / dt)
        t_end = duration if duration is not None else steps * dt
        if not log.particles:
            frames = 0
        elif log.every is not None:
            frames = steps // log.every + 2
        else:
            frames = min(steps, math.ceil(t_end * log.fps)) + 2
        n = self.model.n_particles
        per_particle = 4 * self.model.dim + 3 + 4 * (log.dJ + len(self.plastic_fields()))
        scalars = 24 * (len(self.names) + 12) if log.scalars else 0  # value, step and time per scalar
        return (frames * n * per_particle + (steps + 1) * scalars) / 1e6, frames, steps

    def warn_size(self, dt: float) -> None:
        """Say so before a run whose recording would pass log.size_warning_mb."""
        mb, frames, steps = self.recording_mb(dt)
        limit = self.spec.log.size_warning_mb
        if mb > limit:
            text = (f"the recording will be about {mb:,.0f} MB ({frames} particle frames of "
                    f"{self.model.n_particles} particles, scalars for about {steps} steps), over "
                    f"log.size_warning_mb={limit:g}: lower log.fps or raise log.every (log.every=0: no particles)")
            print(f"warning: {text}", file=sys.stderr, flush=True)
            self.sink.event(0, 0.0, text, level="WARN", estimated_mb=mb)
        self.metrics["recording_estimate_mb"] = mb

    def record_removed(self, report: mpm.StepReport) -> None:
        """Particles that left through open walls: an event per body, counted."""
        for b, n in enumerate(report.removed):
            if n:
                name = self.spec.scene.bodies[b].name
                total = int(self.solver.removed[b])
                self.sink.event(self.step, self.t, f"{n} particles of {name} left through an open wall and were "
                                                   f"removed ({total} so far)",
                                body=name, removed=int(n), removed_total=total)

    def plastic_fields(self) -> dict[str, np.ndarray]:
        """Named per-particle fields of the plastic bodies (mpm.materials.Plastic.fields)
        as the last return mapping left them; NaN on the particles of other bodies."""
        if not self.model.plastic:
            return {}
        history = self.state.history.numpy()
        J_E = np.linalg.det(self.state.Fsn.numpy() @ self.state.F0s.numpy())
        n = self.model.n_particles
        out: dict[str, np.ndarray] = {}
        for body, (start, count) in zip(self.spec.scene.bodies, self.model.body_ranges):
            if body.material.plastic:
                rows = slice(start, start + count)
                for name, values in body.material.fields(history[rows], J_E[rows]).items():
                    out.setdefault(name, np.full(n, np.nan, np.float32))[start:start + count] = values
        return out

    def plastic_summary(self) -> dict:
        """metrics.json ``plastic``: per plastic body, min / mean / max of each field."""
        fields = self.plastic_fields()
        out = {}
        for body, (start, count) in zip(self.spec.scene.bodies, self.model.body_ranges):
            if body.material.plastic:
                rows = {k: v[start:start + count] for k, v in fields.items()}
                out[body.name] = {k: {"min": float(np.min(v)), "mean": float(np.mean(v)),
                                      "max": float(np.max(v))}
                                  for k, v in rows.items() if np.isfinite(v).all()}
        return out

    def errors(self) -> dict:
        """RMS error of the particles against the closed-form solution at the
        current time: E = sqrt(sum_p |phi_p - phi(X_p, t)|^2 / n_p)."""
        x = self.state.x.numpy().astype(np.float64)
        v = self.state.v.numpy().astype(np.float64)
        sol = self.solution
        e = {"displacement": analytic.rms(x - self.X0, sol.displacement(self.X0, self.t)),
             "velocity": analytic.rms(v, sol.velocity(self.X0, self.t))}
        for k, val in e.items():
            self.error_max[k] = max(self.error_max[k], val)
        self.error_last, self._error_step = e, self.step
        return {f"error/{k}": val for k, val in e.items()}

    def save_final_state(self) -> None:
        """``final_state.npz``: positions x, velocities v, initial positions X0
        and masses of the last state (self-convergence and trade-off studies
        compare these)."""
        np.savez(self.out_dir / "final_state.npz", x=self.state.x.numpy(), v=self.state.v.numpy(),
                 X0=self.X0, mass=self.model.mass.numpy(), body=self.model.body.numpy(), step=self.step,
                 time=self.t)

    def spilled(self) -> dict:
        """Per fluid body and bowl-shaped body, the fraction of the fluid below
        the bowl's rim plane outside it (mpm.diagnostics.spilled_fraction)."""
        bodies = self.spec.scene.bodies
        bowls = [b for b in bodies if isinstance(b.shape, mpm.scene.Bowl)]
        fluids = [(i, b) for i, b in enumerate(bodies) if b.material.fluid]
        if not bowls or not fluids:
            return {}
        x, body = self.state.x.numpy().astype(np.float64), self.model.body.numpy()
        return {f"{b.name}/{bowl.name}": spilled_fraction(x[body == i], bowl.shape)
                for i, b in fluids for bowl in bowls}

    def reference_errors(self, path: str) -> dict:
        """RMS difference of the final positions and velocities to a reference
        run's final state with the same particles (the A-ULMPM paper's eq. 36),
        also logged as the last step's error/* scalars."""
        ref = np.load(path)
        out = {"solution": "reference", "reference": path}
        if ref["X0"].shape != self.X0.shape or not np.allclose(ref["X0"], self.X0, rtol=0, atol=1e-9):
            return {**out, "problem": "the reference has other particles (scene.particle_resolution "
                                      "fixes the particle set across grids)"}
        if abs(float(ref["time"]) - self.t) > 1e-9 * max(1.0, self.t):
            return {**out, "problem": f"the reference ends at t = {float(ref['time']):.6g} s, this run at "
                                      f"{self.t:.6g} s"}
        x, v = self.state.x.numpy().astype(np.float64), self.state.v.numpy().astype(np.float64)
        e = {"displacement": analytic.rms(x, ref["x"].astype(np.float64)),
             "velocity": analytic.rms(v, ref["v"].astype(np.float64))}
        self.sink.scalars(self.step, self.t, {f"error/{k}": v for k, v in e.items()})
        return {**e, **out}

    def log_fracture(self) -> np.ndarray:
        """The fracture measure and the pieces per body (recounted only when a
        body's fraction of broken pairs changed: the count is a host-side graph
        search, 0.1 s for 100K particles)."""
        frac = self.solver.fracture(self.state)
        overall = float(np.sum(frac * self.solver.pair_counts) / max(self.solver.pair_counts.sum(), 1))
        if self._pieces is None or not np.array_equal(frac, self._pieces[0]):
            self._pieces = (frac.copy(), self.solver.fragments())
        pieces = self._pieces[1]
        row = {"fracture": overall, "fragments": float(pieces.sum())}
        if len(frac) > 1:
            row.update({f"fracture/{b.name}": float(f) for b, f in zip(self.spec.scene.bodies, frac)})
            row.update({f"fragments/{b.name}": float(c) for b, c in zip(self.spec.scene.bodies, pieces)})
        inside = self.solver.inside_colliders(self.state)
        if len(inside):
            names = self.collider_names()
            row["inside_colliders"] = float(inside.sum())
            if len(inside) > 1:
                row.update({f"inside_colliders/{n}": float(c) for n, c in zip(names, inside)})
            self.inside_max = inside if self.inside_max is None else np.maximum(self.inside_max, inside)
            self.inside_last = inside
        self.sink.scalars(self.step, self.t, row)
        self.fracture, self.fracture_step = (overall, frac), self.step
        return frac

    def collider_names(self) -> list[str]:
        return [c.name or f"{c.kind}{i}" for i, c in enumerate(self.spec.scene.colliders)]

    def announce_scheme(self) -> None:
        s = self.scheme
        if s.name == "empm":
            text = ("empm: every body's reference configuration is updated at every step (s = n); "
                    "the cumulative count is the scalar config_updates")
        elif s.name == "tlmpm":
            text = "tlmpm: the reference configuration is the initial one (s = 0), never updated"
        else:
            text = (f"aulmpm ({s.criterion} criterion): a body is updated when the fraction of its "
                    f"particles with dJ >= {s.epsilon:g} reaches {s.eta:g}")
            if s.criterion == "distortion":
                text += (f", or a particle has dJ >= {max(s.dJ_max, s.epsilon):g} or a reference cell "
                         f"is squeezed below {s.stretch_min:g} of its width")
            text += f"; affine matrix: {s.affine}"
        params = {k: v for k, v in vars(s).items() if isinstance(v, (int, float, str))}
        self.sink.event(0, 0.0, text, scheme=s.name, **params)
        if self.implicit:
            i = self.spec.integrator
            step = (f"fixed step {self.spec.run.dt:g} s" if self.spec.run.dt is not None else
                    f"adaptive step: at most {i.displacement:g} cell per step, halved up to {i.halvings} "
                    "times after a failed solve")
            kind = ("the semi-implicit update (one Newton step)" if i.newton_max == 1 else
                    f"Newton to {i.newton_tol:g} of the initial residual in at most {i.newton_max} iterations")
            self.sink.event(0, 0.0, f"implicit: backward Euler, {kind}; CG to {i.cg_tol:g} in at most "
                                    f"{i.cg_max} iterations; {step}",
                            **{k: v for k, v in vars(i).items() if isinstance(v, (int, float, str))})

    def record_updates(self, report: mpm.StepReport) -> None:
        counts = self.solver.body_counts
        if report.updated:
            self.update_steps += 1
            self.updates[report.updated] += 1
        if self.scheme.name != "aulmpm":
            return  # EMPM: every step, logged as the count; TLMPM: never
        for b in report.updated:
            name = self.spec.scene.bodies[b].name
            frac = report.marked[b] / counts[b]
            self.sink.event(
                self.step, self.t,
                f"configuration update of {name}: {100 * frac:.1f}% of its particles have "
                f"dJ >= {self.scheme.epsilon:g}",
                body=name, marked_fraction=float(frac), update_step=self.step, update_time=self.t)

    def row_extra(self, dt: float, report: mpm.StepReport) -> dict:
        extra = {"dt": dt, "dt_fresh": self._fresh_dt, "max_speed": report.max_speed,
                 "config_updates": float(self.updates.sum())}
        if self.scheme.tracks_marks():
            for name, m, n in zip(self.marked_names, report.marked, self.solver.body_counts):
                extra[name] = float(m / max(n, 1))
        if self.scheme.name != "empm":  # the narrowest reference cell (1 in EMPM)
            for name, s in zip(self.stretch_names, report.min_stretch):
                extra[name] = float(s)
        if self.solution is not None:
            extra.update(self.errors())
        if self.solver.removal:
            extra["removed"] = float(self.solver.removed.sum())
        if report.newton is not None:
            n = report.newton
            extra.update(newton_iterations=float(n.newton), cg_iterations=float(n.cg),
                         newton_residual=n.residual)
        return extra

    # ------------------------------------------------------------ loop
    def next_dt(self, report: mpm.StepReport | None, duration: float | None) -> float:
        """The solver's stable step (mpm.Solver.stable_dt) capped by run.dt_max,
        unless run.dt fixes it; the implicit integrator's step is the
        displacement limit instead (mpm.Solver.displacement_dt), times a
        factor that halves with a failed solve and recovers; the last step
        ends on the duration."""
        run = self.spec.run
        if self.implicit:
            limit_dt = self._dt_scale * self.solver.displacement_dt(report, self._v0)
            self._fresh_dt, self._reference_factor = limit_dt, 1.0
            binding = "displacement"
        else:
            limits = self.solver.step_limits(run.cfl, report, self._v0)
            limit = min(limits, key=lambda lim: lim.dt)
            self._fresh_dt = min(run.dt_max, min(lim.fresh for lim in limits))
            self._reference_factor = limit.reference_factor
            limit_dt, binding = limit.dt, limit.binding
        if run.dt is not None:
            dt = run.dt
            self.dt_binding["fixed"] += 1
        else:
            dt = min(run.dt_max, limit_dt)
            self.dt_binding["dt_max" if run.dt_max <= limit_dt else binding] += 1
            if self._dt0 is None:
                self._dt0 = dt
        self._stable_dt = dt
        return dt if duration is None else min(dt, duration - self.t)

    def _speed(self, report: mpm.StepReport | None) -> float:
        return report.max_speed if report is not None else self._v0

    def collapsed(self) -> str | None:
        """Why the adaptive step counts as collapsed (a particle's strain rate or
        compression running away), or None: below run.dt_collapse of the first step."""
        dt, dt0 = self._stable_dt, self._dt0
        if self.spec.run.dt is not None or dt0 is None:
            return None
        if not (dt >= self.spec.run.dt_collapse * dt0):  # NaN and 0 included
            return (f"time step collapsed to {dt:.3g} s, below {self.spec.run.dt_collapse:g} of the first "
                    f"step ({dt0:.3g} s): a particle's strain rate or compression is running away")
        return None

    def loop(self) -> None:
        log = self.spec.log
        steps_end, duration = self.spec.end
        self.measure({"config_updates": 0.0, **(self.errors() if self.solution is not None else {})})
        if log.particles:
            self.particles()
            self._next_frame = 1.0 / log.fps
        self.log_fracture()
        self.announce_scheme()
        progress = Progress(steps_end, duration, log.progress)
        self._v0 = float(np.max(np.linalg.norm(self.state.v.numpy(), axis=1)))
        if self.spec.detect.action != "off":
            self.detector = mpm.Detector(self.spec.detect, self.spec.scene, self.solver.boundary_speed(),
                                         self._v0, self.model.kernel.n_grids,
                                         float(self.model.mass.numpy().astype(np.float64).sum()))
        self.metrics["status"], self.metrics["reason"] = "running", ""
        d0 = self._pending[2]
        energies = [float(d0[self.names.index(k)]) for k in ("kinetic_energy", "potential_energy")]
        if not (np.all(np.isfinite(energies)) and np.isfinite(self._v0)):
            self.unstable(f"the initial state's kinetic or potential energy is not finite (fastest particle "
                          f"{self._v0:.3g} m/s in {self.spec.run.precision}): velocities or positions "
                          f"overflow", "nonfinite")
            progress.close()
            return
        if self.detector is not None:  # the initial state's energies; then each step's G2P sums them
            self._energies = (float(d0[self.names.index("kinetic_energy")]),
                              float(d0[self.names.index("potential_energy")]))
            if self.react(self.detector.initial(self.state.numpy()["F"], self.model.body.numpy())):
                progress.close()
                return

        def done() -> bool:
            return self.step >= steps_end if steps_end is not None else self.t >= duration * (1 - 1e-12)

        self.interrupts.deferred = True
        try:
            self._steps(done, duration, progress)
        finally:
            self.interrupts.deferred = False
            progress.close()

    def _steps(self, done, duration, progress) -> None:
        """Step until done, unstable or interrupted (at a step boundary)."""
        log = self.spec.log
        report = None
        while not done():
            self.interrupts.check()
            dt = self.next_dt(report, duration)
            if self.step == 0 and 0.0 < dt < math.inf:
                self.warn_size(dt)
            collapse = self.collapsed()
            if not (0.0 < dt < math.inf):  # a step of 0 would never end the run (or end it at t = 0)
                collapse = (f"the time step is {dt:.3g} s (fastest particle {self._speed(report):.3g} m/s): "
                            "the run cannot advance")
            if collapse:
                self.unstable(collapse, "dt_collapse")
                break
            t0 = time.perf_counter()
            halvings = self.spec.integrator.halvings if self.implicit and self.spec.run.dt is None else 0
            report = self.solver.advance(self.state, dt, halvings)
            self.step_ms.append(1e3 * (time.perf_counter() - t0))
            if self._pending:
                self.emit(self.solver.step_energy())
            trips = []
            if self.detector is not None and (report.newton is None or report.newton.converged):
                # the state the step started from: its kinetic and potential energy from the last
                # G2P, its elastic energy from this step's P2G
                trips = self.detector.energy(self._energies[0], self.solver.step_energy(), self._energies[1])
                self._energies = (report.kinetic, report.potential)
            if report.newton is not None and not report.newton.converged:  # the state is the step's start
                n = report.newton
                self.unstable(report.reason, "newton", newton_iterations=n.newton, cg_iterations=n.cg,
                              newton_residual=n.residual, halvings=report.halvings)
                break
            self.update_ms.append(1e3 * report.update_time)
            self.dts.append(report.dt)
            self._landing = dt < self._stable_dt  # shortened to land on the duration
            self.reference_factors.append(self._reference_factor)
            self.step += 1
            self.t += report.dt
            if report.newton is not None:
                self.record_newton(report)
            # the detection names the cause when particles also left the domain in this step
            if (self.detector is not None and not report.nonfinite
                    and self.react(trips + self.detector.step(report))):
                break
            if report.reason:
                self.unstable(report.reason, "nonfinite" if report.nonfinite else "outside",
                              nonfinite=report.nonfinite, outside=report.outside)
                break
            if report.removed is not None:
                self.record_removed(report)
            self.record_updates(report)
            self.sink.timings(self.step, self.t, {"step_time_ms": self.step_ms[-1], **(
                {"update_ms": self.update_ms[-1]} if report.updated else {})})
            t1 = time.perf_counter()
            last = done()
            if log.scalars or last:
                self.measure(self.row_extra(dt, report))
            if log.particles and self.frame_due(last):
                self.particles()
                self.log_ms.append(1e3 * (time.perf_counter() - t1))
            if self.step % log.fracture_every == 0:
                self.log_fracture()
            progress.update(self.step, self.t, self.step_ms[-1])
        else:
            self.metrics["status"], self.metrics["reason"] = "completed", ""

    def record_newton(self, report: mpm.StepReport) -> None:
        """Iteration counts of an implicit step; halvings as events."""
        n = report.newton
        self.newton.append((n.newton, n.cg, n.residual))
        if report.halvings:
            self.halvings += report.halvings
            self._dt_scale *= 0.5 ** report.halvings
            self.sink.event(self.step, self.t, f"implicit step halved {report.halvings} time(s) to "
                                               f"{report.dt:.3g} s after a failed Newton solve",
                            level="WARN", halvings=report.halvings, dt=report.dt)
        else:
            self._dt_scale = min(1.0, 2.0 * self._dt_scale)

    def implicit_summary(self) -> dict:
        """metrics.json ``implicit``: Newton and CG iterations per step."""
        opt = self.spec.integrator
        out = {"newton_max": opt.newton_max, "newton_tol": opt.newton_tol, "cg_max": opt.cg_max,
               "cg_tol": opt.cg_tol, "halvings": self.halvings}
        if self.newton:
            a = np.array(self.newton, dtype=float)
            out.update(newton_mean=float(a[:, 0].mean()), newton_max_seen=int(a[:, 0].max()),
                       cg_mean=float(a[:, 1].mean()), cg_max_seen=int(a[:, 1].max()),
                       cg_per_newton=float(a[:, 1].sum() / max(a[:, 0].sum(), 1.0)),
                       residual_max=float(a[:, 2].max()))
        return out

    def react(self, trips: list) -> bool:
        """Act on the detection's trips (mpm.stability): with detect.action
        ``stop`` the first ends the run unstable (True); with ``warn`` each is
        an event and a line of metrics.json ``detect_warnings``."""
        for trip in trips:
            if self.spec.detect.action == "stop":
                self.unstable(trip.message, trip.criterion, trip.body, value=trip.value, limit=trip.limit)
                return True
            self.metrics.setdefault("detect_warnings", []).append(
                {"step": self.step, "time": self.t, "criterion": trip.criterion, "body": trip.body,
                 "message": trip.message})
            where = {"criterion": trip.criterion, **({"body": trip.body} if trip.body else {})}
            self.sink.event(self.step, self.t, f"stability warning: {trip.message}", level="WARN",
                            **where, value=trip.value, limit=trip.limit)
        return False

    def unstable(self, reason: str, criterion: str, body: str | None = None, **values) -> None:
        """End the run as unstable at this step: ``criterion`` (nonfinite,
        outside, dt_collapse, newton, or a detection criterion of
        mpm.stability) and the ``body`` it names, if any."""
        self.metrics["status"] = "unstable"
        self.metrics["reason"] = f"step {self.step} (t = {self.t:.6g} s): {reason}"
        self.metrics["unstable_step"] = self.step
        self.metrics["unstable_time"] = self.t
        self.metrics["unstable_criterion"] = criterion
        self.metrics["unstable_body"] = body
        if self.spec.log.particles:
            self.particles()
        where = {"criterion": criterion, **({"body": body} if body else {})}
        self.sink.event(self.step, self.t, f"unstable: {self.metrics['reason']}", level="ERROR", **where, **values)

    # ------------------------------------------------------------ finish
    def finish(self) -> None:
        """Complete the last scalar row, summarise, close the sink, write metrics.json."""
        m = self.metrics
        if self.built and m["status"] != "failed":
            # the last state reached: its elastic energy by one more P2G pass
            if not self._pending:
                self.measure({"config_updates": float(self.updates.sum())})
            self.emit(self.solver.measure(self.state)[self.names.index("elastic_energy")])
            if m["status"] == "interrupted" and self.spec.log.particles:
                self.particles()
            if self.fracture is None or self.fracture_step != self.step:
                self.log_fracture()
            overall, per_body = self.fracture
            names = [b.name for b in self.spec.scene.bodies]
            m["fracture"] = {"total": overall, **{n: float(f) for n, f in zip(names, per_body)}}
            if self.inside_max is not None:  # particles more than a cell deep in a collider
                m["inside_colliders"] = {n: {"final": int(a), "max": int(b)} for n, a, b in
                                         zip(self.collider_names(), self.inside_last, self.inside_max)}
            spilled = self.spilled()
            if spilled:
                m["spilled"] = spilled
            pieces = self.solver.fragments()  # exact at the end
            m["fragments"] = {"total": int(pieces.sum()), **{n: int(c) for n, c in zip(names, pieces)}}
            self.save_final_state()
            if self.model.plastic:
                m["plastic"] = self.plastic_summary()
            if self.spec.run.reference is not None and m["status"] == "completed":
                m["error"] = self.reference_errors(self.spec.run.reference)
            elif self.solution is not None:
                if self.error_last is None or self._error_step != self.step:
                    self.errors()
                u, v = self.solution.scales()
                m["error"] = {"displacement": self.error_last["displacement"],
                              "velocity": self.error_last["velocity"],
                              "displacement_max": self.error_max["displacement"],
                              "velocity_max": self.error_max["velocity"],
                              "displacement_scale": u, "velocity_scale": v, "solution": self.solution.name}
        if m["status"] == "interrupted":
            self.sink.event(self.step, self.t, f"interrupted: {m['reason']}", level="WARN")
        steps = self.step
        m.update(
            steps=steps, sim_time=self.t,
            dt=(self.t / steps) if steps else None,
            # the last step, shortened to land on the duration, is not a step the rule chose
            dt_min=min(self.dts[:-1] if self._landing and len(self.dts) > 1 else self.dts) if self.dts else None,
            dt_max=max(self.dts) if self.dts else None,
            dt_binding=dict(self.dt_binding),
            # the stable step against what a fresh reference would allow (1: the reference costs nothing)
            dt_reference_factor=float(np.mean(self.reference_factors)) if self.reference_factors else None,
            step_time_ms=_median(self.step_ms), log_time_ms=_median(self.log_ms),
            loop_time_s=sum(self.step_ms) / 1e3)
        if m["step_time_ms"] and "particles" in m:
            m["particle_steps_per_s"] = m["particles"] / (m["step_time_ms"] / 1e3)
        if self.built:
            names = [b.name for b in self.spec.scene.bodies]
            m.update(
                scheme=self.scheme.name, kernel=self.spec.kernel.name, transfer=self.spec.transfer,
                grid_nodes=self.solver.layout.n_nodes,
                config_updates={"total": int(self.updates.sum()),
                                **{n: int(c) for n, c in zip(names, self.updates)}},
                updates_per_1e4_steps=1e4 * self.update_steps / steps if steps else None,
                update_time_ms=float(np.mean(self.update_ms)) if self.update_ms else None,
                memory_mb=self.solver.memory_bytes(self.state) / 1e6,
                peak_rss_mb=peak_rss_mb())
            if self.scheme.name == "aulmpm":
                m.update(epsilon=self.scheme.epsilon, eta=self.scheme.eta, affine=self.scheme.affine)
            m["integrator"] = self.spec.integrator.name
            if self.implicit:
                m["implicit"] = self.implicit_summary()
        if self.built:
            m.update(self.drift.summary())
            if self.solver.removal:  # particles that left through open walls take their mass along
                kept = self.solver.kept if self.solver.kept is not None else slice(None)
                lost = float(self.mass0.sum() - self.mass0[kept].sum())
                m["removed"] = {"total": int(self.solver.removed.sum()), **{b.name: int(c) for b, c in
                                                                zip(self.spec.scene.bodies, self.solver.removed)},
                                "mass": lost}
                if self.drift.first is not None and self.drift.first[0]:
                    m["mass_drift"] = abs(self.drift.last[0] + lost - self.drift.first[0]) / self.drift.first[0]
        if self.detector is not None:
            m["detect"] = self.detector.summary()


def execute(spec: RunSpec, out_dir: Path, config_yaml: str = "", overrides: list[str] = (),
            choices: dict | None = None, sink: Sink | None = None, identity: dict | None = None) -> dict:
    """Run ``spec``; write the recording and ``metrics.json`` into ``out_dir``.

    ``config_yaml``, ``overrides`` and ``choices`` describe how the spec was
    composed; they are stored in the recording with the provenance.
    ``identity`` (e.g. the config hash) goes into metrics.json as given."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    properties = recording_properties(spec, config_yaml, list(overrides), choices)
    if sink is None:
        sink = RerunSink(out_dir / spec.log.recording, spec.log.flush_every)
    run = Run(spec, out_dir, properties, sink)
    run.metrics.update(identity or {})
    # what a run killed without warning leaves (python -m pipelines.replay <dir> --repair marks it killed)
    write_metrics(out_dir / "metrics.json", {**run.metrics, "status": "running",
                                             "reason": "started, not finished"})
    previous_term = previous_int = None
    try:
        previous_term = signal.signal(signal.SIGTERM, run.interrupts.handler)
        previous_int = signal.signal(signal.SIGINT, run.interrupts.handler)
    except ValueError:  # not the main thread
        pass
    try:
        run.build()
        sink.start(run.meta())
        run.loop()
    except KeyboardInterrupt as e:
        run.metrics["status"] = "interrupted"
        what = "SIGTERM" if isinstance(e, _Terminate) else "Ctrl-C"
        run.metrics["reason"] = f"{what} at step {run.step} (t = {run.t:.6g} s)"
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
                sink.close()
                write_metrics(out_dir / "metrics.json", run.metrics)
        finally:
            if old_int is not None:
                signal.signal(signal.SIGINT, old_int)
            if previous_term is not None:
                signal.signal(signal.SIGTERM, previous_term)
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
