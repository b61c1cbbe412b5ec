"""What a run records of its external loads (mpm.loads): per load and step
the applied force and the mean displacement of its particles (the load
point's displacement, scalars ``load/<name>/force_<axis>`` [N; 2D: N/m] and
``load/<name>/u_<axis>`` [m] at the step's start), and in ``metrics.json``
the resolved loads with their final displacement and, once the profile
holds its last value, the time-mean displacement over the hold (the static
response of an undamped explicit run oscillating about it)."""

from __future__ import annotations

import math

import numpy as np

AXES = "xyz"


class LoadTrack:
    """The loads of ``model`` (its :class:`mpm.loads.LoadTable`) from the
    initial positions ``X0`` [m] on."""

    def __init__(self, model, X0: np.ndarray):
        self.table = table = model.loads
        self.dim = model.dim
        self.names = [s["name"] for s in table.summary]
        self.members = [table.members(i) for i in range(len(table.loads))]
        self.origin = np.array([X0[m].mean(axis=0) for m in self.members])  # [m]
        # the profile holds its last value from here on [s]
        self.hold = np.array([ld.start + float(ld.rows()[-1, 0]) for ld in table.loads])
        self.end = np.array([ld.end for ld in table.loads])  # [s] and it ends here
        self.sum_u = np.zeros((len(self.names), self.dim))
        self.sum_t = np.zeros(len(self.names))

    def add(self, report) -> dict:
        """A step's report: its start's scalars (time-mean over the hold updated)."""
        if report.load_position is None:
            return {}
        t0 = report.time - report.dt
        u = report.load_position[:len(self.names)] - self.origin
        held = (t0 >= self.hold) & (t0 < self.end)
        self.sum_u[held] += report.dt * u[held]
        self.sum_t[held] += report.dt
        row = {}
        for i, name in enumerate(self.names):
            f = self.table.loads[i].factor(t0) * np.asarray(self.table.summary[i]["total_force"])
            for k in range(self.dim):
                row[f"load/{name}/force_{AXES[k]}"] = float(f[k])
                row[f"load/{name}/u_{AXES[k]}"] = float(u[i, k])
        return row

    def summary(self, x: np.ndarray, t: float) -> list[dict]:
        """Per load: its resolution (kind, particles, area or volume, total
        force at factor 1), the force at time ``t`` [s], the displacement at
        the positions ``x`` [m] and its time-mean over the hold."""
        out = []
        for i, s in enumerate(self.table.summary):
            u = x[self.members[i]].mean(axis=0) - self.origin[i]
            mean = self.sum_u[i] / self.sum_t[i] if self.sum_t[i] > 0 else None
            out.append({**s, "force_final": [float(self.table.loads[i].factor(t) * c) for c in s["total_force"]],
                        "displacement_final": [float(c) for c in u],
                        "hold_start": float(self.hold[i]) if math.isfinite(self.hold[i]) else None,
                        "hold_time": float(self.sum_t[i]),
                        "displacement_hold_mean": None if mean is None else [float(c) for c in mean]})
        return out
