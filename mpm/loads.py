"""External loads: point loads, surface tractions and body forces on particle
sets, each scaled in time by a profile.

A :class:`Load` is resolved once, at the initial positions (:func:`resolve`),
into a force per loaded particle at factor 1 [N; N per metre of depth in
2D]:

* ``point``: a total force F shared by the ``count`` particles nearest to
  ``at`` (or those inside ``select``) in proportion to their volumes;
* ``traction``: a force per area t [Pa] on the face of ``select``'s
  particles that faces ``normal``: the outermost layer of particles along the
  normal, one sampling spacing s = (dx^d / ppc)^(1/d) thick, each carrying
  t A_p with the area A_p = V_p / s, or scaled so that sum A_p equals the
  face's ``area`` where it is given (sum A_p is exact for a face whose
  extent is a whole number of sampling spacings and a body sampled with the
  shape's volume; otherwise it is off by up to a spacing along each edge of
  the face: the resolved table reports it);
* ``body``: a force per volume b [N/m^3] on the particles in ``select`` (the
  whole body when None), V_p b each.

At a step starting at time t the loaded particles get the body force
    b_p = sum_l s_l(t) f_lp / m_p    [m/s^2]
which P2G adds to the node momenta as m_p b_p dt (mpm.p2g) in every scheme,
transfer and integrator (the implicit solve takes it as part of the
predicted velocity, like gravity). The profile s_l(t) is 0 outside
[start, end) and inside it the table's piecewise-linear value at t - start
(held at both ends): a constant load is the table ((0, 1),), a ramp over
``ramp`` seconds ((0, 0), (ramp, 1)), a sudden load the constant one.

The loads' work over the step, sum_p dt f_p . (v_p + v_p') / 2 with the
particle's velocities before and after it (G2P sums it: exact for a free
particle, none under a load held still), goes to the step's ``load_work``
(mpm.stepping.status), which the blow-up detection counts as energy put in
(mpm.stepping.detection).
"""

import functools
import math
from dataclasses import dataclass, field
from typing import Protocol, Sequence

import numpy as np
import warp as wp

from .launch import warp_kernel
from .stepping.status import StepControl, StepStatus
from .types import Types

LOAD_KINDS = ("point", "traction", "body")
"""point: a total force [N] (2D: N/m); traction: force per area [Pa] on a
face; body: force per volume [N/m^3] on a region."""

FACE_TOLERANCE = 1e-6  # of the sampling spacing: the face layer's lower edge, open
POINT_REACH = 2.0
"""a point load's ``at`` must lie within this many cells of a particle of its
body(ies): farther, it would silently load whatever particles are nearest"""


class Region(Protocol):
    """A scene shape as a selection: which of the points x (n, d) [m] lie inside."""

    def contains(self, x: np.ndarray) -> np.ndarray: ...


@dataclass
class Load:
    """An external load on the particles of ``body`` (None: of every body).

    ``force``: the total force [N] (point), the traction [Pa] (traction) or
    the force density [N/m^3] (body), a d-vector at profile factor 1.
    ``select``: a scene shape choosing the particles by initial position
    (point: those it holds share the force; traction: the face is taken
    among them; body: None takes the whole body). ``at`` [m] and ``count``:
    a point load on the ``count`` particles nearest ``at`` instead.
    ``normal``: the traction's face, its outward normal (any length);
    ``area``: the face's area [m^2; 2D: m] the traction is scaled to (None:
    the particles' sum V_p / s).
    The profile: active while start <= t < end [s]; inside, ``table`` rows
    (t - start [s], factor) interpolated linearly and held at both ends, or
    a linear ramp from 0 to 1 over ``ramp`` [s], or 1."""

    kind: str
    """point, traction or body (LOAD_KINDS)"""
    force: Sequence[float]
    select: Region | None = None
    body: int | None = None
    at: Sequence[float] | None = None
    count: int = 1
    normal: Sequence[float] | None = None
    start: float = 0.0
    """[s]"""
    end: float = math.inf
    """[s]"""
    ramp: float = 0.0
    table: Sequence[Sequence[float]] | None = None
    name: str = ""
    """a name for reports and the recording (default: load<index>)"""
    area: float | None = None

    def rows(self) -> np.ndarray:
        """The profile as (time after start [s], factor) rows."""
        if self.table is not None:
            return np.asarray(self.table, float).reshape(-1, 2)
        if self.ramp > 0.0:
            return np.array([[0.0, 0.0], [self.ramp, 1.0]])
        return np.array([[0.0, 1.0]])

    def factor(self, t: float) -> float:
        """The profile's factor at time ``t`` [s] (the kernel's rule, on the host)."""
        if not self.start <= t < self.end:
            return 0.0
        rows = self.rows()
        return float(np.interp(t - self.start, rows[:, 0], rows[:, 1]))

    @classmethod
    def point(cls, force, at=None, count: int = 1, select=None, **keys) -> "Load":
        """A total force ``force`` [N; 2D: N/m] shared by the ``count``
        particles nearest to ``at`` [m] (or those inside ``select``) in
        proportion to their volumes."""
        return cls("point", tuple(force), at=None if at is None else tuple(at), count=count, select=select, **keys)

    @classmethod
    def traction(cls, force, select, normal, area: float | None = None, **keys) -> "Load":
        """A force per area ``force`` [Pa] on the face of ``select``'s particles
        facing the outward ``normal`` (scaled to ``area`` [m^2; 2D: m] when given)."""
        return cls("traction", tuple(force), select=select, normal=tuple(normal), area=area, **keys)

    @classmethod
    def body_force(cls, force, select=None, **keys) -> "Load":
        """A force per volume ``force`` [N/m^3] on the particles inside
        ``select`` (None: the whole body, or every body)."""
        return cls("body", tuple(force), select=select, **keys)

    def problems(self, dim: int, n_bodies: int) -> list[tuple[str, str]]:
        """(field, message) for every inconsistency, before anything is sampled."""
        out = []
        if self.kind not in LOAD_KINDS:
            out.append(("kind", f"{self.kind!r}; accepted: {', '.join(LOAD_KINDS)}"))
        if len(self.force) != dim or not np.all(np.isfinite(self.force)):
            out.append(("force", f"{list(self.force)}; accepted: {dim} finite numbers"))
        if self.body is not None and not 0 <= self.body < n_bodies:
            out.append(("body", f"{self.body}; accepted: 0 to {n_bodies - 1}, or null (every body)"))
        if self.kind == "point":
            if (self.at is None) == (self.select is None):
                out.append(("at", "a point load takes either at (with count) or select; accepted: one of them"))
            if self.at is not None and (len(self.at) != dim or not np.all(np.isfinite(self.at))):
                out.append(("at", f"{list(self.at)}; accepted: {dim} finite numbers [m]"))
            if int(self.count) != self.count or self.count < 1:
                out.append(("count", f"{self.count}; accepted: an integer >= 1"))
        elif self.at is not None:
            out.append(("at", f"set on a {self.kind} load; accepted: at only on point loads (use select)"))
        if self.kind == "traction":
            if self.select is None:
                out.append(("select", "a traction needs the region holding its face; accepted: a shape"))
            n = np.asarray(self.normal if self.normal is not None else [], float)
            if n.shape != (dim,) or not np.all(np.isfinite(n)) or not np.linalg.norm(n) > 0.0:
                out.append(("normal", f"{self.normal}; accepted: {dim} finite numbers, not all 0 (the face's "
                                      "outward normal)"))
        elif self.normal is not None or self.area is not None:
            key = "normal" if self.normal is not None else "area"
            out.append((key, f"set on a {self.kind} load; accepted: {key} only on tractions"))
        if self.area is not None and not (math.isfinite(self.area) and self.area > 0.0):
            out.append(("area", f"{self.area}; accepted: a finite number > 0 [m^2; 2D: m], or None"))
        if not (self.start >= 0.0 and self.end > self.start):
            out.append(("end", f"start {self.start}, end {self.end}; accepted: 0 <= start < end"))
        if not (math.isfinite(self.ramp) and self.ramp >= 0.0):
            out.append(("ramp", f"{self.ramp}; accepted: a finite number >= 0 [s]"))
        if self.table is not None:
            rows = np.asarray(self.table, float)
            if (rows.ndim != 2 or rows.shape[1] != 2 or len(rows) == 0 or not np.all(np.isfinite(rows))
                    or np.any(np.diff(rows[:, 0]) < 0.0) or rows[0, 0] < 0.0):
                out.append(("table", f"{self.table}; accepted: rows [t - start (s), factor], finite, "
                                     "times >= 0 and non-decreasing"))
            elif self.ramp > 0.0:
                out.append(("ramp", "given with a table; accepted: one of ramp and table"))
        return out


class LoadError(ValueError):
    """A load that cannot be resolved: ``index`` in the scene's loads, ``key`` its field."""

    def __init__(self, index: int, key: str, message: str):
        super().__init__(f"loads[{index}].{key}: {message}")
        self.index, self.key, self.message = index, key, message


@dataclass
class LoadTable:
    """The loads resolved on the particles: per loaded particle (sorted,
    unique) the range of its entries, per entry its load and force at
    factor 1 [N]; per load a summary (``summary``: kind, particles, the
    face's area or region's volume, the total force at factor 1)."""

    particles: np.ndarray
    """int32, the loaded particles"""
    offsets: np.ndarray
    """int32, entries of particle j: offsets[j]:offsets[j + 1]"""
    entry_load: np.ndarray
    """int32"""
    entry_force: np.ndarray
    """(entries, d) [N] at factor 1"""
    entry_weight: np.ndarray
    """1 / (the load's particles): its mean position's weight"""
    loads: list[Load]
    summary: list[dict] = field(default_factory=list)

    def members(self, i: int) -> np.ndarray:
        """The particles load ``i`` acts on (sorted)."""
        owner = np.repeat(self.particles, np.diff(self.offsets))
        return np.unique(owner[self.entry_load == i])

    def acceleration(self, body_masses) -> float:
        """The largest acceleration [m/s^2] a load can give the bodies it acts
        on as a whole: its total force at its largest profile factor over
        their mass (the blow-up detection's speed allowance, mpm.stepping.detection)."""
        out = 0.0
        for i, load in enumerate(self.loads):
            peak = float(np.abs(load.rows()[:, 1]).max())
            M = float(np.sum(body_masses)) if load.body is None else float(body_masses[load.body])
            if M > 0.0:
                out = max(out, peak * float(np.linalg.norm(self.summary[i]["total_force"])) / M)
        return out

    def force(self, t: float) -> np.ndarray:
        """The total force of every load at time ``t`` [s], summed [N]."""
        s = np.array([load.factor(t) for load in self.loads])
        return (s[self.entry_load][:, None] * self.entry_force).sum(axis=0)


def resolve(loads: list[Load], x: np.ndarray, volume: np.ndarray, body: np.ndarray, body_ranges,
            spacing, dx: float, names=None) -> LoadTable:
    """The loads on the particles at positions ``x`` [m] with volumes ``volume``
    [m^d] and bodies ``body``; ``body_ranges[b]`` (start, count) of body b,
    ``spacing[b]`` [m] its sampling spacing (dx^d / ppc)^(1/d), ``dx`` [m]
    the grid's cell, ``names[b]`` its name for messages (None: its index).
    Raises :class:`LoadError` for a load that selects no particle, or a point load whose ``at`` lies farther than
    :data:`POINT_REACH` cells from every particle of its body."""
    entries = []  # (particle indices, load index, forces)
    summary = []
    for i, load in enumerate(loads):
        bodies = range(len(body_ranges)) if load.body is None else [load.body]
        idx = np.concatenate([np.arange(s, s + c) for s, c in (body_ranges[b] for b in bodies)])
        f = np.asarray(load.force, float)
        V = volume[idx]
        measure = {}  # the face's area or the region's volume
        if load.kind == "point" and load.at is not None:
            dist = np.linalg.norm(x[idx] - np.asarray(load.at, float), axis=1)
            if dist.min() > POINT_REACH * dx:
                whose = ("of any body" if load.body is None else
                         f"of body '{names[load.body]}'" if names else f"of body {load.body}")
                raise LoadError(i, "at", f"{list(load.at)} is {dist.min():.4g} m from the nearest particle {whose}; "
                                         f"accepted: a point within {POINT_REACH:g} cells ({POINT_REACH * dx:.4g} m) "
                                         "of the loaded body")
            keep = np.argsort(dist, kind="stable")[:int(load.count)]
        else:
            keep = (np.flatnonzero(load.select.contains(x[idx])) if load.select is not None
                    else np.arange(len(idx)))
        if len(keep) == 0:
            raise LoadError(i, "select", "selects no particle; accepted: a shape holding particles of "
                                         + ("every body" if load.body is None else f"body {load.body}"))
        if load.kind == "traction":
            n = np.asarray(load.normal, float)
            n = n / np.linalg.norm(n)
            s = np.asarray(spacing, float)[body[idx[keep]]]
            along = x[idx[keep]] @ n
            face = along > along.max() - s * (1.0 - FACE_TOLERANCE)
            keep, s = keep[face], s[face]
            area = V[keep] / s
            if load.area is not None:
                area *= load.area / area.sum()
            forces = area[:, None] * f
            measure = {"area": float(area.sum())}
        elif load.kind == "point":
            forces = (V[keep] / V[keep].sum())[:, None] * f
        else:
            forces = V[keep][:, None] * f
            measure = {"volume": float(V[keep].sum())}
        entries.append((idx[keep], i, forces))
        summary.append({"name": load.name or f"load{i}", "kind": load.kind, "particles": int(len(keep)),
                        **measure, "total_force": [float(c) for c in forces.sum(axis=0)]})
    p = np.concatenate([e[0] for e in entries])
    which = np.concatenate([np.full(len(e[0]), e[1]) for e in entries])
    forces = np.concatenate([e[2] for e in entries])
    weight = np.concatenate([np.full(len(e[0]), 1.0 / len(e[0])) for e in entries])
    order = np.argsort(p, kind="stable")
    p, which, forces, weight = p[order], which[order], forces[order], weight[order]
    particles, starts = np.unique(p, return_index=True)
    offsets = np.append(starts, len(p)).astype(np.int32)
    return LoadTable(particles.astype(np.int32), offsets, which.astype(np.int32), forces, weight, list(loads),
                     summary)


@functools.cache
def make_load_data(t: Types):
    """The struct type ``LoadData``: a :class:`LoadTable` and the loads'
    profiles on the device."""
    f64 = wp.float64

    @wp.struct
    class LoadData:
        particles: wp.array(dtype=wp.int32)  # the loaded particles
        offsets: wp.array(dtype=wp.int32)  # entries of particle j: offsets[j]:offsets[j + 1]
        entry_load: wp.array(dtype=wp.int32)
        entry_force: wp.array(dtype=t.vec)  # [N] at factor 1
        entry_weight: wp.array(dtype=f64)  # 1 / (the load's particles)
        window: wp.array(dtype=wp.vec2d)  # per load: (start, end) [s]
        first: wp.array(dtype=wp.int32)  # per load: its first profile row (one more: the end)
        table_t: wp.array(dtype=f64)  # per row: time after start [s]
        table_f: wp.array(dtype=f64)  # per row: factor

    return LoadData


@functools.cache
def make_apply_loads(t: Types):
    """``apply_loads``: per loaded particle, the body force b_p = sum_l
    s_l(t) f_lp / m_p [m/s^2] at the step's start ``control.t``, and each
    load's mean particle position into ``status.load_position`` (G2P sums
    the loads' work, mpm.g2p)."""
    f64 = wp.float64
    S = t.scalar
    LoadData = make_load_data(t)

    @wp.func
    def factor(loads: LoadData, n: int, time: f64):
        """Load n's profile at ``time`` [s]: 0 outside its window, else its
        table interpolated at time - start, held at both ends."""
        w = loads.window[n]
        if time < w[0] or time >= w[1]:
            return f64(0.0)
        tau = time - w[0]
        a = loads.first[n]
        b = loads.first[n + 1]
        k = a  # the first row after tau (the times do not decrease)
        for j in range(a, b):
            if loads.table_t[j] <= tau:
                k = j + 1
        if k == a:
            return loads.table_f[a]
        if k == b:
            return loads.table_f[b - 1]
        u = (tau - loads.table_t[k - 1]) / (loads.table_t[k] - loads.table_t[k - 1])
        return loads.table_f[k - 1] + u * (loads.table_f[k] - loads.table_f[k - 1])

    @warp_kernel
    def apply_loads(loads: LoadData, mass: wp.array(dtype=S), x: wp.array(dtype=t.vec), control: StepControl,
                    status: StepStatus, body_force: wp.array(dtype=t.vec)):
        if control.skip[0] != f64(0.0):
            return
        j = wp.tid()
        p = loads.particles[j]
        time = control.t[0]
        xp = x[p]
        f = t.vec()
        for e in range(loads.offsets[j], loads.offsets[j + 1]):  # pyright: ignore[reportOperatorIssue]
            n = loads.entry_load[e]
            f = f + S(factor(loads, n, time)) * loads.entry_force[e]
            for k in range(wp.static(t.dim)):
                wp.atomic_add(status.load_position, n * wp.static(t.dim) + k, loads.entry_weight[e] * f64(xp[k]))
        m = mass[p]
        b = t.vec()
        if m > S(0.0):
            b = f / m
        body_force[p] = b

    return apply_loads


class Loads:
    """A model's loads on the device and the pass that applies them at a
    step's start (into the P2G body force, ``body_force``)."""

    def __init__(self, model, launch, buffer, body_force):
        table = model.loads
        t = model.types
        self.model, self.launch, self.buffer, self.body_force = model, launch, buffer, body_force
        self.kernel = make_apply_loads(t)
        S = np.float32 if t.precision == "float32" else np.float64
        rows = [load.rows() for load in table.loads]
        first = np.cumsum([0] + [len(r) for r in rows]).astype(np.int32)
        table_rows = np.concatenate(rows)
        d = self.data = make_load_data(t)()
        with wp.ScopedDevice(model.device):
            d.particles, d.offsets = wp.array(table.particles, dtype=wp.int32), wp.array(table.offsets, dtype=wp.int32)
            d.entry_load = wp.array(table.entry_load, dtype=wp.int32)
            d.entry_force = wp.array(table.entry_force.astype(S), dtype=t.vec)
            d.entry_weight = wp.array(table.entry_weight, dtype=wp.float64)
            d.window = wp.array(np.array([[ld.start, ld.end] for ld in table.loads], np.float64), dtype=wp.vec2d)
            d.first = wp.array(first, dtype=wp.int32)
            d.table_t = wp.array(table_rows[:, 0].copy(), dtype=wp.float64)
            d.table_f = wp.array(table_rows[:, 1].copy(), dtype=wp.float64)
        self.n = len(table.particles)

    def kernels(self) -> list:
        return [self.kernel]

    def apply(self, state) -> None:
        """The loaded particles' body force at the device's step start."""
        b = self.buffer
        self.launch(self.kernel, self.n, [self.data, self.model.mass, state.x, b.control, b.status, self.body_force])
