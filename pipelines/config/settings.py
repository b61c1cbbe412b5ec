"""The settings of a run: ``run``, ``log``, ``kernel`` and
``stability_map``. Each dataclass is both the schema Hydra composes and the
checked settings a :class:`pipelines.config.validate.RunSpec` carries."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import List, Optional

import mpm
from mpm.transfer import TRANSFERS

from .fields import ConfigError, Context, setting

PRECISIONS = ("float32", "float64")
DEVICES = ("auto", "cpu", "cuda")
# log.color; dJ needs log.dJ, plastic_strain a plastic body; speed: |v| [m/s], recorded then
COLORS = ("auto", "body", "dJ", "plastic_strain", "speed")


def reference(key: str, path, ctx: Context | None = None) -> str:
    """The final_state.npz of a reference run, given the run's directory or the file."""
    p = os.path.join(str(path), "final_state.npz") if os.path.isdir(str(path)) else str(path)
    if not os.path.isfile(p):
        raise ConfigError(key, f"{path!r}: no final_state.npz there; accepted: the directory of a "
                               "finished run (or its final_state.npz)")
    return os.path.abspath(p)


def recording_name(key: str, value, ctx: Context | None = None) -> str:
    """A file name inside the run directory."""
    name = "" if value is None else str(value)
    if not name or "/" in name or "\\" in name or not name.endswith(".rrd") or name == ".rrd":
        raise ConfigError(key, f"{value!r}; accepted: a file name ending in .rrd, without a directory (it is "
                               "written into the run directory)")
    if name.endswith(".timings.rrd"):
        raise ConfigError(key, f"{value!r}: the name of a recording's timings file; accepted: a file name ending "
                               "in .rrd but not in .timings.rrd")
    return name


@dataclass
class RunSettings:
    """How long and how to step."""

    steps: Optional[int] = setting(None, "number of steps (exclusive with run.duration)", ge=1)
    duration: Optional[float] = setting(None, "simulated time [s]; null: the scene's", gt=0.0)
    dt: Optional[float] = setting(None, "fixed time step [s]; null: adaptive (explicit: the CFL limit; "
                                        "implicit: the displacement limit)", gt=0.0)
    cfl: float = setting(0.4, "CFL number of the adaptive step", gt=0.0, le=1.0)
    dt_max: float = setting(1.0e-3, "largest adaptive step [s]", gt=0.0)
    dt_collapse: float = setting(1.0e-4, "unstable when the adaptive step falls below this fraction of the "
                                         "first", ge=0.0, le=1.0)
    precision: str = setting("float32", "floating-point precision of the state", choices=PRECISIONS)
    device: str = setting("${oc.env:MPM_DEVICE,auto}", "auto (CUDA when Warp finds a GPU, else the CPU), "
                                                       "cpu or cuda; the default: the environment's MPM_DEVICE, "
                                                       "else auto", choices=DEVICES)
    force: bool = setting(False, "in a sweep: run even if a job with the same config hash finished")
    plan: bool = setting(False, "print the stages and kernels of a step and exit (nothing compiled or run)")
    fuse: Optional[bool] = setting(None, "explicit EMPM: stencils located in P2G/G2P, G2P updates the "
                                         "reference (the same results); null: where it pays")
    compensate: Optional[bool] = setting(None, "G2P keeps x and F as compensated sums (float32 resolves a small "
                                               "step's strain as float64 does); null: where float32 cannot "
                                               "resolve the scene (mpm.precision)")
    reference: Optional[str] = setting(None, "a run directory (or its final_state.npz) to measure the error "
                                             "against", parse=reference)
    sync_every: Optional[int] = setting(None, "the host reads the step's figures every k steps; null: 1 on the "
                                              "CPU, 10 on CUDA", ge=1)
    graph: Optional[bool] = setting(None, "replay a fixed-size scene's k steps as a CUDA graph; null: on CUDA "
                                          "where the scene allows it")
    checkpoint_every: Optional[float] = setting(None, "simulated time between checkpoints [s] (<run dir>/checkpoints, "
                                                      "the last two kept); 0: none; null: every 5 minutes of wall "
                                                      "time", ge=0.0)
    resume: Optional[bool] = setting(False, "continue from the newest valid checkpoint in the run directory "
                                            "(hydra.run.dir=<dir>); null: where it holds one, else start (a "
                                            "requeued job)")

    def problems(self):
        if self.steps is not None and self.duration is not None:
            return [("steps", "set run.steps or run.duration, not both")]
        return []


@dataclass
class LogSettings:
    """What goes into the recording."""

    every: Optional[int] = setting(None, "particles every N steps; 0: none; null: log.fps frames per simulated "
                                         "second", ge=0)
    fps: float = setting(60.0, "particle frames per simulated second (when log.every is null)", gt=0.0)
    color: str = setting("body", f"particle colour: {', '.join(COLORS)} (auto: plastic_strain with a plastic "
                                 "body, else dJ; dJ needs log.dJ, plastic_strain a plastic body)")
    color_range: Optional[List[float]] = setting(None, "[low, high] of the colour map of log.color (speed: "
                                                       "[m/s]); null: the field's fixed default (speed: the "
                                                       "initial speed with a free fall over the scene)", size=2)
    channels: List[str] = setting([], "extra particle entities /channels/<field>, one per field (dJ, plastic_strain, "
                                      "speed), each coloured by it on its fixed range, hidden until shown in the "
                                      "viewer; []: none")
    size_warning_mb: float = setting(1000.0, "warn before a run whose recording would be larger [MB]", gt=0.0)
    dJ: bool = setting(True, "the per-particle dJ field with the particles")
    fracture_every: int = setting(20, "steps between evaluations of the fracture measure (and at the end)", ge=1)
    scalars: bool = setting(True, "physics scalars every step")
    flush_every: int = setting(500, "steps between batched scalar sends", ge=1)
    progress: Optional[bool] = setting(None, "progress bar; null: on a terminal")
    recording: str = setting("recording.rrd", "file name inside the run directory", parse=recording_name)

    def problems(self):
        r = self.color_range
        if r is not None and not (math.isfinite(r[0]) and math.isfinite(r[1]) and r[0] < r[1]):
            return [("color_range", f"{list(r)}; accepted: [low, high], finite numbers with low < high")]
        return []

    @property
    def particles(self) -> bool:
        """Whether particle frames are logged at all."""
        return self.every != 0

    def resolve_color(self, scene: mpm.Scene) -> None:
        """``color`` checked against the scene, ``auto`` resolved."""
        plastic = any(b.material.plastic for b in scene.bodies)
        accepted = [c for c in COLORS if (c != "dJ" or self.dJ) and (c != "plastic_strain" or plastic)]
        if self.color not in accepted:
            why = ("" if self.color not in ("dJ", "plastic_strain") else
                   " (log.dJ is false)" if self.color == "dJ" else " (no plastic body in this scene)")
            raise ConfigError("log.color", f"{self.color!r}{why}; accepted: {', '.join(accepted)}")
        if self.color == "auto":
            self.color = "plastic_strain" if plastic else "dJ" if self.dJ else "body"
        fields = [c for c in accepted if c not in ("auto", "body")]
        for c in self.channels:
            if c not in fields:
                raise ConfigError("log.channels", f"{c!r}; accepted: a list of {', '.join(fields)}")


@dataclass
class KernelConfig:
    """Interpolation kernel (mpm.kernels) and the transfer that uses it (mpm.transfer)."""

    # choices: the registry itself, so that kernels registered later (pipelines.config.plugins) are accepted
    name: str = setting("quadratic", "the kernel", choices=mpm.KERNELS)
    transfer: str = setting("mls", "the transfer: mls, apic (affine), pic, flip (a PIC/FLIP blend)",
                            choices=TRANSFERS)
    flip: float = setting(0.95, "transfer=flip: the share of each particle's own velocity updated by the grid's "
                                "change (1: FLIP, 0: PIC)", ge=0.0, le=1.0)


@dataclass
class MapSpec:
    """The points of a stability map (pipelines.run.stability_map)."""

    E: List[float] = setting([], "stiffness [Pa]: Young's modulus (a fluid's bulk modulus)", gt=0.0,
                             nonempty="a list of numbers > 0")
    dt_cfl: List[float] = setting([], "fixed step [multiples of the explicit CFL limit]", gt=0.0,
                                  nonempty="a list of numbers > 0")
    steps: int = setting(100, "steps per point", ge=1)
