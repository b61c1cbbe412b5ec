"""A material-point driver: a constitutive model driven by a prescribed
deformation at independent points, without a grid.

Every step applies the increment dF = F_{k+1} F_k^-1 to the elastic state,
F_E^tr = dF F_E, and runs what P2G runs for that material: the return mapping
and the stress for plastic models (mpm.materials.plastic), the stress of
F = F_E for elastic ones and fluids (whose viscous stress reads
L = (dF - I) / dt). The tests use it to check return mappings against closed
forms; ``pipelines.material_point`` plots stress against strain with it.

Paths: :func:`deformation_path` (F at every step, any number of points),
:func:`velocity_path` (a constant velocity gradient, F_{k+1} = (I + dt L) F_k,
as MPM advances F) and :meth:`MaterialPoint.uniaxial_stress` (stretch along
x with the lateral stretches solved so that the lateral stresses vanish).
"""

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..launch import warp_kernel
from . import Material
from .plastic import make_plastic_update
from ..types import Types, make_types


@functools.cache
def _evaluator(t: Types, cls: type[Material]):
    S = t.scalar
    if cls.plastic:
        update = make_plastic_update(t, cls)
    else:
        stress_energy = cls.stress_energy(t)

    @warp_kernel
    def evaluate(F_tr: wp.array(dtype=t.mat), L: wp.array(dtype=t.mat), params: t.params,
                 history: wp.array(dtype=t.history), dt: S,
                 F_E: wp.array(dtype=t.mat), P: wp.array(dtype=t.mat), psi: wp.array(dtype=S)):
        i = wp.tid()
        if wp.static(cls.plastic):
            Fe, Pi, e, h = update(F_tr[i], params, history[i], dt)
            history[i] = h
        else:
            Fe = F_tr[i]
            Pi, e = stress_energy(Fe, L[i], params)
        F_E[i] = Fe
        P[i] = Pi
        psi[i] = e

    return evaluate


@dataclass
class PathResult:
    """Arrays per step k = 0..steps (step 0: the initial state) and point."""

    F: np.ndarray  # (steps + 1, n, d, d) total deformation gradient
    F_E: np.ndarray  # elastic part
    P: np.ndarray  # first Piola-Kirchhoff stress [Pa]
    psi: np.ndarray  # (steps + 1, n) stored energy per rest volume [J/m^3]
    history: np.ndarray  # (steps + 1, n, 2) history variables (plastic models)

    @property
    def tau(self) -> np.ndarray:
        """Kirchhoff stress P F_E^T [Pa]."""
        return self.P @ np.swapaxes(self.F_E, -1, -2)

    @property
    def cauchy(self) -> np.ndarray:
        """Cauchy stress tau / J_E [Pa]."""
        return self.tau / np.linalg.det(self.F_E)[..., None, None]


class MaterialPoint:
    """Evaluates one material at ``n`` independent points (float64 by default)."""

    def __init__(self, material: Material, dim: int = 3, precision: str = "float64",
                 device: str = "cpu"):
        self.material, self.device = material, device
        self.t = make_types(dim, precision)
        self.dtype = np.float64 if precision == "float64" else np.float32
        self.params = self.t.params(*material.packed_padded())
        self._kernel = _evaluator(self.t, type(material))

    def initial_history(self, n: int) -> np.ndarray:
        h = self.material.initial_history() if self.material.plastic else (0.0, 0.0)
        return np.tile(np.asarray(h, float), (n, 1))

    def evaluate(self, F_trial: np.ndarray, history: np.ndarray, dt: float,
                 L: np.ndarray | None = None):
        """One update of the trial elastic states (n, d, d): (F_E, P, psi, history)."""
        t, n = self.t, len(F_trial)
        L = np.zeros_like(F_trial) if L is None else L
        with wp.ScopedDevice(self.device):
            h = wp.array(np.asarray(history, self.dtype), dtype=t.history)
            F_E = wp.zeros(n, dtype=t.mat)
            P = wp.zeros(n, dtype=t.mat)
            psi = wp.zeros(n, dtype=t.scalar)
            wp.launch(self._kernel, n, inputs=[
                wp.array(np.asarray(F_trial, self.dtype), dtype=t.mat),
                wp.array(np.asarray(L, self.dtype), dtype=t.mat), self.params, h, t.scalar(dt),
                F_E, P, psi])
            return F_E.numpy().astype(float), P.numpy().astype(float), psi.numpy().astype(float), \
                h.numpy().astype(float)

    def run(self, F: np.ndarray, dt: float) -> PathResult:
        """Drive the points through the deformation gradients ``F`` (steps + 1,
        n, d, d), F[0] the initial (elastic) state."""
        F = np.asarray(F, float)
        steps, n = len(F) - 1, F.shape[1]
        F_E = np.empty_like(F)
        P = np.empty_like(F)
        psi = np.empty(F.shape[:2])
        hist = np.empty((steps + 1, n, 2))
        hist[0] = self.initial_history(n)
        F_E[0], P[0], psi[0], _ = self.evaluate(F[0], hist[0], 0.0)
        for k in range(steps):
            dF = F[k + 1] @ np.linalg.inv(F[k])
            L = (dF - np.eye(F.shape[-1])) / dt
            F_E[k + 1], P[k + 1], psi[k + 1], hist[k + 1] = self.evaluate(dF @ F_E[k], hist[k], dt, L)
        return PathResult(F, F_E, P, psi, hist)

    def uniaxial_stress(self, stretch: np.ndarray, dt: float, tol: float = 1e-10) -> PathResult:
        """Uniaxial stress along x: F = diag(s_k, l, l[, l]) with s_k = ``stretch``
        (stretch[0] = 1) and the lateral stretch l found at every step by
        Newton's method so that the lateral Kirchhoff stress vanishes
        (to ``tol`` times the axial one)."""
        d = self.t.dim
        steps = len(stretch) - 1
        F = np.tile(np.eye(d), (steps + 1, 1, 1, 1))
        F_E = np.empty_like(F)
        P = np.empty_like(F)
        psi = np.empty((steps + 1, 1))
        hist = np.empty((steps + 1, 1, 2))
        hist[0] = self.initial_history(1)
        F_E[0], P[0], psi[0], _ = self.evaluate(F[0], hist[0], 0.0)
        lateral = 1.0
        for k in range(steps):
            def attempt(l_new, k=k):  # (called in this iteration only)
                Fn = np.diag([stretch[k + 1]] + [l_new] * (d - 1))[None]
                dF = Fn @ np.linalg.inv(F[k])
                L = (dF - np.eye(d)) / dt
                out = self.evaluate(dF @ F_E[k], hist[k], dt, L)
                tau = out[1] @ np.swapaxes(out[0], -1, -2)
                return Fn, out, tau[0]
            for _ in range(50):
                Fn, out, tau = attempt(lateral)
                r = tau[1, 1]
                if abs(r) <= tol * max(abs(tau[0, 0]), 1e-30):
                    break
                h = 1e-7 * lateral
                slope = (attempt(lateral + h)[2][1, 1] - r) / h
                if slope == 0.0:
                    break
                lateral -= r / slope
            F[k + 1] = Fn
            F_E[k + 1], P[k + 1], psi[k + 1], hist[k + 1] = out
        return PathResult(F, F_E, P, psi, hist)


def velocity_path(L: np.ndarray, dt: float, steps: int, F0: np.ndarray | None = None) -> np.ndarray:
    """F_{k+1} = (I + dt L) F_k for a constant velocity gradient L (d, d) [1/s]:
    (steps + 1, 1, d, d)."""
    d = L.shape[0]
    F = np.empty((steps + 1, 1, d, d))
    F[0, 0] = np.eye(d) if F0 is None else F0
    step = np.eye(d) + dt * L
    for k in range(steps):
        F[k + 1, 0] = step @ F[k, 0]
    return F


def deformation_path(F: np.ndarray) -> np.ndarray:
    """A path of one point from deformation gradients (steps + 1, d, d)."""
    return np.asarray(F, float)[:, None]
