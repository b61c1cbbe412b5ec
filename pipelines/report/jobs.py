"""The jobs of a sweep as the report reads them: one :class:`Job` per job
directory (its metrics, overrides and composed config), merged by config
hash (:func:`load_jobs`), labelled by method (:func:`assign_labels`) and
given an error (:func:`assign_errors`): the analytic error from
``metrics.json`` when the scene has an analytic solution, otherwise the
self-convergence error against the finest job of the same scene and method
that shares its particle set."""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from mpm import analytic

from .common import natural_key, num, total

LABEL_KEYS = ("scheme", "kernel", "transfer")
# overrides already part of a label or a column of their own
COVERED_KEYS = {"scheme", "scheme.name", "kernel", "kernel.name", "kernel.transfer", "scene",
                "scene.name", "integrator", "integrator.name"}
RESOLUTION_KEYS = {"scene.resolution", "scene.particle_resolution"}


def _load_yaml(path: Path) -> Any:
    """A YAML file as plain containers, each top-level entry with its
    interpolations resolved where they resolve (a scene's value picked by
    its size), else left as written; None if unreadable."""
    if not path.is_file():
        return None
    try:
        from omegaconf import DictConfig, OmegaConf

        loaded = OmegaConf.load(path)
        if not isinstance(loaded, DictConfig):  # (OmegaConf.is_dict)
            return OmegaConf.to_container(loaded, resolve=False)
        out: Any = OmegaConf.to_container(loaded, resolve=False)  # a dict (a mapping's document)
        for key in loaded:
            try:
                out[key] = OmegaConf.to_container(loaded[key], resolve=True) if OmegaConf.is_config(
                    loaded[key]) else OmegaConf.select(loaded, str(key))
            except Exception:  # a resolver of the run's own (e.g. the core count) or a missing key: as written
                pass
        return out
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


def config_value(config, *path) -> Any:
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
            value = config_value(self.config, *config_path)
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
        r = num(self._pick("resolution", "scene", "resolution", override="scene.resolution"))
        return None if r is None else int(r)

    @property
    def dx(self) -> float | None:
        """Grid spacing [m]."""
        dx = num(self.metrics.get("dx"))
        if dx is None:
            domain = config_value(self.config, "scene", "domain")
            width = num(domain[0]) if isinstance(domain, list) and domain else None
            if width is not None and self.resolution:
                dx = width / self.resolution
        return dx

    def num(self, key: str) -> float | None:
        """A numeric metric (a per-body dict gives its total)."""
        return total(self.metrics.get(key))

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
    jobs = [j for p in sorted(sweep_dir.rglob("metrics.json"), key=lambda p: natural_key(str(p)))
            if (j := _read_job(p.parent, sweep_dir)) is not None]
    by_hash: dict[str, list[Job]] = defaultdict(list)
    for j in jobs:
        by_hash[str(j.metrics.get("config_hash") or f"dir:{j.rel}")].append(j)
    kept = [min(group, key=lambda j: (not j.completed, bool(j.metrics.get("skipped")), natural_key(j.rel)))
            for group in by_hash.values()]
    kept.sort(key=lambda j: natural_key(j.rel))
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


def extras_without(job: Job, prefix: str) -> tuple:
    """The job's varying overrides but those starting with ``prefix``."""
    return tuple(sorted((k, v) for k, v in job.extras.items() if not k.startswith(prefix)))


def group_name(j: Job) -> str:
    """The scene and resolution of a job, the groups of the bar charts."""
    return f"{j.scene} · {j.resolution} cells" if j.resolution is not None else j.scene


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
            d, v = num(err.get("displacement")), num(err.get("velocity"))
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
        ref = max(members, key=lambda j: cast(int, j.resolution))  # (grouped: a resolution)
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


def job_error(j: Job, quantity: str) -> float | None:
    """The job's ``displacement`` [m] or ``velocity`` [m/s] error."""
    return j.error_displacement if quantity == "displacement" else j.error_velocity
