"""What a step leaves on the device for the host: its stability figures.

The kernels of a step accumulate into a :class:`StepStatus`, a Warp struct
with one float64 array per figure (:data:`FIELDS`: one value for the step,
one per body, or one per body and axis). The arrays are views into one flat
buffer (:class:`StatusBuffer`), so that resetting the figures before a step is
one copy, reading them back is one copy, and a step's figures can be kept in
a history row as they are. :class:`StepReport` is the host's typed reading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

STEP, BODY, BOX = "step", "body", "box"  # one value; one per body; one per body and axis


@dataclass(frozen=True)
class Field:
    name: str
    per: str  # STEP, BODY or BOX
    reset: float  # the value before a step (the identity of its reduction)
    doc: str


FIELDS = (
    Field("max_v2", STEP, 0.0, "largest |v_p|^2 of the new state [m^2/s^2]"),
    Field("nonfinite", STEP, 0.0, "particles with a non-finite position, velocity or F^sn"),
    Field("outside", STEP, 0.0, "particles that left the domain interior"),
    Field("boundary_work", STEP, 0.0, "positive work of the boundary conditions on the grid, all grids [J]"),
    Field("kinetic", STEP, 0.0, "kinetic energy of the new state [J] (track_energy)"),
    Field("potential", STEP, 0.0, "its gravitational potential energy -sum m g . x [J] (track_energy)"),
    Field("removed", STEP, 0.0, "particles removed at open faces in this step"),
    Field("contact_nodes", STEP, 0.0, "body nodes whose bin was in contact (mpm.contact)"),
    Field("marked", BODY, 0.0, "particles with dJ >= epsilon (A-ULMPM)"),
    Field("max_dJ", BODY, 0.0, "the largest dJ = |det F^sn - 1|"),
    Field("min_J", BODY, math.inf, "the smallest det F (compression)"),
    Field("min_stretch2", BODY, math.inf, "the smallest singular value of F^sn, squared (Lagrangian schemes)"),
    Field("max_rate2", BODY, 0.0, "the largest |L|^2 of the velocity gradient [1/s^2]"),
    Field("stiffening", BODY, 0.0, "the largest growth of the squared wave speed (hardening; 0: none)"),
    Field("max_speed2", BODY, 0.0, "the largest |v_p|^2 [m^2/s^2] (track_energy)"),
    Field("min_F_stretch2", BODY, math.inf, "the smallest singular value of F, squared (track_J)"),
    Field("max_F_norm", BODY, 0.0, "the largest |F^sn|_inf (walls-only Lagrangian scenes)"),
    Field("box_lo", BOX, math.inf, "bounding box of the new positions, lower corner [m]"),
    Field("box_hi", BOX, -math.inf, "upper corner [m]"),
)


@wp.struct
class StepStatus:
    """The figures of one step on the device (see :data:`FIELDS`; per-body
    figures at index b, per-axis ones at b * dim + d)."""

    max_v2: wp.array(dtype=wp.float64)
    nonfinite: wp.array(dtype=wp.float64)
    outside: wp.array(dtype=wp.float64)
    boundary_work: wp.array(dtype=wp.float64)
    kinetic: wp.array(dtype=wp.float64)
    potential: wp.array(dtype=wp.float64)
    removed: wp.array(dtype=wp.float64)
    contact_nodes: wp.array(dtype=wp.float64)
    marked: wp.array(dtype=wp.float64)
    max_dJ: wp.array(dtype=wp.float64)
    min_J: wp.array(dtype=wp.float64)
    min_stretch2: wp.array(dtype=wp.float64)
    max_rate2: wp.array(dtype=wp.float64)
    stiffening: wp.array(dtype=wp.float64)
    max_speed2: wp.array(dtype=wp.float64)
    min_F_stretch2: wp.array(dtype=wp.float64)
    max_F_norm: wp.array(dtype=wp.float64)
    box_lo: wp.array(dtype=wp.float64)
    box_hi: wp.array(dtype=wp.float64)


assert list(StepStatus.vars) == [f.name for f in FIELDS], "StepStatus and FIELDS disagree"


class StatusBuffer:
    """The flat float64 buffer behind a :class:`StepStatus`: ``status`` (the
    struct the kernels take), ``flat`` (the buffer), :meth:`reset`,
    :meth:`read`."""

    def __init__(self, n_bodies: int, dim: int, device):
        sizes = {STEP: 1, BODY: n_bodies, BOX: n_bodies * dim}
        self.n_bodies, self.dim = n_bodies, dim
        self.slices: dict[str, slice] = {}
        start = 0
        for f in FIELDS:
            self.slices[f.name] = slice(start, start + sizes[f.per])
            start += sizes[f.per]
        self.size = start
        reset = np.empty(self.size)
        for f in FIELDS:
            reset[self.slices[f.name]] = f.reset
        with wp.ScopedDevice(device):
            self.flat = wp.array(reset, dtype=wp.float64)
            self._reset = wp.array(reset, dtype=wp.float64)
        self.status = StepStatus()
        for f in FIELDS:
            s = self.slices[f.name]
            setattr(self.status, f.name, self.flat[s.start:s.stop])

    def reset(self) -> None:
        """Every figure to its reduction's identity (one device copy)."""
        wp.copy(self.flat, self._reset)

    def values(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        """A flat buffer's values by field name (views)."""
        return {name: flat[s] for name, s in self.slices.items()}

    def read(self) -> dict[str, np.ndarray]:
        """The figures on the host, by field name (one device-to-host copy)."""
        return self.values(self.flat.numpy().copy())


@dataclass
class StepReport:
    """What one step left behind: stability figures, the criterion per body,
    the configuration updates it triggered."""

    max_speed: float  # [m/s]
    nonfinite: int  # particles with a non-finite position, velocity or F^sn
    outside: int  # particles that left the domain interior
    marked: np.ndarray  # per body: particles with dJ >= epsilon (A-ULMPM), else 0
    max_dJ: np.ndarray  # per body: the largest dJ (A-ULMPM), else 0
    min_J: np.ndarray  # per body: the smallest det F (compression, for the time step)
    min_stretch: np.ndarray  # per body: the smallest singular value of F^sn (for the time step)
    max_rate: np.ndarray  # per body: the largest velocity gradient |L| [1/s] (for the time step)
    stiffening: np.ndarray  # per body: the largest growth of the squared wave speed (0: none)
    box_lo: np.ndarray  # per body: bounding box of the new positions [m] (the next reference grids)
    box_hi: np.ndarray
    updated: list[int] = field(default_factory=list)  # bodies whose configuration was updated
    update_time: float = 0.0  # [s] deciding and updating
    dt: float = 0.0  # [s] the step taken (an implicit step may have been halved)
    newton: object = None  # the implicit solve's NewtonReport (None: explicit)
    halvings: int = 0  # times the implicit step was halved after a failed solve
    body_speed: np.ndarray | None = None  # per body: the fastest particle [m/s] (track_energy; else 0)
    min_F_stretch: np.ndarray | None = None  # per body: smallest singular value of F (track_J; else inf)
    boundary_work: float = 0.0  # [J] work of the boundary conditions on the grid (all grids)
    kinetic: float = float("nan")  # [J] kinetic energy of the new state (track_energy)
    potential: float = float("nan")  # [J] its gravitational potential energy, -sum m g . x
    removed: np.ndarray | None = None  # per body: particles removed at open faces in this step (None: none)
    max_F_norm: np.ndarray | None = None  # per body: the largest |F^sn|_inf (walls-only Lagrangian scenes)
    contact_nodes: int = 0  # body nodes whose bin was in contact in this step (mpm.contact)
    positioned: bool = True  # the node positions were available (False: not summed)
    elastic: float = float("nan")  # [J] elastic energy of the state the step started from (its P2G)
    dt_fresh: float = float("nan")  # [s] the step a freshly updated reference would have allowed
    wall_time: float = 0.0  # [s] host time the step took

    @classmethod
    def failed(cls, n_bodies: int) -> "StepReport":
        """The report of a step that did not complete (its state was restored)."""
        return cls(0.0, 0, 0, *([np.zeros(n_bodies)] * 8))

    @classmethod
    def of(cls, v: dict[str, np.ndarray], dim: int, energy: bool, reach: bool) -> "StepReport":
        """The report of the figures ``v`` (:meth:`StatusBuffer.values`);
        ``energy``: they hold the kinetic and potential energy; ``reach``:
        the largest |F^sn|_inf."""
        nb = len(v["marked"])
        return cls(
            max_speed=float(np.sqrt(v["max_v2"][0])), nonfinite=int(v["nonfinite"][0]),
            outside=int(v["outside"][0]), marked=v["marked"].astype(np.int64), max_dJ=v["max_dJ"].copy(),
            min_J=v["min_J"].copy(), min_stretch=np.sqrt(v["min_stretch2"]), max_rate=np.sqrt(v["max_rate2"]),
            stiffening=v["stiffening"].copy(), box_lo=v["box_lo"].reshape(nb, dim).copy(),
            box_hi=v["box_hi"].reshape(nb, dim).copy(), body_speed=np.sqrt(v["max_speed2"]),
            min_F_stretch=np.sqrt(v["min_F_stretch2"]),
            max_F_norm=v["max_F_norm"].copy() if reach else None,
            boundary_work=float(v["boundary_work"][0]), contact_nodes=int(v["contact_nodes"][0]),
            removed=np.zeros(nb, np.int64) if v["removed"][0] > 0 else None,
            kinetic=float(v["kinetic"][0]) if energy else float("nan"),
            potential=float(v["potential"][0]) if energy else float("nan"))

    @property
    def reason(self) -> str | None:
        if self.newton is not None and not self.newton.converged:
            return self.newton.reason
        if self.nonfinite:
            return f"{self.nonfinite} particles have non-finite position, velocity or F"
        if self.outside:
            return f"{self.outside} particles left the domain"
        return None
