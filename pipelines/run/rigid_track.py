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
  ``rotation_<axis>``, the rotation vector), and its energies
  (mpm.rigid_coupling.Coupler.energies) ``kinetic_energy`` (translation),
  ``rotational_energy`` and ``potential_energy`` (-m g . x) [J; 2D: J/m];
  with them the scalar ``rigid_energy``, all bodies' sum, and
  ``system_energy``, the material's ``total_energy`` plus that, at the
  frame's step (the material's row is complete one step later);
* in ``metrics.json`` (``rigid_bodies``) its final pose, velocities and
  energies, and (:meth:`RigidTrack.balance`) ``rigid_energy_initial``,
  ``rigid_energy_final`` and the material's and the bodies' together,
  ``total_energy_initial`` and ``total_energy_final``, which the run's
  ``energy_change`` then weighs (pipelines.run.recorder).
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
        self.initial = self.energy(self.state())  # [J] all bodies' (kept by a checkpoint: pipelines.run.checkpoints)
        self.final = self.initial
        self.at: tuple[int, float] | None = None  # (step, all bodies' energy [J]) of the last frame

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

    def energies(self, s: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Per body, the energies of a state ``s`` (:meth:`state`), by their scalars' names [J]."""
        e = self.coupler.energies(s)
        return {f"{k}_energy": e[k] for k in ("kinetic", "rotational", "potential")}

    def energy(self, s: dict[str, np.ndarray], energies: dict[str, np.ndarray] | None = None) -> float:
        """[J] All bodies' energy in a state ``s`` (:meth:`state`; or its ``energies`` where taken)."""
        return float(sum(np.sum(v) for v in (energies or self.energies(s)).values()))

    def system(self, step: int, material: float) -> dict:
        """The scalar ``system_energy`` [J] at ``step``: the material's total energy ``material`` plus the
        bodies' at the frame of that step (none where no frame was taken there)."""
        return {"system_energy": material + self.at[1]} if self.at is not None and self.at[0] == step else {}

    def balance(self, initial: float, final: float) -> dict:
        """metrics.json: the bodies' energy at the start and at the end (:meth:`summary`'s state), and with the
        material's ``initial`` and ``final`` energy [J]."""
        return {"rigid_energy_initial": self.initial, "rigid_energy_final": self.final,
                "total_energy_initial": initial + self.initial, "total_energy_final": final + self.final}

    def frame(self, s: dict[str, np.ndarray], step: int = 0) -> tuple[list, dict]:
        """Of a state ``s`` (:meth:`state`) at ``step``: each body's pose as (R, b), a point q of its shape at
        rest drawn at R q + b, and the frame's scalars, by name."""
        poses, row = [], {}
        d = self.dim
        energies = self.energies(s)
        self.at = (step, self.energy(s, energies))
        row["rigid_energy"] = self.at[1]
        for i, name in enumerate(self.names):
            row.update({f"rigid/{name}/{k}": float(v[i]) for k, v in energies.items()})
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
        [rad/s] (2D: about z), ``torque`` [N m] (over the last step; 2D: about z, N m/m), ``mass`` [kg], and its
        ``kinetic_energy`` (translation), ``rotational_energy`` and ``potential_energy`` [J; 2D: J/m]; the
        bodies' energy is kept for :meth:`balance`."""
        out = {}
        d = self.dim
        energies = self.energies(s)
        self.final = self.energy(s, energies)
        for i, name in enumerate(self.names):
            turn = rotation_vector(s["quaternion"][i])
            w, tau = s["angular_velocity"][i], s["torque"][i]
            out[name] = {"position": [float(c) for c in s["position"][i, :d]],
                         "quaternion": [float(c) for c in s["quaternion"][i]],
                         **({"angle": float(turn[2])} if d == 2 else {"rotation": [float(c) for c in turn]}),
                         "velocity": [float(c) for c in s["velocity"][i, :d]],
                         "angular_velocity": float(w[2]) if d == 2 else [float(c) for c in w],
                         "torque": float(tau[2]) if d == 2 else [float(c) for c in tau],
                         "mass": float(s["mass"][i]), **{k: float(v[i]) for k, v in energies.items()}}
        return out
