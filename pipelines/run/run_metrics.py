"""What a run's ``metrics.json`` summarises besides its steps: conserved
quantities' drift, the plastic fields, the implicit solve, spilled fluid,
the error against a reference run, and the final state kept for later
comparison."""

from __future__ import annotations

import math
import statistics
import sys
from pathlib import Path
from typing import Protocol

import numpy as np

import mpm
from mpm import analytic
from mpm.diagnostics import relative_drift, spilled_fraction


class ClosedForm(Protocol):
    """What the run reads of a scene's closed-form solution (mpm.analytic: VibratingBar, ShearWave, Vortex)."""

    name: str

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray: ...

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray: ...

    def scales(self) -> tuple[float, float]: ...


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
        assert self.first is not None and self.last is not None  # add() sets both
        return relative_drift(self.first[idx], self.last[idx], scale)

    def energy(self, d: np.ndarray) -> float:
        return float(sum(d[self.names.index(k)] for k in ("kinetic_energy", "elastic_energy",
                                                          "potential_energy")))

    def summary(self) -> dict:
        if self.first is None or self.last is None:  # (add() sets both)
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


def energy_change(m: dict) -> dict:
    """metrics.json ``energy_change``: the energy the run lost (< 0) or made beyond the boundaries' work
    (``detect``'s ``boundary_work``), in units of the detection's energy scale, from the metrics ``m``: the
    material's ``energy_initial`` and ``energy_final``, or, where the scene has rigid bodies, the material's
    and the bodies' together (``total_energy_initial``, ``total_energy_final``: pipelines.run.rigid_track;
    the work the bodies did on the material is in the boundaries' work too, which bounds it from above)."""
    d = m["detect"]
    if d["energy_growth_max"] is None or not d["energy_scale"] > 0 or "energy_final" not in m:
        return {}
    pre = "total_" if "total_energy_final" in m else ""
    return {"energy_change": (m[pre + "energy_final"] - m[pre + "energy_initial"] - d["boundary_work"])
                             / d["energy_scale"]}


def peak_rss_mb() -> float | None:
    """The process's peak resident memory [MB] so far (None where the OS does not say)."""
    try:
        import resource
    except ImportError:  # not a Unix
        return None
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1e6 if sys.platform == "darwin" else kb / 1e3  # macOS counts bytes


def median(xs: list[float]) -> float | None:
    return statistics.median(xs) if xs else None


def plastic_fields(model, state) -> dict[str, np.ndarray]:
    """Named per-particle fields of the plastic bodies (mpm.materials.Plastic.fields)
    as the last return mapping left them; NaN on the particles of other bodies."""
    if not model.plastic:
        return {}
    history = state.history.numpy()
    J_E = np.linalg.det(state.Fsn.numpy() @ state.F0s.numpy())
    n = model.n_particles
    out: dict[str, np.ndarray] = {}
    for body, (start, count) in zip(model.scene.bodies, model.body_ranges):
        if body.material.plastic:
            rows = slice(start, start + count)
            for name, values in body.material.fields(history[rows], J_E[rows]).items():
                out.setdefault(name, np.full(n, np.nan, np.float32))[start:start + count] = values
    return out


def particle_fields(model, state, speed: bool = False) -> dict[str, np.ndarray]:
    """The plastic fields (:func:`plastic_fields`) and, with ``speed``, each
    particle's speed |v| [m/s] (float32)."""
    out = plastic_fields(model, state)
    if speed:
        out["speed"] = np.linalg.norm(state.v.numpy().astype(np.float64), axis=1).astype(np.float32)
    return out


def field_range(name: str, log) -> tuple[tuple[float, float] | None, str]:
    """The colour map's (low, high) of the particle field ``name`` and where
    it comes from: ``log.color_range`` for the field that colours the
    particles (``log.color``), else None: the run's own range, found when
    it ends (:mod:`pipelines.recording.colours`)."""
    if name == log.color and log.color_range is not None:
        return (float(log.color_range[0]), float(log.color_range[1])), "log.color_range"
    return None, ""


def color_range(spec) -> tuple[tuple[float, float] | None, str]:
    """:func:`field_range` of ``log.color``."""
    return field_range(spec.log.color, spec.log)


def channel_ranges(log) -> dict:
    """``RunMeta.channels``: :func:`field_range` of each field of
    ``log.channels``."""
    return {name: field_range(name, log) for name in log.channels}


DJ_SINCE = {  # what dJ = |det F^sn - 1| accumulates, per scheme: F^sn maps the last reference configuration
    "empm": "Under EMPM the reference is the last step's configuration: dJ is one step's volume change",
    "tlmpm": "Under TLMPM the reference is the initial configuration: dJ is the volume change since the start",
    "aulmpm": "Under A-ULMPM dJ is the volume change since the body's last configuration update",
}


def field_notes(scheme: str) -> dict:
    """``RunMeta.field_notes``: what to know when reading a coloured field."""
    return {"dJ": DJ_SINCE[scheme]} if scheme in DJ_SINCE else {}


def recording_estimate(spec, model, state, n_scalars: int, dt: float) -> tuple[float, int, int]:
    """Estimated size of the recording [MB], its particle frames and steps,
    from the first step ``dt`` [s] (an adaptive step may shrink later);
    ``n_scalars``: the diagnostics logged per step; each of log.channels
    logs the particles again with their colours."""
    log, (steps_end, duration) = spec.log, spec.end
    steps = steps_end if steps_end is not None else math.ceil(duration / dt)
    t_end = duration if duration is not None else steps * dt
    if not log.particles:
        frames = 0
    elif log.every is not None:
        frames = steps // log.every + 2
    else:
        frames = min(steps, math.ceil(t_end * log.fps)) + 2
    per_particle = 4 * model.dim + 3 + 4 * (log.dJ + len(plastic_fields(model, state)))
    per_particle += len(log.channels) * (4 * model.dim + 4 + 4)  # /channels/<field>: positions, colours, its values
    scalars = 24 * (n_scalars + 12) if log.scalars else 0  # value, step and time per scalar
    return (frames * model.n_particles * per_particle + (steps + 1) * scalars) / 1e6, frames, steps


def plastic_summary(model, state) -> dict:
    """metrics.json ``plastic``: per plastic body, min / mean / max of each field."""
    fields = plastic_fields(model, state)
    out = {}
    for body, (start, count) in zip(model.scene.bodies, model.body_ranges):
        if body.material.plastic:
            rows = {k: v[start:start + count] for k, v in fields.items()}
            out[body.name] = {k: {"min": float(np.min(v)), "mean": float(np.mean(v)), "max": float(np.max(v))}
                              for k, v in rows.items() if np.isfinite(v).all()}
    return out


def implicit_summary(integrator, newton: list[tuple], halvings: int) -> dict:
    """metrics.json ``implicit``: Newton and CG iterations per step (``newton``:
    per step the Newton and CG iterations, the residual, whether the step
    took a near miss, its solves and the contact nodes and bins it left
    unsettled, mpm.implicit); ``near_misses`` counts the near misses,
    ``unsettled_steps`` the steps whose contact rounds ran out (mpm.implicit.solve
    ROUNDS: the last solve kept)."""
    out = {"newton_max": integrator.newton_max, "newton_tol": integrator.newton_tol,
           "newton_accept": integrator.newton_accept, "cg_max": integrator.cg_max, "cg_tol": integrator.cg_tol,
           "halvings": halvings, "near_misses": int(sum(bool(row[3]) for row in newton)),
           "unsettled_steps": int(sum(row[5] > 0 for row in newton))}
    if newton:
        a = np.array(newton, dtype=float)
        out.update(newton_mean=float(a[:, 0].mean()), newton_max_seen=int(a[:, 0].max()),
                   cg_mean=float(a[:, 1].mean()), cg_max_seen=int(a[:, 1].max()),
                   cg_per_newton=float(a[:, 1].sum() / max(a[:, 0].sum(), 1.0)),
                   residual_max=float(a[:, 2].max()), rounds_mean=float(a[:, 4].mean()),
                   rounds_max_seen=int(a[:, 4].max()), unsettled_max=int(a[:, 5].max()))
    return out


def spilled(model, state, X0: np.ndarray) -> dict:
    """Per fluid body and bowl-shaped body, the fraction of the fluid below
    the bowl's rim plane outside it, judged in the bowl's initial shape
    (mpm.diagnostics.spilled_fraction; ``X0`` the initial positions [m])."""
    bodies = model.scene.bodies
    bowls = [(k, b) for k, b in enumerate(bodies) if isinstance(b.shape, mpm.scene.Bowl)]
    fluids = [(i, b) for i, b in enumerate(bodies) if b.material.fluid]
    if not bowls or not fluids:
        return {}
    x, body = state.x.numpy().astype(np.float64), model.body.numpy()
    def spacing(b) -> float:  # the bowl particles' spacing [m]
        return model.dx / max(b.ppc or model.scene.ppc, 1) ** (1.0 / model.dim)

    return {f"{b.name}/{bowl.name}": spilled_fraction(x[body == i], bowl.shape, x[body == k], X0[body == k],
                                                      spacing(bowl))
            for i, b in fluids for k, bowl in bowls}


def reference_errors(path: str, state, X0: np.ndarray, t: float) -> dict:
    """RMS difference of the final positions and velocities to a reference
    run's final state with the same particles (the A-ULMPM paper's eq. 36);
    ``problem`` says why there is none."""
    ref = np.load(path)
    out = {"solution": "reference", "reference": path}
    if ref["X0"].shape != X0.shape or not np.allclose(ref["X0"], X0, rtol=0, atol=1e-9):
        return {**out, "problem": "the reference has other particles (scene.particle_resolution "
                                  "fixes the particle set across grids)"}
    if abs(float(ref["time"]) - t) > 1e-9 * max(1.0, t):
        return {**out, "problem": f"the reference ends at t = {float(ref['time']):.6g} s, this run at {t:.6g} s"}
    x, v = state.x.numpy().astype(np.float64), state.v.numpy().astype(np.float64)
    return {"displacement": analytic.rms(x, ref["x"].astype(np.float64)),
            "velocity": analytic.rms(v, ref["v"].astype(np.float64)), **out}


def save_final_state(path: Path, model, state, X0: np.ndarray, step: int, t: float) -> None:
    """``final_state.npz``: positions x, velocities v, initial positions X0
    and masses of the last state (self-convergence and trade-off studies
    compare these)."""
    np.savez(path, x=state.x.numpy(), v=state.v.numpy(), X0=X0, mass=model.mass.numpy(),
             body=model.body.numpy(), step=step, time=t)
