"""What a run records of its rigid bodies (mpm.rigid, mpm.rigid_coupling).

Per body ``<name>`` (its name, else ``rigid<i>``):

* every step, the coupling force and torque the material exerts on it over
  the step, minus its collider's impulse and angular impulse about its
  centre of mass (StepReport.collider_impulse, collider_torque: rigid body
  b is collider ``len(scene.colliders) + b``, every kernel grid's) divided
  by the step and the kernel's grids, as the Coupler applies them: scalars
  ``rigid/<name>/force_<axis>`` [N; 2D: N/m] and ``torque`` [N m; 2D: N m/m,
  about z] (3D: ``torque_<axis>``);
* at every particle frame, its Newton state then (read from the device
  with the frame, no other read): the pose as the transform that takes its
  shape at rest to its place (drawn under /rigid/<name>), and scalars
  ``rigid/<name>/position_<axis>`` (centre of mass) [m],
  ``velocity_<axis>`` [m/s], ``angular_velocity`` [rad/s] (2D: about z;
  3D: ``angular_velocity_<axis>``) and ``angle`` [rad] (2D: about z; 3D:
  ``rotation_<axis>``, the rotation vector);
* in ``metrics.json`` (``rigid_bodies``) its final pose and velocities.
"""

from __future__ import annotations

import numpy as np

AXES = "xyz"


def names(scene) -> list[str]:
    """The scene's rigid bodies' names (``rigid<i>`` for one without)."""
    return [b.name or f"rigid{i}" for i, b in enumerate(scene.rigid_bodies)]


def rotation(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(c) for c in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rotation_vector(q: np.ndarray) -> np.ndarray:
    """The rotation vector [rad] of a unit quaternion (x, y, z, w)."""
    axis = np.asarray(q[:3], np.float64)
    s = float(np.linalg.norm(axis))
    return axis * (2.0 * np.arctan2(s, float(q[3])) / s) if s > 0.0 else np.zeros(3)


class RigidTrack:
    """The rigid bodies of ``scene`` coupled by ``coupler`` (mpm.rigid_coupling.Coupler) under a kernel of
    ``n_grids`` grids."""

    def __init__(self, scene, coupler, n_grids: int):
        self.names, self.dim, self.n_grids = names(scene), scene.dim, n_grids
        self.coupler = coupler
        self.first = len(scene.colliders)
        self.rest = [np.pad(b.center(), (0, 3 - scene.dim)) for b in scene.rigid_bodies]  # initial centres

    def forces(self, report) -> dict:
        """A step's report: its force and torque scalars, by name."""
        if report.collider_impulse is None or report.dt <= 0.0:
            return {}
        rows = slice(self.first, self.first + len(self.names))
        f = -report.collider_impulse[rows] / (self.n_grids * report.dt)
        out = {f"rigid/{name}/force_{AXES[k]}": float(f[i, k]) for i, name in enumerate(self.names)
               for k in range(self.dim)}
        if report.collider_torque is not None:
            tau = -report.collider_torque[rows] / (self.n_grids * report.dt)
            for i, name in enumerate(self.names):
                if self.dim == 2:
                    out[f"rigid/{name}/torque"] = float(tau[i, 2])
                else:
                    out.update({f"rigid/{name}/torque_{AXES[k]}": float(tau[i, k]) for k in range(3)})
        return out

    def state(self) -> dict[str, np.ndarray]:
        """The Newton state now (one read from the device): the Coupler's poses, and ``torque`` [N m], the
        material's torque over the last step."""
        out = self.coupler.poses()
        out["torque"] = self.coupler.state.body_f.numpy().astype(np.float64)[:, 3:]
        return out

    def frame(self, s: dict[str, np.ndarray]) -> tuple[list, dict]:
        """Of a state ``s`` (:meth:`state`): each body's pose as (R, b), a point q of its shape at rest
        drawn at R q + b, and the frame's scalars, by name."""
        poses, row = [], {}
        d = self.dim
        for i, name in enumerate(self.names):
            R = rotation(s["quaternion"][i])
            poses.append((R, s["position"][i] - R @ self.rest[i]))
            p = f"rigid/{name}/"
            row.update({f"{p}position_{AXES[k]}": float(s["position"][i, k]) for k in range(d)})
            row.update({f"{p}velocity_{AXES[k]}": float(s["velocity"][i, k]) for k in range(d)})
            turn = rotation_vector(s["quaternion"][i])
            if d == 2:
                row.update({f"{p}angle": float(turn[2]), f"{p}angular_velocity": float(s["angular_velocity"][i, 2])})
            else:
                for k in range(3):
                    row.update({f"{p}rotation_{AXES[k]}": float(turn[k]),
                                f"{p}angular_velocity_{AXES[k]}": float(s["angular_velocity"][i, k])})
        return poses, row

    def summary(self, s: dict[str, np.ndarray]) -> dict:
        """Per body its final state: ``position`` [m], ``quaternion`` (x, y, z, w), ``angle`` [rad] (2D,
        about z) or ``rotation`` (3D, the rotation vector), ``velocity`` [m/s], ``angular_velocity``
        [rad/s] (2D: about z), ``torque`` [N m] (over the last step; 2D: about z, N m/m), ``mass`` [kg]."""
        out = {}
        d = self.dim
        for i, name in enumerate(self.names):
            turn = rotation_vector(s["quaternion"][i])
            w, tau = s["angular_velocity"][i], s["torque"][i]
            out[name] = {"position": [float(c) for c in s["position"][i, :d]],
                         "quaternion": [float(c) for c in s["quaternion"][i]],
                         **({"angle": float(turn[2])} if d == 2 else {"rotation": [float(c) for c in turn]}),
                         "velocity": [float(c) for c in s["velocity"][i, :d]],
                         "angular_velocity": float(w[2]) if d == 2 else [float(c) for c in w],
                         "torque": float(tau[2]) if d == 2 else [float(c) for c in tau],
                         "mass": float(s["mass"][i])}
        return out
