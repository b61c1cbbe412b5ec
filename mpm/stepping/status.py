"""What a step leaves on the device for the host: its figures, and the
device-side clock and decisions that let several steps run without the host.

One flat float64 buffer (:class:`StepBuffer`) holds three regions, each a
Warp struct of views (one array per quantity, :data:`FIELDS` and
:data:`CONTROL`):

* :class:`StepStatus`, reset before every step: what the step's kernels
  accumulate (G2P's speeds, counts and bounds, P2G's elastic energy, the
  boundary conditions' work and impulse, contact), the blow-up detection's trips, and
  the diagnostics of the new state when they are measured (mpm.diagnostics);
* :class:`StepControl`, kept from step to step: the time, the step taken
  and the next one (chosen on the device from the last step's figures,
  mpm.stepping.timestep), the step count, why the run must stop or wait for the host
  (``halt``, :data:`HALTS`), the configuration updates the criterion asked
  for (mpm.stepping.criterion), and the detection's running state (mpm.stepping.detection).

Resetting the status is one copy; reading everything back is one copy; a
step's whole buffer is one row of the history the host reads every k steps
(mpm.stepping.driver). :class:`StepReport` is the host's typed reading of a row.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np
import warp as wp

STEP, BODY, BOX, TRIP, DIAG, AXIS, LOAD, COLLIDER, TORQUE = ("step", "body", "box", "trip", "diag", "axis", "load",
                                                        "collider", "torque")
TRIP_SIZE = 6  # criterion code, body, value, limit, energy scale, boundary work (mpm.stepping.detection)

# why the steps stopped: the host acts, then (PAUSE, REGRID) the run goes on
HALTS = ("running", "done", "pause", "regrid", "nonfinite", "outside", "detection", "collapse")
(RUNNING, DONE, PAUSE, REGRID, NONFINITE, OUTSIDE, DETECTION, COLLAPSE) = range(len(HALTS))


@dataclass(frozen=True)
class Field:
    name: str
    per: str
    """STEP, BODY, BOX (body and axis), TRIP, DIAG (mpm.diagnostics), AXIS, LOAD (load and axis),
    COLLIDER (collider and axis), TORQUE (collider and the three axes of an angular impulse)"""
    reset: float
    """the value before a step (the identity of its reduction), or at the start"""
    doc: str


def _fields(table: str) -> tuple[Field, ...]:
    """The fields of a table: one a line, ``name per reset doc`` (``reset`` a
    float: 0, 1, inf, nan...); an indented line goes on with the doc above."""
    out: list[list] = []
    for line in table.strip("\n").split("\n"):
        if line[:1].isspace():
            out[-1][3] += " " + line.strip()
            continue
        name, per, reset, doc = line.split(maxsplit=3)
        if per not in (STEP, BODY, BOX, TRIP, DIAG, AXIS, LOAD, COLLIDER, TORQUE):
            raise ValueError(f"unknown extent {per!r} of field {name!r}")
        out.append([name, per, float(reset), doc])
    return tuple(Field(*f) for f in out)


FIELDS = _fields("""
max_v2            step  0     largest |v_p|^2 of the new state [m^2/s^2] (and of the rigid bodies'
                              surfaces at the step's start, mpm.rigid_coupling)
nonfinite         step  0     particles with a non-finite position, velocity or F^sn
outside           step  0     particles that left the domain interior
boundary_work     step  0     positive work of the boundary conditions on the grid, all grids [J]
load_work         step  0     work of the external loads over the step [J] (mpm.loads)
boundary_impulse  axis  0     momentum the boundary conditions gave the grid in the step,
                              sum m_i (v_bc - v_i) per axis, all grids [N s] (mpm.grid)
collider_impulse  collider 0  the part of it each collider gave, per axis, all grids [N s] (mpm.collider_device)
collider_torque   torque 0    its angular impulse about the collider's centre, r x J, per axis (x, y, z; 2D: z
                              only), all grids [N m s]: summed only where the scene has rigid bodies
                              (mpm.rigid_coupling), else 0
kinetic           step  0     kinetic energy of the new state [J] (track_energy)
potential         step  0     its gravitational potential energy -sum m g . x [J] (track_energy)
elastic           step  0     elastic energy of the state the step started from [J] (P2G)
contact_nodes     step  0     body nodes whose bin was in contact (mpm.contact)
contact_work      step  0     work of the contact between bodies on the grid velocities over the step, the
                              kinetic energy its corrections changed (never > 0 but for round-off) [J]
trips             step  0     detection trips recorded in this step
positioned        step  0     1: P2G summed the node positions in this step
removed           body  0     particles removed at open faces in this step
marked            body  0     particles with dJ >= epsilon (A-ULMPM)
max_dJ            body  0     the largest dJ = |det F^sn - 1|
min_J             body  inf   the smallest det F (compression)
min_stretch2      body  inf   the smallest singular value of F^sn, squared (Lagrangian schemes)
max_rate2         body  0     the largest |L|^2 of the velocity gradient [1/s^2]
stiffening        body  0     the largest growth of the squared wave speed (hardening; 0: none)
max_speed2        body  0     the largest |v_p|^2 [m^2/s^2] (track_energy)
min_F_stretch2    body  inf   the smallest singular value of F, squared (track_J)
max_F_norm        body  0     the largest |F^sn|_inf (walls-only Lagrangian scenes)
box_lo            box   inf   bounding box of the new positions, lower corner [m]
box_hi            box   -inf  upper corner [m]
load_position     load  0     mean position of each load's particles at the step's start [m] (mpm.loads)
trip              trip  0     the trips' records (TRIP_SIZE values each, mpm.stepping.detection)
diagnostics       diag  0     the new state's diagnostics as summed (mpm.diagnostics)
""")

CONTROL = _fields("""
t               step  0     time of the state [s]
dt              step  inf   the next step [s]
step            step  0     steps completed
halt            step  0     0: the next step runs; else why not (HALTS)
skip            step  0     1: the kernels of this step do nothing (the steps halted before it)
positions       step  1     1: P2G sums the node positions in the next step
host_update     step  0     1: a body's configuration update waits for the host (mpm.stepping.criterion)
dt_step         step  0     the step just taken [s]
fresh_step      step  nan   the step a fresh reference would have allowed it [s]
factor_step     step  1     its reference factor, dt / fresh of the binding body
landing_step    step  0     1: it was shortened to land on the end
dt_limit        step  inf   the rule's next step before landing on the end [s]
dt_request      step  inf   the next step after landing on the end, before any halving [s]
dt_fresh        step  nan   the step a fresh reference would allow [s]
factor          step  1     the next step's reference factor
binding         step  -1    the term that bound the next step (mpm.stepping.timestep.BINDINGS)
dt0             step  0     the first adaptive step [s]
dt0_set         step  0     1 once dt0 is taken
scale           step  1     the implicit step's factor after halvings
stop_step       step  inf   pause (PAUSE) once this many steps are done
stop_time       step  inf   pause once this time is reached [s]
e0              step  0     detection: the total energy of the first state checked [J]
e0_set          step  0     detection: 1 once e0 is taken
work            step  0     detection: the boundaries' work so far [J]
escale          step  0     detection: the energy scale [J]
growth          step  -inf  detection: the largest relative growth seen
kinetic_last    step  0     detection: kinetic energy of the last state [J]
potential_last  step  0     detection: its potential energy [J]
fired           step  0     detection: criteria reported so far (bits of mpm.stepping.detection.CRITERIA)
alive           body  0     particles not removed
update          body  0     1: the body's reference configuration moves after this step
regrid          body  0     1: it must, but its grid does not cover it: the host refits
center          axis  0     centre of the angular momentum scale [m] (mpm.diagnostics)
""")


def _struct(name: str, fields: tuple[Field, ...], doc: str):
    """A Warp struct with one float64 array per field."""
    cls = type(name, (), {"__annotations__": {f.name: wp.array(dtype=wp.float64) for f in fields},
                          "__doc__": doc, "__module__": __name__})
    return wp.struct(cls)


StepStatus = _struct("StepStatus", FIELDS, "The figures of one step on the device (FIELDS; per body at "
                                           "index b, per body and axis at b * dim + d).")
StepControl = _struct("StepControl", CONTROL, "The device's clock and decisions (CONTROL).")


class StepBuffer:
    """The flat float64 buffer behind a :class:`StepStatus` (``status``) and a
    :class:`StepControl` (``control``): :meth:`reset` (the status), :meth:`read`,
    ``flat`` (one row of the history)."""

    def __init__(self, n_bodies: int, dim: int, n_diagnostics: int, device, max_trips: int | None = None,
                 n_loads: int = 0, n_colliders: int = 0):
        self.n_bodies, self.dim, self.n_loads, self.n_colliders = n_bodies, dim, n_loads, n_colliders
        self.max_trips = max_trips if max_trips is not None else 1 + 3 * n_bodies
        sizes = {STEP: 1, BODY: n_bodies, BOX: n_bodies * dim, TRIP: TRIP_SIZE * self.max_trips,
                 DIAG: n_diagnostics, AXIS: dim, LOAD: max(n_loads, 1) * dim, COLLIDER: max(n_colliders, 1) * dim,
                 TORQUE: max(n_colliders, 1) * 3}
        self.slices: dict[str, slice] = {}
        start = 0
        for f in FIELDS + CONTROL:
            self.slices[f.name] = slice(start, start + sizes[f.per])
            start += sizes[f.per]
        self.size = start
        self.status_size = self.slices[CONTROL[0].name].start
        self.initial = np.empty(self.size)
        for f in FIELDS + CONTROL:
            self.initial[self.slices[f.name]] = f.reset
        with wp.ScopedDevice(device):
            self.flat = wp.array(self.initial, dtype=wp.float64)
            self._reset = wp.array(self.initial[:self.status_size], dtype=wp.float64)
        self._status_view = cast(wp.array, self.flat[:self.status_size])
        self._views: dict[str, wp.array] = {}
        self.status, self.control = StepStatus(), StepControl()
        for f in FIELDS:
            setattr(self.status, f.name, self.view(f.name))
        for f in CONTROL:
            setattr(self.control, f.name, self.view(f.name))

    def view(self, name: str) -> wp.array:
        """The device array of one field (a view into the buffer, made once)."""
        v = self._views.get(name)
        if v is None:
            s = self.slices[name]
            v = self._views[name] = cast(wp.array, self.flat[s.start:s.stop])  # a contiguous view
        return v

    def reset(self) -> None:
        """The status to its reductions' identities (one device copy); the control stays."""
        wp.copy(self._status_view, self._reset)

    def values(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        """A buffer's (or a history row's) values by field name (views)."""
        return {name: flat[s] for name, s in self.slices.items()}

    def read(self) -> dict[str, np.ndarray]:
        """Everything on the host, by field name (one device-to-host copy)."""
        return self.values(self.flat.numpy().copy())

    def set(self, **values) -> None:
        """Write control values from the host (host-to-device copies)."""
        for name, v in values.items():
            self.view(name).assign(np.asarray(v, np.float64).reshape(-1))


@dataclass
class NewtonReport:
    """What one implicit solve did."""

    newton: int = 0  # Newton iterations
    cg: int = 0  # conjugate-gradient iterations, all Newton iterations together
    residual: float = 0.0  # final |R| / initial |R| (0 when no iteration was needed)
    residual0: float = 0.0  # initial |R| [kg m/s]
    backtracks: int = 0  # line-search halvings, all iterations together
    rounds: int = 1  # solves (more than one where friction or a one-sided constraint changed a node's state)
    unsettled: int = 0  # bins and nodes the last solve leaves unsatisfied after ROUNDS solves (0: settled)
    reason: str = ""  # why it failed, or what the near miss was
    # converged | near_miss (out of iterations, or the line search stalled, within newton_accept of the
    # tolerance) | missed | diverged | stalled (see ImplicitSolve.solve)
    outcome: str = "converged"

    @property
    def converged(self) -> bool:
        """Whether the step may use the solution: converged, or a near miss."""
        return self.outcome in ("converged", "near_miss")


@dataclass
class StepReport:
    """What one step left behind: stability figures, the criterion per body,
    the configuration updates it triggered."""

    max_speed: float
    """the fastest particle of the new state [m/s] (or rigid body's surface at the step's start)"""
    nonfinite: int
    """particles with a non-finite position, velocity or F^sn"""
    outside: int
    """particles that left the domain interior"""
    marked: np.ndarray
    """per body: particles with dJ >= epsilon (A-ULMPM), else 0"""
    max_dJ: np.ndarray
    """per body: the largest dJ (A-ULMPM), else 0"""
    min_J: np.ndarray
    """per body: the smallest det F (compression, for the time step)"""
    min_stretch: np.ndarray
    """per body: the smallest singular value of F^sn (for the time step)"""
    max_rate: np.ndarray
    """per body: the largest velocity gradient |L| [1/s] (for the time step)"""
    stiffening: np.ndarray
    """per body: the largest growth of the squared wave speed (0: none)"""
    box_lo: np.ndarray
    """per body: bounding box of the new positions [m] (the next reference grids)"""
    box_hi: np.ndarray
    """per body: its upper corner [m]"""
    updated: list[int] = field(default_factory=list)
    """bodies whose configuration was updated"""
    update_time: float = 0.0
    """[s] deciding and updating"""
    dt: float = 0.0
    """[s] the step taken (an implicit step may have been halved)"""
    newton: NewtonReport | None = None
    """the implicit solve's NewtonReport (None: explicit)"""
    halvings: int = 0
    """times the implicit step was halved after a failed solve"""
    body_speed: np.ndarray | None = None
    """per body: the fastest particle [m/s] (track_energy; else 0)"""
    min_F_stretch: np.ndarray | None = None
    """per body: smallest singular value of F (track_J; else inf)"""
    boundary_work: float = 0.0
    """[J] work of the boundary conditions on the grid (all grids)"""
    load_work: float = 0.0
    """[J] work of the external loads over the step (mpm.loads)"""
    boundary_impulse: np.ndarray | None = None
    """[N s] per axis: the momentum the walls, colliders and regions gave the
    grid in the step, summed over the kernel's grids: the bodies receive it
    divided by the kernel's ``n_grids`` (2 for the compact kernel), as every
    grid carries their full mass"""
    collider_impulse: np.ndarray | None = None
    """[N s] per collider and axis: its part of ``boundary_impulse`` (all grids)"""
    collider_torque: np.ndarray | None = None
    """[N m s] per collider, 3 axes: its angular impulse about its centre (all grids; rigid bodies only, else 0)"""
    load_position: np.ndarray | None = None
    """per load: its particles' mean position at the step's start [m]"""
    kinetic: float = float("nan")
    """[J] kinetic energy of the new state (track_energy)"""
    potential: float = float("nan")
    """[J] its gravitational potential energy, -sum m g . x"""
    removed: np.ndarray | None = None
    """per body: particles removed at open faces in this step (None: none)"""
    max_F_norm: np.ndarray | None = None
    """per body: the largest |F^sn|_inf (walls-only Lagrangian scenes)"""
    contact_nodes: int = 0
    """body nodes whose bin was in contact in this step (mpm.contact)"""
    contact_work: float = 0.0
    """[J] the kinetic energy the contact between bodies changed in this step (mpm.contact; <= 0)"""
    positioned: bool = True
    """the node positions were available (False: not summed)"""
    regrid: list[int] = field(default_factory=list)
    """bodies whose grids the host refits (mpm.stepping.criterion)"""
    host_update: bool = False
    """the host moves a reference configuration (its diagnostics wait for it)"""
    step: int = 0
    """steps completed after this one (0: a step the host took by hand)"""
    time: float = 0.0
    """[s] the time after it (0: a step the host took by hand)"""
    halt: int = 0
    """why the steps stopped after it (mpm.stepping.status.HALTS)"""
    diagnostics: np.ndarray | None = None
    """the new state's diagnostics as summed (when measured)"""
    trips: np.ndarray | None = None
    """the detection's new trips (TRIP_SIZE values each, mpm.stepping.detection)"""
    elastic: float = float("nan")
    """[J] elastic energy of the state the step started from (its P2G)"""
    dt_fresh: float = float("nan")
    """[s] the step a freshly updated reference would have allowed"""
    wall_time: float = 0.0
    """[s] host time the step took"""
    measure_time: float = 0.0
    """[s] host time its diagnostics took after it (driver's measure)"""

    @classmethod
    def failed(cls, n_bodies: int, dim: int) -> "StepReport":
        """The report of a step that did not complete (its state was restored)."""
        z, box = np.zeros(n_bodies), np.zeros((n_bodies, dim))
        return cls(0.0, 0, 0, z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), box.copy(), box.copy())

    @classmethod
    def of(cls, v: dict[str, np.ndarray], dim: int, energy: bool, reach: bool) -> "StepReport":
        """The report of the step buffer's values ``v`` (:meth:`StepBuffer.values`);
        ``energy``: they hold the kinetic and potential energy; ``reach``: the
        largest |F^sn|_inf."""
        nb = len(v["marked"])
        removed = v["removed"]
        return cls(
            max_speed=float(np.sqrt(v["max_v2"][0])), nonfinite=int(v["nonfinite"][0]),
            outside=int(v["outside"][0]), marked=v["marked"].astype(np.int64), max_dJ=v["max_dJ"].copy(),
            min_J=v["min_J"].copy(), min_stretch=np.sqrt(v["min_stretch2"]), max_rate=np.sqrt(v["max_rate2"]),
            stiffening=v["stiffening"].copy(), box_lo=v["box_lo"].reshape(nb, dim).copy(),
            box_hi=v["box_hi"].reshape(nb, dim).copy(), body_speed=np.sqrt(v["max_speed2"]),
            min_F_stretch=np.sqrt(v["min_F_stretch2"]),
            max_F_norm=v["max_F_norm"].copy() if reach else None,
            boundary_work=float(v["boundary_work"][0]), load_work=float(v["load_work"][0]),
            boundary_impulse=v["boundary_impulse"].copy(),
            collider_impulse=v["collider_impulse"].reshape(-1, dim).copy(),
            collider_torque=v["collider_torque"].reshape(-1, 3).copy(),
            load_position=v["load_position"].reshape(-1, dim).copy(), contact_nodes=int(v["contact_nodes"][0]),
            contact_work=float(v["contact_work"][0]),
            removed=removed.astype(np.int64) if removed.any() else None,
            kinetic=float(v["kinetic"][0]) if energy else float("nan"),
            potential=float(v["potential"][0]) if energy else float("nan"),
            updated=[b for b in range(nb) if v["update"][b]], regrid=[b for b in range(nb) if v["regrid"][b]],
            host_update=bool(v["host_update"][0]), positioned=bool(v["positioned"][0]),
            elastic=float(v["elastic"][0]), dt=float(v["dt_step"][0]), dt_fresh=float(v["fresh_step"][0]),
            step=int(v["step"][0]), time=float(v["t"][0]), halt=int(v["halt"][0]),
            diagnostics=v["diagnostics"].copy(), trips=v["trip"][:TRIP_SIZE * int(v["trips"][0])].copy())

    @property
    def reason(self) -> str | None:
        if self.newton is not None and not self.newton.converged:
            return self.newton.reason
        if self.nonfinite:
            return f"{self.nonfinite} particles have non-finite position, velocity or F"
        if self.outside:
            return f"{self.outside} particles left the domain"
        return None
