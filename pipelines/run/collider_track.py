"""What a run records of its colliders' forces (mpm.colliders): per
collider and step the force it exerts on the bodies, its impulse over the
step (StepReport.collider_impulse, every kernel grid's) divided by the step
and the kernel's grids (scalars ``collider/<name>/force_<axis>`` [N; 2D:
N/m]), and in ``metrics.json`` (``collider_forces``) per collider the force
of the last step and its time-mean over the run."""

from __future__ import annotations

import numpy as np

AXES = "xyz"


class ColliderForces:
    """The forces of the colliders ``names`` in ``dim`` dimensions under a
    kernel of ``n_grids`` grids."""

    def __init__(self, names: list[str], dim: int, n_grids: int):
        self.names, self.dim, self.n_grids = names, dim, n_grids
        self.impulse = np.zeros((len(names), dim))  # [N s] summed over the run
        self.time = 0.0  # [s]
        self.last = np.zeros((len(names), dim))  # [N] the last step's force

    def add(self, report) -> dict:
        """A step's report: its scalars, by name."""
        if report.collider_impulse is None or report.dt <= 0.0:
            return {}
        J = report.collider_impulse[:len(self.names)] / self.n_grids
        self.impulse += J
        self.time += report.dt
        self.last = J / report.dt
        return {f"collider/{name}/force_{AXES[k]}": float(self.last[i, k])
                for i, name in enumerate(self.names) for k in range(self.dim)}

    def summary(self) -> dict:
        """Per collider: ``force_final`` and ``force_mean`` [N; 2D: N/m]."""
        mean = self.impulse / self.time if self.time > 0.0 else self.impulse
        return {name: {"force_final": [float(c) for c in self.last[i]], "force_mean": [float(c) for c in mean[i]]}
                for i, name in enumerate(self.names)}
