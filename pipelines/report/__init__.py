"""Summarise a Hydra multirun sweep: CSV tables, PNG plots and one ``report.md``.

    python -m pipelines.report <sweep dir> [--out DIR]

Every job directory below the sweep dir (any depth, found by its
``metrics.json``) is read together with ``.hydra/config.yaml``,
``.hydra/overrides.yaml`` and, when present, ``final_state.npz`` and
``recording.rrd``. Jobs with the same ``config_hash`` are merged (a completed
one is kept). The report has one section per analysis, each written only when
the sweep holds the data for it:

runs.csv            one row per job: method, size, status, timings, errors, drifts
error_vs_time.png   error against run time with the Pareto front (pareto.csv)
convergence.png     error against grid spacing with fitted orders (convergence.csv)
update_cost.csv     configuration-update frequency and cost, EMPM/A-ULMPM reduction
speed.csv/.png      ms per step and particle-steps per second, kernel cost ratios
conservation.png    momentum and angular-momentum drift over time (conservation.csv)
fracture.csv/.png   fraction of neighbouring particle pairs torn apart, fragments

A job's error is its analytic error (from ``metrics.json``) when the scene has
an analytic solution, otherwise its self-convergence error against the finest
job of the same scene and method that shares its particle set:
E = sqrt(sum_p |phi_p - phi_ref,p|^2 / n_p) for positions [m] and velocities [m/s].

:class:`ReportCallback` writes the report at the end of a multirun when listed
under ``hydra.callbacks``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mpm import analytic
from mpm.diagnostics import relative_drift
from hydra.experimental.callback import Callback

MAX_RECORDINGS = 40  # recordings read for the conservation plot
MAX_TABLE_ROWS = 60  # rows of a markdown table before it is cut short
DRIFT_FLOOR = 1e-17  # smallest drift drawn on the log axis

LABEL_KEYS = ("scheme", "kernel", "transfer")
# overrides already part of a label or a column of their own
COVERED_KEYS = {"scheme", "scheme.name", "kernel", "kernel.name", "kernel.transfer", "scene",
                "scene.name", "integrator", "integrator.name"}
RESOLUTION_KEYS = {"scene.resolution", "scene.particle_resolution"}


# ----------------------------------------------------------------- small helpers
def _num(value) -> float | None:
    """``value`` as a float, None if it is missing or not a number."""
    if isinstance(value, bool) or value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _total(value) -> float | None:
    """The "total" entry of a per-body dict (or the value itself if a number)."""
    if isinstance(value, dict):
        return _num(value.get("total"))
    return _num(value)


def _int(value) -> int | None:
    """A count as an int, None if missing."""
    v = _num(value)
    return None if v is None or not math.isfinite(v) else int(round(v))


def _positive(value: float | None) -> bool:
    return value is not None and math.isfinite(value) and value > 0


def _natural_key(text: str) -> list:
    """Sort key that orders "2" before "10"."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


def _fmt(value, digits: int = 4) -> str:
    """A table cell: numbers to ``digits`` significant digits, None as empty."""
    if value is None:
        return ""
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        return f"{value:.{digits}g}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def _md_table(headers: list[str], rows: list[list]) -> list[str]:
    """Markdown table lines, cut short after MAX_TABLE_ROWS rows."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(_fmt(c) for c in row) + " |" for row in rows[:MAX_TABLE_ROWS]]
    if len(rows) > MAX_TABLE_ROWS:
        lines.append(f"\n({len(rows) - MAX_TABLE_ROWS} more rows in the CSV file)")
    return lines + [""]


def _write_csv(path: Path, headers: list[str], rows: list[list]) -> None:
    """CSV with full-precision numbers; None as an empty cell."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(headers)
        for row in rows:
            w.writerow(["" if c is None else repr(c) if isinstance(c, float) else c for c in row])


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _style(labels: list[str]) -> dict[str, tuple]:
    """A (colour, marker) per label, the same in every figure."""
    markers = "osD^v<>ph*X"
    colours = [f"C{i}" for i in range(10)]
    return {lab: (colours[i % 10], markers[(i // 10 + i) % len(markers)]) for i, lab in enumerate(labels)}


def _image(lines: list[str], name: str, caption: str) -> None:
    lines += [f"![{caption}]({name})", ""]


def _absent(title: str, why: str) -> list[str]:
    return [f"## {title}", "", f"Not available: {why}.", ""]


# ---------------------------------------------------------------------- jobs
def _load_yaml(path: Path):
    """A YAML file as plain containers, interpolations left unresolved; None if unreadable."""
    if not path.is_file():
        return None
    try:
        from omegaconf import OmegaConf

        return OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    except Exception:
        try:
            import yaml

            return yaml.safe_load(path.read_text())
        except Exception:
            return None


def parse_overrides(items) -> dict[str, str]:
    """Hydra override strings ("+scene.resolution=32") as {key: value}; the
    "+", "++" and "~" prefixes are dropped."""
    out = {}
    for item in items or []:
        key, sep, value = str(item).partition("=")
        key = key.lstrip("+~").strip()
        if key:
            out[key] = value.strip() if sep else ""
    return out


def _config_value(config, *path):
    """A value of the composed config, None if missing or an unresolved interpolation."""
    node = config
    for key in path:
        if not isinstance(node, dict) or key not in node:
            return None
        node = node[key]
    if isinstance(node, str) and "${" in node:
        return None
    return node


@dataclass
class Job:
    """One job of the sweep with the quantities the report derives from it."""

    path: Path  # job directory
    rel: str  # job directory relative to the sweep dir
    metrics: dict
    overrides: dict[str, str] = field(default_factory=dict)
    config: dict | None = None
    label: str = ""
    extras: dict[str, str] = field(default_factory=dict)  # varying overrides in the label
    error_displacement: float | None = None  # [m]
    error_velocity: float | None = None  # [m/s]
    error_kind: str = ""  # "analytic" | "self" | ""
    error_ref: str = ""  # reference job (self-convergence)
    _state: dict | None = field(default=None, repr=False)

    def _pick(self, key: str, *config_path: str, override: str | None = None):
        value = self.metrics.get(key)
        if value is None and config_path:
            value = _config_value(self.config, *config_path)
        if value is None and override is not None:
            value = self.overrides.get(override)
        return value

    @property
    def status(self) -> str:
        return str(self.metrics.get("status") or "unknown")

    @property
    def completed(self) -> bool:
        return self.status == "completed"

    @property
    def scene(self) -> str:
        return str(self._pick("scene", "scene", "name", override="scene") or "")

    @property
    def scheme(self) -> str:
        return str(self._pick("scheme", "scheme", "name", override="scheme") or "")

    @property
    def kernel(self) -> str:
        return str(self._pick("kernel", "kernel", "name", override="kernel") or "")

    @property
    def transfer(self) -> str:
        return str(self._pick("transfer", "kernel", "transfer", override="kernel.transfer") or "")

    @property
    def integrator(self) -> str:
        return str(self._pick("integrator", "integrator", "name", override="integrator") or "explicit")

    @property
    def resolution(self) -> int | None:
        """Grid cells along x."""
        r = _num(self._pick("resolution", "scene", "resolution", override="scene.resolution"))
        return None if r is None else int(r)

    @property
    def dx(self) -> float | None:
        """Grid spacing [m]."""
        dx = _num(self.metrics.get("dx"))
        if dx is None:
            domain = _config_value(self.config, "scene", "domain")
            width = _num(domain[0]) if isinstance(domain, list) and domain else None
            if width is not None and self.resolution:
                dx = width / self.resolution
        return dx

    def num(self, key: str) -> float | None:
        """A numeric metric (a per-body dict gives its total)."""
        return _total(self.metrics.get(key))

    def data_file(self, name: str) -> Path | None:
        """``name`` in the job dir, or in the dir of the job it reused."""
        candidates = [self.path / name]
        skipped = self.metrics.get("skipped")
        if skipped:
            s = Path(str(skipped))
            candidates += [s / name] if s.is_absolute() else [
                self.path / s / name, self.path.parent / s / name, Path.cwd() / s / name]
        return next((p for p in candidates if p.is_file()), None)

    def final_state(self) -> dict | None:
        """Arrays x [m], v [m/s], X0 [m] (and mass [kg], None in older files) of
        final_state.npz, None if absent or unreadable."""
        if self._state is None:
            path = self.data_file("final_state.npz")
            state: dict = {}
            if path is not None:
                try:
                    with np.load(path, allow_pickle=False) as npz:
                        if all(k in npz for k in ("x", "v", "X0")):
                            state = {k: np.asarray(npz[k], dtype=np.float64) for k in ("x", "v", "X0")}
                            state["time"] = float(npz["time"]) if "time" in npz else None
                            state["mass"] = np.asarray(npz["mass"], dtype=np.float64) if "mass" in npz else None
                except Exception:
                    state = {}
            self._state = state
        return self._state or None


def _read_job(path: Path, sweep_dir: Path) -> Job | None:
    try:
        metrics = json.loads((path / "metrics.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(metrics, dict):
        return None
    overrides = _load_yaml(path / ".hydra" / "overrides.yaml")
    config = _load_yaml(path / ".hydra" / "config.yaml")
    try:
        rel = path.relative_to(sweep_dir).as_posix() or "."
    except ValueError:
        rel = str(path)
    return Job(path, rel, metrics, parse_overrides(overrides if isinstance(overrides, list) else []),
               config if isinstance(config, dict) else None)


def load_jobs(sweep_dir: Path) -> tuple[list[Job], int]:
    """The jobs below ``sweep_dir``, one per config_hash (a completed one
    preferred, then one that ran rather than reused a result), and the number
    of duplicates merged."""
    sweep_dir = Path(sweep_dir)
    jobs = [j for p in sorted(sweep_dir.rglob("metrics.json"), key=lambda p: _natural_key(str(p)))
            if (j := _read_job(p.parent, sweep_dir)) is not None]
    by_hash: dict[str, list[Job]] = defaultdict(list)
    for j in jobs:
        by_hash[str(j.metrics.get("config_hash") or f"dir:{j.rel}")].append(j)
    kept = [min(group, key=lambda j: (not j.completed, bool(j.metrics.get("skipped")), _natural_key(j.rel)))
            for group in by_hash.values()]
    kept.sort(key=lambda j: _natural_key(j.rel))
    return kept, len(jobs) - len(kept)


def assign_labels(jobs: list[Job]) -> None:
    """Label each job "scheme · kernel · transfer" (and "implicit" for the
    implicit integrator) plus every override whose
    value varies across the sweep (resolutions, run.force, log.* and hydra* aside:
    a sweep over run.dt or run.precision compares different methods)."""
    values: dict[str, set] = defaultdict(set)
    keys = {k for j in jobs for k in j.overrides}
    for key in keys:
        if key in COVERED_KEYS or key in RESOLUTION_KEYS or key.startswith(("log.", "hydra")) \
                or key in ("run", "log", "run.force"):
            continue
        for j in jobs:
            values[key].add(j.overrides.get(key))
    varying = sorted(k for k, v in values.items() if len(v) > 1)
    for j in jobs:
        j.extras = {k: j.overrides[k] for k in varying if k in j.overrides}
        parts = [p for p in (j.scheme, j.kernel, j.transfer) if p]
        parts += ["implicit"] if j.integrator == "implicit" else []
        parts += [f"{k}={v}" for k, v in j.extras.items()]
        j.label = " · ".join(parts) or "(unknown)"


def _extras_without(job: Job, prefix: str) -> tuple:
    return tuple(sorted((k, v) for k, v in job.extras.items() if not k.startswith(prefix)))


# -------------------------------------------------------------------- errors
def fit_slope(h, e) -> tuple[float, float]:
    """Least-squares line log10(e) = slope * log10(h) + intercept over the
    points with h > 0 and e > 0; returns (slope, intercept). Raises ValueError
    with fewer than two distinct h."""
    h, e = np.asarray(h, dtype=np.float64), np.asarray(e, dtype=np.float64)
    ok = np.isfinite(h) & np.isfinite(e) & (h > 0) & (e > 0)
    if np.unique(h[ok]).size < 2:
        raise ValueError("a slope needs errors at two or more distinct spacings")
    slope, intercept = np.polyfit(np.log10(h[ok]), np.log10(e[ok]), 1)
    return float(slope), float(intercept)


def pareto_front(times, errors) -> np.ndarray:
    """Boolean mask of the points no other point dominates, i.e. none is at
    least as fast and as accurate and strictly better in one; non-finite
    points are never on the front."""
    t, e = np.asarray(times, dtype=np.float64), np.asarray(errors, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(e)
    front = np.zeros(t.shape, dtype=bool)
    for i in np.flatnonzero(ok):
        dominated = ok & (t <= t[i]) & (e <= e[i]) & ((t < t[i]) | (e < e[i]))
        front[i] = not dominated.any()
    return front


def _same_particles(a: np.ndarray, b: np.ndarray) -> bool:
    """Same shape and values within 1e-12 relative to the largest coordinate."""
    if a.shape != b.shape:
        return False
    scale = float(np.max(np.abs(b))) if b.size else 0.0
    return bool(np.all(np.abs(a - b) <= 1e-12 * max(scale, np.finfo(float).tiny)))


def assign_errors(jobs: list[Job]) -> None:
    """Analytic errors from metrics.json; for the other completed jobs with a
    final state, the self-convergence error against the finest job of the
    same (scene, label) with the same initial particles."""
    for j in jobs:
        err = j.metrics.get("error")
        if isinstance(err, dict):
            d, v = _num(err.get("displacement")), _num(err.get("velocity"))
            if d is not None or v is not None:
                kind = "reference" if err.get("solution") == "reference" else "analytic"
                j.error_displacement, j.error_velocity, j.error_kind = d, v, kind
    groups: dict[tuple, list[Job]] = defaultdict(list)
    for j in jobs:
        if not j.error_kind and j.resolution is not None:
            groups[(j.scene, j.label)].append(j)
    for members in groups.values():
        # the reference is the finest grid of the method; if that run did not
        # complete (or left no final state), the method has no self error
        ref = max(members, key=lambda j: j.resolution)
        rs = ref.final_state() if ref.completed else None
        if rs is None:
            continue
        for j in members:
            s = j.final_state() if j.completed else None
            if s is None or j.resolution == ref.resolution or not _same_particles(s["X0"], rs["X0"]):
                continue
            if s["x"].shape != rs["x"].shape or s["v"].shape != rs["v"].shape:
                continue
            if s["time"] is not None and rs["time"] is not None and \
                    abs(s["time"] - rs["time"]) > 1e-9 * max(1.0, abs(rs["time"])):
                continue  # not the same instant
            j.error_displacement = analytic.rms(s["x"], rs["x"])
            j.error_velocity = analytic.rms(s["v"], rs["v"])
            j.error_kind, j.error_ref = "self", ref.rel


def _errors(j: Job, quantity: str) -> float | None:
    return j.error_displacement if quantity == "displacement" else j.error_velocity


def _run_time(j: Job) -> float | None:
    """Wall seconds spent stepping (compile and logging excluded)."""
    return j.num("loop_time_s")


# ------------------------------------------------------------------ sections
RUN_COLUMNS = ["dir", "label", "scene", "scheme", "kernel", "transfer", "integrator", "resolution", "dx", "particles",
               "status", "reason", "steps", "sim_time", "step_time_ms", "particle_steps_per_s",
               "loop_time_s", "wall_time_s", "compile_time_s", "error_kind", "error_reference",
               "error_displacement", "error_velocity", "updates_per_1e4_steps", "update_time_ms",
               "config_updates", "fracture", "fragments", "mass_drift", "momentum_drift",
               "angular_momentum_drift", "config_hash", "skipped"]


def section_runs(jobs: list[Job], out: Path, duplicates: int) -> list[str]:
    """runs.csv (every job) and the list of jobs that did not complete."""
    rows = []
    for j in jobs:
        m = j.metrics
        rows.append([j.rel, j.label, j.scene, j.scheme, j.kernel, j.transfer, j.integrator, j.resolution, j.dx,
                     _int(j.num("particles")), j.status, m.get("reason") or "", _int(j.num("steps")),
                     j.num("sim_time"),
                     j.num("step_time_ms"), j.num("particle_steps_per_s"), j.num("loop_time_s"),
                     j.num("wall_time_s"), j.num("compile_time_s"), j.error_kind, j.error_ref,
                     j.error_displacement, j.error_velocity, j.num("updates_per_1e4_steps"),
                     j.num("update_time_ms"), _int(j.num("config_updates")), j.num("fracture"),
                     _int(j.num("fragments")), j.num("mass_drift"), j.num("momentum_drift"),
                     j.num("angular_momentum_drift"), m.get("config_hash") or "", m.get("skipped") or ""])
    _write_csv(out / "runs.csv", RUN_COLUMNS, rows)
    counts = Counter(j.status for j in jobs)
    lines = ["## Runs", "",
             f"{len(jobs)} jobs ({', '.join(f'{n} {s}' for s, n in sorted(counts.items()))})"
             + (f"; {duplicates} duplicate(s) of an identical configuration merged" if duplicates else "")
             + ". One row per job in [runs.csv](runs.csv); run time is the wall time spent stepping "
               "(compile and logging excluded).", ""]
    lines += _md_table(["dir", "scene", "label", "cells", "particles", "status", "steps", "ms/step",
                        "run time [s]"],
                       [[j.rel, j.scene, j.label, j.resolution, _int(j.num("particles")), j.status,
                         _int(j.num("steps")), j.num("step_time_ms"), j.num("loop_time_s")] for j in jobs])
    bad = [j for j in jobs if j.status != "completed"]
    if bad:
        lines += ["Jobs that did not complete:", ""]
        lines += _md_table(["dir", "label", "cells", "status", "reason"],
                           [[j.rel, j.label, j.resolution, j.status, j.metrics.get("reason") or ""]
                            for j in bad])
    else:
        lines += ["All jobs completed.", ""]
    return lines


def section_errors(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """error_vs_time.png and pareto.csv: error against run time, Pareto front per scene."""
    title = "Error against run time"
    have = [j for j in jobs if j.completed and _positive(_run_time(j))
            and (_positive(j.error_displacement) or _positive(j.error_velocity))]
    if not have:
        why = ("no completed job has both a run time and an error: analytic errors need a scene with an "
               "analytic solution, self-convergence errors a final_state.npz with the same initial "
               "particles (X0) as the finest job of the method, e.g. a fixed scene.particle_resolution")
        return _absent(title, why)
    kinds = Counter(j.error_kind for j in have)
    lines = [f"## {title}", "",
             "Displacement error [m] (left) and velocity error [m/s] (right) at the end of the run "
             "against the wall time spent stepping [s], log-log; points of one method are joined in "
             "order of resolution, the dashed step line is the Pareto front (no other job is both "
             "faster and more accurate). Errors: "
             + ", ".join(f"{n} {'analytic' if k == 'analytic' else 'self-convergence'}"
                         for k, n in sorted(kinds.items()))
             + " (self-convergence: RMS difference to the finest job of the same method, "
               "reference in [runs.csv](runs.csv)).", ""]
    plt = _pyplot()
    scenes = sorted({j.scene for j in have})
    quantities = ("displacement", "velocity")
    fig, axes = plt.subplots(len(scenes), 2, figsize=(11, 4.2 * len(scenes)), squeeze=False)
    pareto_rows = []
    for r, scene in enumerate(scenes):
        members = [j for j in have if j.scene == scene]
        for c, q in enumerate(quantities):
            ax = axes[r][c]
            pts = [j for j in members if _positive(_errors(j, q))]
            for label in sorted({j.label for j in pts}):
                js = sorted((j for j in pts if j.label == label), key=lambda j: j.resolution or 0)
                colour, marker = style[label]
                ax.plot([_run_time(j) for j in js], [_errors(j, q) for j in js], marker=marker,
                        color=colour, label=label)
            if pts:
                t = np.array([_run_time(j) for j in pts])
                e = np.array([_errors(j, q) for j in pts])
                front = pareto_front(t, e)
                order = np.argsort(t[front])
                ax.plot(t[front][order], e[front][order], "k--", drawstyle="steps-post", lw=1,
                        label="Pareto front")
                for i in np.flatnonzero(front)[order]:
                    j = pts[i]
                    pareto_rows.append([scene, q, j.rel, j.label, j.resolution, _run_time(j), e[i],
                                        j.error_kind])
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("run time [s]")
            ax.set_ylabel(f"{q} error [{'m' if q == 'displacement' else 'm/s'}]")
            ax.set_title(f"{scene}: {q}")
            ax.grid(True, which="both", alpha=0.3)
            if pts:
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "error_vs_time.png", dpi=120)
    plt.close(fig)
    _write_csv(out / "pareto.csv", ["scene", "quantity", "dir", "label", "resolution", "loop_time_s",
                                    "error", "error_kind"], pareto_rows)
    _image(lines, "error_vs_time.png", "error against run time")
    lines += ["Errors of the completed jobs:", ""]
    lines += _md_table(["dir", "scene", "label", "cells", "kind", "run time [s]", "displacement [m]",
                        "velocity [m/s]"],
                       [[j.rel, j.scene, j.label, j.resolution, j.error_kind, _run_time(j),
                         j.error_displacement, j.error_velocity] for j in have])
    lines += ["Pareto front ([pareto.csv](pareto.csv)), fastest first:", ""]
    lines += _md_table(["scene", "error", "dir", "label", "cells", "run time [s]", "error value"],
                       [[r[0], r[1], r[2], r[3], r[4], r[5], r[6]] for r in pareto_rows])
    return lines


def section_convergence(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """convergence.png and convergence.csv: error against dx with fitted orders."""
    title = "Convergence"
    have = [j for j in jobs if j.completed and _positive(j.dx)
            and (_positive(j.error_displacement) or _positive(j.error_velocity))]
    if not have:
        return _absent(title, "no completed job has an error and a grid spacing (see the section above)")
    groups: dict[tuple, list[Job]] = defaultdict(list)
    for j in have:
        groups[(j.scene, j.label)].append(j)
    quantities = ("displacement", "velocity")
    fits: dict[tuple, dict] = {}
    rows = []
    for key, members in sorted(groups.items()):
        row = [key[0], key[1], "/".join(sorted({j.error_kind for j in members}))]
        for q in quantities:
            pts = [(j.dx, _errors(j, q)) for j in members if _positive(_errors(j, q))]
            h, e = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
            try:
                slope, intercept = fit_slope(h, e)
                fits[(key, q)] = {"h": h, "slope": slope, "intercept": intercept}
            except ValueError:
                slope = intercept = None
            row += [len(pts), slope, intercept]
        rows.append(row)
    _write_csv(out / "convergence.csv",
               ["scene", "label", "error_kind", "n_displacement", "slope_displacement",
                "intercept_displacement", "n_velocity", "slope_velocity", "intercept_velocity"], rows)
    if not fits:
        lines = _absent(title, "no method has errors at two or more grid spacings")
        lines.insert(-1, "The points are in [convergence.csv](convergence.csv).")
        return lines
    plt = _pyplot()
    scenes = sorted({k[0] for k in groups})
    fig, axes = plt.subplots(len(scenes), 2, figsize=(11, 4.2 * len(scenes)), squeeze=False)
    for r, scene in enumerate(scenes):
        for c, q in enumerate(quantities):
            ax = axes[r][c]
            for (sc, label), members in sorted(groups.items()):
                if sc != scene:
                    continue
                js = sorted((j for j in members if _positive(_errors(j, q))), key=lambda j: j.dx)
                if not js:
                    continue
                colour, marker = style[label]
                fit = fits.get(((sc, label), q))
                name = label if fit is None else f"{label} (order {fit['slope']:.2f})"
                ax.plot([j.dx for j in js], [_errors(j, q) for j in js], marker, color=colour, label=name)
                if fit is not None:
                    h = np.geomspace(fit["h"].min(), fit["h"].max(), 20)
                    ax.plot(h, 10 ** fit["intercept"] * h ** fit["slope"], "-", color=colour, lw=1)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("dx [m]")
            ax.set_ylabel(f"{q} error [{'m' if q == 'displacement' else 'm/s'}]")
            ax.set_title(f"{scene}: {q}")
            ax.grid(True, which="both", alpha=0.3)
            if ax.lines:
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "convergence.png", dpi=120)
    plt.close(fig)
    lines = [f"## {title}", "",
             "Displacement and velocity errors against the grid spacing dx [m], log-log, per method "
             "with the least-squares line through log10(error) against log10(dx); its slope is the "
             "observed order of convergence ([convergence.csv](convergence.csv)).", ""]
    _image(lines, "convergence.png", "error against grid spacing")
    lines += _md_table(["scene", "label", "error", "points", "order (displacement)", "order (velocity)"],
                       [[r[0], r[1], r[2], max(r[3], r[6]), r[4], r[7]] for r in rows])
    return lines


def section_update_cost(jobs: list[Job], out: Path) -> list[str]:
    """update_cost.csv: configuration updates per 1e4 steps, their mean cost
    [ms], and the EMPM/A-ULMPM cost ratio at equal scene, kernel, transfer and resolution."""
    title = "Configuration-update cost"
    have = [j for j in jobs if j.completed and (j.num("update_time_ms") is not None
                                                or j.num("updates_per_1e4_steps") is not None)]
    if not have:
        return _absent(title, "no completed job reports configuration updates")

    def match_key(j: Job) -> tuple:
        return (j.scene, j.kernel, j.transfer, j.resolution, _extras_without(j, "scheme"))

    empm = {}
    for j in have:
        if j.scheme == "empm" and _positive(j.num("update_time_ms")):
            empm.setdefault(match_key(j), j)
    rows, pairs = [], []
    for j in sorted(have, key=lambda j: (j.scene, j.label, j.resolution or 0)):
        reduction, partner = None, None
        e = empm.get(match_key(j))
        if j.scheme == "aulmpm" and e is not None and _positive(j.num("update_time_ms")):
            partner = e
            reduction = e.num("update_time_ms") / j.num("update_time_ms")
            pairs.append([j.scene, j.kernel, j.transfer, j.resolution, e.label, j.label,
                          e.num("update_time_ms"), j.num("update_time_ms"), reduction])
        rows.append([j.scene, j.label, j.scheme, j.kernel, j.transfer, j.resolution, j.rel,
                     j.num("updates_per_1e4_steps"), j.num("update_time_ms"), _int(j.num("config_updates")),
                     reduction, partner.rel if partner else ""])
    _write_csv(out / "update_cost.csv",
               ["scene", "label", "scheme", "kernel", "transfer", "resolution", "dir",
                "updates_per_1e4_steps", "update_time_ms", "config_updates", "reduction", "reduction_vs"],
               rows)
    lines = [f"## {title}", "",
             "Configuration updates per 10^4 steps and the mean wall time [ms] per step spent on them "
             "([update_cost.csv](update_cost.csv)); the reduction is EMPM's update time divided by "
             "A-ULMPM's for the same scene, kernel, transfer and resolution.", ""]
    lines += _md_table(["scene", "label", "cells", "updates / 1e4 steps", "update time [ms]"],
                       [[r[0], r[1], r[5], r[7], r[8]] for r in rows])
    if pairs:
        lines += _md_table(["scene", "kernel", "transfer", "cells", "EMPM", "A-ULMPM", "EMPM [ms]",
                            "A-ULMPM [ms]", "reduction"], pairs)
    else:
        lines += ["No EMPM and A-ULMPM jobs share a scene, kernel, transfer and resolution: "
                  "no reduction ratio.", ""]
    return lines


def _bar_chart(path: Path, groups: list[str], values: dict[tuple[str, str], float], style: dict,
               ylabel: str, log: bool = False) -> None:
    """Bars of ``values[(group, label)]``, one cluster per group, one colour per label."""
    plt = _pyplot()
    labels = sorted({lab for _, lab in values})
    width = 0.8 / max(len(labels), 1)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.2 + len(groups) * len(labels) * 0.35), 4.5))
    for k, label in enumerate(labels):
        xs = [i + (k - (len(labels) - 1) / 2) * width for i, g in enumerate(groups) if (g, label) in values]
        ys = [values[(g, label)] for g in groups if (g, label) in values]
        ax.bar(xs, ys, width=width, color=style[label][0], label=label)
    ax.set_xticks(range(len(groups)))
    tilt = len(groups) > 3
    ax.set_xticklabels(groups, rotation=20 if tilt else 0, ha="right" if tilt else "center")
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _group_name(j: Job) -> str:
    return f"{j.scene} · {j.resolution} cells" if j.resolution is not None else j.scene


def section_speed(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """speed.csv and speed.png: median ms per step and particle-steps per second,
    with each kernel's ms/step relative to the quadratic kernel's."""
    title = "Speed"
    have = [j for j in jobs if j.completed and _positive(j.num("step_time_ms"))]
    if not have:
        return _absent(title, "no completed job reports a step time")

    def kernel_key(j: Job) -> tuple:
        return (j.scene, j.scheme, j.transfer, j.resolution, _extras_without(j, "kernel"))

    quadratic = {}
    for j in have:
        if j.kernel == "quadratic":
            quadratic.setdefault(kernel_key(j), j)
    rows, ratios = [], []
    for j in sorted(have, key=lambda j: (j.scene, j.resolution or 0, j.label)):
        q = quadratic.get(kernel_key(j))
        ratio = None
        if q is not None and q is not j and j.kernel != "quadratic":
            ratio = j.num("step_time_ms") / q.num("step_time_ms")
            ratios.append([j.scene, j.scheme, j.transfer, j.resolution, j.kernel, j.num("step_time_ms"),
                           q.num("step_time_ms"), ratio])
        elif q is j and any(kernel_key(o) == kernel_key(j) and o.kernel != "quadratic" for o in have):
            ratio = 1.0
        rows.append([j.scene, j.label, j.resolution, _int(j.num("particles")), j.rel,
                     j.num("step_time_ms"), j.num("particle_steps_per_s"), ratio])
    _write_csv(out / "speed.csv", ["scene", "label", "resolution", "particles", "dir", "step_time_ms",
                                   "particle_steps_per_s", "ms_per_step_vs_quadratic"], rows)
    groups = sorted({_group_name(j) for j in have}, key=_natural_key)
    values: dict[tuple[str, str], float] = {}
    for j in have:  # the fastest job of a label in a group (repeats, varying extras aside)
        key = (_group_name(j), j.label)
        values[key] = min(values.get(key, math.inf), j.num("step_time_ms"))
    _bar_chart(out / "speed.png", groups, values, style, "median wall time per step [ms]")
    lines = [f"## {title}", "",
             "Median wall time per step [ms] per method, grouped by scene and resolution, and "
             "particle-steps per second ([speed.csv](speed.csv)).", ""]
    _image(lines, "speed.png", "ms per step")
    lines += _md_table(["scene", "label", "cells", "particles", "ms/step", "particle-steps/s"],
                       [[r[0], r[1], r[2], r[3], r[5], r[6]] for r in rows])
    if ratios:
        lines += ["Kernels against the quadratic kernel (same scene, scheme, transfer and resolution):", ""]
        lines += _md_table(["scene", "scheme", "transfer", "cells", "kernel", "ms/step",
                            "quadratic ms/step", "ratio"], ratios)
    return lines


def _time_axis(rec, steps: np.ndarray) -> np.ndarray | None:
    """Simulated time [s] at ``steps``: the scalar rows' times (or a
    sim_time scalar), else interpolated from the particle frames' times; None
    if none covers the steps."""
    for s, t in (rec.clock, rec.scalars.get("sim_time", ((), ()))):
        s = np.asarray(s)
        if len(s) and set(steps.tolist()) <= set(s.tolist()):
            order = np.argsort(s)
            return np.interp(steps, s[order], np.asarray(t)[order])
    fs, ft = np.asarray(rec.steps, dtype=np.float64), np.asarray(rec.times, dtype=np.float64)
    if len(fs) >= 2 and len(steps) and steps.min() >= fs.min() and steps.max() <= fs.max():
        order = np.argsort(fs)
        return np.interp(steps, fs[order], ft[order])
    return None


def drift_series(scalars: dict, prefix: str) -> tuple[np.ndarray, np.ndarray] | None:
    """(steps, |Q(t) - Q(0)| / scale) for Q the vector of scalars named
    ``prefix`` or ``prefix_x/_y/_z``, relative to |Q(0)|, or to the largest
    ``prefix_scale`` seen (the largest |Q| if absent) when |Q(0)| is near zero
    (mpm.diagnostics.relative_drift)."""
    names = [n for n in scalars if (n == prefix or re.fullmatch(prefix + r"_[xyz]", n))]
    if not names:
        return None
    common = None
    for n in names:
        s = scalars[n][0]
        common = s if common is None else np.intersect1d(common, s)
    if common is None or len(common) == 0:
        return None
    common = np.sort(common)
    Q = np.stack([np.interp(common, *scalars[n]) for n in sorted(names)], axis=1)
    scale_series = scalars.get(f"{prefix}_scale")
    scale = float(np.nanmax(scale_series[1])) if scale_series is not None and len(scale_series[1]) else 0.0
    if not scale > 0:
        scale = float(np.nanmax(np.linalg.norm(Q, axis=1)))
    return common, relative_drift(Q[0], Q, scale)


def section_conservation(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """conservation.csv (final drifts from metrics.json) and conservation.png
    (drift over time from the recordings)."""
    title = "Conservation"
    keys = ("mass_drift", "momentum_drift", "angular_momentum_drift")
    have = [j for j in jobs if any(j.num(k) is not None for k in keys)]
    with_rec = [j for j in jobs if j.data_file("recording.rrd") is not None]
    if not have and not with_rec:
        return _absent(title, "no job reports drifts or has a recording")
    lines = [f"## {title}", ""]
    if have:
        rows = [[j.rel, j.scene, j.label, j.resolution, j.status] + [j.num(k) for k in keys]
                + [j.num("energy_initial"), j.num("energy_final")] for j in have]
        _write_csv(out / "conservation.csv", ["dir", "scene", "label", "resolution", "status"] + list(keys)
                   + ["energy_initial", "energy_final"], rows)
        lines += ["Relative drifts between the first and the last measurement: mass, linear momentum "
                  "and angular momentum about the centre of mass, against the first value (against the "
                  "quantity's scale where it starts near zero) ([conservation.csv](conservation.csv)).", ""]
        lines += _md_table(["dir", "scene", "label", "cells", "status", "mass", "momentum",
                            "angular momentum"], [r[:8] for r in rows])
    if not with_rec:
        lines += ["No recording.rrd in the job directories: no drift over time.", ""]
        return lines
    read_list = with_rec[:MAX_RECORDINGS]
    series, failed = [], []
    from ..recording.recordings import read

    for j in read_list:
        try:
            rec = read(j.data_file("recording.rrd"), particles=False)  # scalars only: frames can be GBs
        except Exception as exc:
            failed.append(f"{j.rel} ({type(exc).__name__})")
            continue
        p = drift_series(rec.scalars, "momentum")
        L = drift_series(rec.scalars, "angular_momentum")
        if p is None and L is None:
            failed.append(f"{j.rel} (no momentum scalars)")
            continue
        series.append((j, rec, p, L))
    if series:
        use_time = all(_time_axis(rec, s[0]) is not None
                       for _, rec, p, L in series for s in (p, L) if s is not None)
        plt = _pyplot()
        scenes = sorted({item[0].scene for item in series}, key=_natural_key)
        fig, axes = plt.subplots(len(scenes), 2, figsize=(12, 4.5 * len(scenes)), squeeze=False)
        for r, scene in enumerate(scenes):
            for c, (name, idx) in enumerate((("linear momentum", 2), ("angular momentum", 3))):
                ax = axes[r][c]
                for item in series:
                    j, rec, s = item[0], item[1], item[idx]
                    if s is None or j.scene != scene:
                        continue
                    x = _time_axis(rec, s[0]) if use_time else s[0]
                    colour = style[j.label][0]
                    ax.plot(x, np.maximum(s[1], DRIFT_FLOOR), color=colour, lw=1,
                            label=f"{j.label} · {j.resolution}" if j.resolution else j.label)
                ax.set_yscale("log")
                ax.set_xlabel("time [s]" if use_time else "step")
                ax.set_ylabel(f"relative {name} drift")
                ax.set_title(f"{scene}: {name}")
                ax.grid(True, which="both", alpha=0.3)
                if ax.lines and len(ax.lines) <= 20:
                    ax.legend(fontsize=6)
        fig.tight_layout()
        fig.savefig(out / "conservation.png", dpi=120)
        plt.close(fig)
        lines += [f"Relative drift over {'time [s]' if use_time else 'steps'} read from {len(series)} "
                  "recording(s): |Q(t) - Q(0)| / |Q(0)| for the linear momentum P and the angular momentum L "
                  "about the centre of mass (against the quantity's scale where Q(0) is near zero: "
                  f"two spheres colliding head-on), log scale floored at {DRIFT_FLOOR:g}; colours by method, one line per job.", ""]
        _image(lines, "conservation.png", "momentum drift over time")
    if len(with_rec) > MAX_RECORDINGS:
        lines += [f"Only the first {MAX_RECORDINGS} of {len(with_rec)} recordings were read.", ""]
    if failed:
        lines += ["Recordings not plotted: " + ", ".join(failed) + ".", ""]
    return lines


def section_fracture(jobs: list[Job], out: Path, style: dict) -> list[str]:
    """fracture.csv and fracture.png: fraction of initially neighbouring particle
    pairs torn apart, and the number of fragments, per method."""
    title = "Numerical fracture"
    have = [j for j in jobs if j.completed and j.num("fracture") is not None]
    if not have:
        return _absent(title, "no completed job reports fracture")
    rows = []
    for j in sorted(have, key=lambda j: (j.scene, j.resolution or 0, j.label)):
        rows.append([j.scene, j.label, j.resolution, j.rel, j.num("fracture"), _int(j.num("fragments"))])
    _write_csv(out / "fracture.csv", ["scene", "label", "resolution", "dir", "fracture", "fragments"], rows)
    groups = sorted({_group_name(j) for j in have}, key=_natural_key)
    values: dict[tuple[str, str], float] = {}
    for j in have:
        key = (_group_name(j), j.label)
        values[key] = max(values.get(key, 0.0), j.num("fracture"))
    _bar_chart(out / "fracture.png", groups, values, style, "fraction of neighbour pairs torn apart")
    lines = [f"## {title}", "",
             "Fraction of initially neighbouring particle pairs torn apart at the end of the run, per "
             "method, grouped by scene and resolution, and the number of fragments "
             "([fracture.csv](fracture.csv)).", ""]
    _image(lines, "fracture.png", "numerical fracture")
    lines += _md_table(["scene", "label", "cells", "fracture", "fragments"],
                       [[r[0], r[1], r[2], r[4], r[5]] for r in rows])
    return lines


def section_spilled(jobs: list[Job], out: Path) -> list[str]:
    """spilled.csv: the fraction of a fluid below a bowl's rim plane outside it (the leaking bowl)."""
    have = [j for j in jobs if j.completed and j.metrics.get("spilled")]
    if not have:
        return []
    rows = [[j.scene, j.label, j.resolution, j.rel, name, frac, (j.metrics.get("fragments") or {}).get(
        name.split("/")[1])] for j in sorted(have, key=lambda j: (j.scene, j.resolution or 0, j.label))
        for name, frac in j.metrics["spilled"].items()]
    _write_csv(out / "spilled.csv", ["scene", "label", "resolution", "dir", "fluid/bowl", "spilled",
                                     "bowl_fragments"], rows)
    return ["## Leaks", "",
            "Fraction of each fluid's particles that end below a bowl's rim plane and outside it, and "
            "the bowl's pieces at the end ([spilled.csv](spilled.csv)).", "",
            *_md_table(["scene", "label", "cells", "fluid / bowl", "spilled", "bowl fragments"],
                       [[r[0], r[1], r[2], r[4], r[5], r[6]] for r in rows])]


# -------------------------------------------------------------------- report
def write_report(sweep_dir: Path, out: Path | None = None) -> Path:
    """Read the jobs of ``sweep_dir`` and write the tables, plots and report.md
    into ``out`` (default: the sweep dir); returns the path of report.md."""
    sweep_dir = Path(sweep_dir)
    out = Path(out) if out is not None else sweep_dir
    out.mkdir(parents=True, exist_ok=True)
    from ..sweeps.stability import section_extreme, section_stability, write_stability_md
    from .sections.dam_break import section_dam_break
    from .sections.granular import section_granular, section_plastic  # experiment families of their own
    from .sections.integration import section_integration
    from .sections.paper_tables import section_table3, section_table4
    from .sections.tradeoff import section_tradeoff

    jobs, duplicates = load_jobs(sweep_dir)
    lines = ["# Sweep report", "", f"Sweep: `{sweep_dir}`", ""]
    if not jobs:
        lines += ["No job found (no metrics.json below the sweep directory).", ""]
    else:
        assign_labels(jobs)
        assign_errors(jobs)
        style = _style(sorted({j.label for j in jobs}))
        lines += section_runs(jobs, out, duplicates)
        lines += section_errors(jobs, out, style)
        lines += section_convergence(jobs, out, style)
        lines += section_update_cost(jobs, out)
        lines += section_speed(jobs, out, style)
        lines += section_conservation(jobs, out, style)
        lines += section_fracture(jobs, out, style)
        lines += section_granular(jobs, out)
        lines += section_plastic(jobs, out)
        lines += section_tradeoff(jobs, out)
        lines += section_table3(jobs, out)
        lines += section_table4(jobs, out)
        lines += section_spilled(jobs, out)
        lines += section_dam_break(jobs, out)
        lines += section_integration(jobs, out)
        maps, extreme = section_stability(jobs, out), section_extreme(jobs, out)
        write_stability_md(out, maps, extreme)
        lines += maps + extreme
    path = out / "report.md"
    path.write_text("\n".join(lines).rstrip() + "\n")
    return path


class ReportCallback(Callback):
    """Hydra callback writing the sweep report at the end of a multirun::

        hydra:
          callbacks:
            report:
              _target_: pipelines.report.ReportCallback
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


SWEEPS: list[dict[str, int]] = []  # per multirun of this process: jobs per status (pipelines.run's exit code)


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipelines.report", description=__doc__.split("\n")[0])
    parser.add_argument("sweep_dir", type=Path, help="multirun sweep directory")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default: the sweep dir)")
    args = parser.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"error: {args.sweep_dir}: no such directory", file=sys.stderr)
        return 2
    print(write_report(args.sweep_dir, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
