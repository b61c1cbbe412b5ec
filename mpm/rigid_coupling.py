"""The rigid bodies of a scene (mpm.rigid) coupled both ways to the material
through Newton, a stage of the step only where a scene has any.

:class:`Coupler` builds a Newton model of the bodies (one free body each,
its mass and inertia from a box, sphere or cylinder shape of the body's
density; 2D: the shape one metre deep, a sphere a disc, a cylinder along z)
and holds its state (``body_q``: the pose, ``body_qd``: the velocity of the
centre of mass and the angular velocity, world frame). Each step, on the
device and with no read-back:

* :meth:`Coupler.place`, at the step's start: each body's collider record
  (rigid body b is collider ``len(scene.colliders) + b``) takes the pose and
  the velocities of the Newton state at the step's time ``control.t``
  (mpm.collider_motion places it at any time of the step from them);
* the grid rule (mpm.collider_device) and the keep-out (mpm.keep_out) then
  sum the impulse J they give the material at each body's surface
  (``status.collider_impulse``, all grids) and its angular impulse about
  the body's centre of mass, r x J (``status.collider_torque``, reset with
  the step's status);
* :meth:`Coupler.push`, after G2P: each body takes minus that, as the force
  -J / dt and the torque -(r x J) / dt over the step ``control.dt``, plus
  gravity, and Newton's semi-implicit rigid-body integrator (its
  ``integrate_rigid_body``, the update of newton.solvers.SolverSemiImplicit,
  with no damping) advances it: v' = v + dt (f / m + g), x' = x + dt v',
  omega' from the torque and the gyroscopic term, the orientation by
  omega'. What the material gains the body loses, so the momentum of the
  two together is kept (to the body state's float32 rounding).

The coupling is staggered: the material sees the body move at its velocity
at the step's start, the body answers after the step (explicit, every scheme
and kernel). The implicit integrator is refused with rigid bodies (there the
body's velocity would have to stay fixed during the solve and the solve's
constraint reactions be summed as torques too: not done). 2D bodies stay in
the plane: the forces have no z component, the torques only a z one, and
the out-of-plane components of the state are zeroed after each step.
"""


import functools

import numpy as np
import warp as wp

from .collider_shapes import make_collider_data
from .launch import warp_kernel
from .stepping.status import StepControl
from .types import Types


def refusal(scene, options) -> str | None:
    """Why ``options`` cannot step ``scene``'s rigid bodies (one line), or None."""
    from .integrators import Implicit

    if getattr(scene, "rigid_bodies", None) and isinstance(options.integrator, Implicit):
        return ("options.integrator: rigid bodies are coupled under the explicit integrator only; "
                "accepted: mpm.Explicit(), or no rigid bodies")
    return None


def quaternion(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation vector [rad]."""
    theta = float(np.linalg.norm(rotation))
    if theta == 0.0:
        return (0.0, 0.0, 0.0, 1.0)
    axis = np.asarray(rotation, float) / theta
    s = np.sin(0.5 * theta)
    return (axis[0] * s, axis[1] * s, axis[2] * s, float(np.cos(0.5 * theta)))


def newton_model(scene, device):
    """The Newton model of ``scene``'s rigid bodies (module docstring), with
    its gravity (2D: in the plane)."""
    import newton

    dim = scene.dim
    gravity = tuple(scene.gravity) + (0.0,) * (3 - dim)
    builder = newton.ModelBuilder(gravity=gravity)
    for i, b in enumerate(scene.rigid_bodies):
        c = b.shape
        centre = tuple(b.center()) + (0.0,) * (3 - dim)
        body = builder.add_body(xform=wp.transform(centre, wp.quat(*quaternion(b.turned(dim)))),
                                label=b.name or f"rigid{i}")
        cfg = newton.ModelBuilder.ShapeConfig(density=b.total_mass(dim) / b.volume(dim), has_shape_collision=False,
                                              has_particle_collision=False)
        if c.type == "box":
            h = tuple(c.half_size) + (0.5,) * (3 - dim)  # (2D: one metre deep)
            builder.add_shape_box(body, hx=h[0], hy=h[1], hz=h[2], cfg=cfg)
        elif c.type == "sphere" and dim == 2:
            builder.add_shape_cylinder(body, radius=c.radius, half_height=0.5, cfg=cfg)  # a disc, along z
        elif c.type == "sphere":
            builder.add_shape_sphere(body, radius=c.radius, cfg=cfg)
        else:
            from .colliders import axis_vector

            turn = wp.quat_between_vectors(wp.vec3(0.0, 0.0, 1.0), wp.vec3(*axis_vector(c.axis, 3)))
            builder.add_shape_cylinder(body, xform=wp.transform((0.0, 0.0, 0.0), turn), radius=c.radius,
                                       half_height=c.half_height, cfg=cfg)
    return builder.finalize(device=device)


@functools.cache
def make_place_bodies(t: Types):
    """Kernel: rigid body b's collider record (index ``first + b``) from the
    Newton state at the step's time (module docstring)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    V3, W2, dim = wp.types.vector(3, S), wp.types.vector(2, S), t.dim

    @warp_kernel
    def place_bodies(body_q: wp.array(dtype=wp.transform), body_qd: wp.array(dtype=wp.spatial_vector),
                     control: StepControl, first: int, colliders: wp.array(dtype=Data)):
        b = wp.tid()
        if control.skip[0] != wp.float64(0.0):
            return
        k = first + b  # pyright: ignore[reportOperatorIssue]
        c = colliders[k]
        x = wp.transform_get_translation(body_q[b])
        r = wp.transform_get_rotation(body_q[b])
        v = wp.spatial_top(body_qd[b])
        w = wp.spatial_bottom(body_qd[b])
        start = S(control.t[0])
        c.window = W2(start, S(1.0e30))
        u = vec()
        origin = vec()
        for d in range(wp.static(dim)):
            u[d] = S(v[d])  # pyright: ignore[reportIndexIssue]
            origin[d] = S(x[d]) - c.pivot[d]  # pyright: ignore[reportIndexIssue]
        c.u = u
        c.origin = origin
        c.omega = V3(S(w[0]), S(w[1]), S(w[2]))  # pyright: ignore[reportIndexIssue]
        # the rotation vector of r: 2 atan2(|xyz|, w) about xyz / |xyz|
        axis = wp.vec3(r[0], r[1], r[2])  # pyright: ignore[reportIndexIssue]
        s = wp.length(axis)  # pyright: ignore[reportArgumentType, reportCallIssue]
        frame = V3()
        if s > 0.0:
            angle = 2.0 * wp.atan2(s, r[3]) / s  # pyright: ignore[reportIndexIssue]
            frame = V3(S(axis[0] * angle), S(axis[1] * angle), S(axis[2] * angle))
        c.frame = frame
        colliders[k] = c

    return place_bodies


@functools.cache
def make_push_bodies(t: Types):
    """Kernel: each rigid body advanced by Newton's integrator over the
    step ``control.dt`` with minus the material's impulse and angular
    impulse (module docstring); 2D: the out-of-plane components zeroed."""
    from newton._src.solvers.solver import integrate_rigid_body

    dim = t.dim

    @warp_kernel
    def push_bodies(body_q: wp.array(dtype=wp.transform), body_qd: wp.array(dtype=wp.spatial_vector),
                    body_com: wp.array(dtype=wp.vec3), inertia: wp.array(dtype=wp.mat33),
                    inv_mass: wp.array(dtype=float), inv_inertia: wp.array(dtype=wp.mat33),
                    gravity: wp.array(dtype=wp.vec3), control: StepControl, first: int, n_grids: float,
                    impulse: wp.array(dtype=wp.float64), torque: wp.array(dtype=wp.float64),
                    body_f: wp.array(dtype=wp.spatial_vector)):
        b = wp.tid()
        if control.skip[0] != wp.float64(0.0):
            return
        k = first + b  # pyright: ignore[reportOperatorIssue]
        dt = control.dt[0]
        per = wp.float64(-1.0) / (wp.float64(n_grids) * dt)  # minus the material's share, as a mean force
        f = wp.vec3()
        tau = wp.vec3()
        for d in range(wp.static(dim)):
            f[d] = float(impulse[k * dim + d] * per)
        for a in range(3):
            tau[a] = float(torque[3 * k + a] * per)
        wrench = wp.spatial_vector(f, tau)  # pyright: ignore[reportArgumentType]
        body_f[b] = wrench
        q, qd = integrate_rigid_body(body_q[b], body_qd[b], wrench, body_com[b], inertia[b], inv_mass[b],
                                     inv_inertia[b], gravity[0], 0.0, float(dt))
        if wp.static(dim == 2):  # planar: z and the rotation about x and y stay zero
            x = wp.transform_get_translation(q)  # pyright: ignore[reportArgumentType]
            r = wp.transform_get_rotation(q)  # pyright: ignore[reportArgumentType]
            q = wp.transform(wp.vec3(x[0], x[1], 0.0), wp.normalize(wp.quat(0.0, 0.0, r[2], r[3])))  # pyright: ignore[reportArgumentType, reportCallIssue, reportIndexIssue]
            v = wp.spatial_top(qd)
            w = wp.spatial_bottom(qd)
            qd = wp.spatial_vector(wp.vec3(v[0], v[1], 0.0), wp.vec3(0.0, 0.0, w[2]))  # pyright: ignore[reportArgumentType, reportIndexIssue]
        body_q[b] = q
        body_qd[b] = qd

    return push_bodies


class Coupler:
    """``model``'s rigid bodies in Newton and the two stages of a step that
    couple them to the material (module docstring): :meth:`place` before the
    grid update (mpm.conditions.Conditions.update_grid), :meth:`push` after
    G2P (mpm.transfer.Transfers.interpolate); ``conditions`` holds the
    packed records and the angular impulses, ``control`` the step's clock.
    ``newton``: the Newton model; ``state``: its state (``body_q``,
    ``body_qd``, also named here for checkpoints; ``body_f`` the wrench the
    material applied over the last step)."""

    def __init__(self, model, conditions, control):
        t, scene = model.types, model.scene
        self.model, self.conditions, self.control = model, conditions, control
        self.first = len(scene.colliders)
        self.n = len(scene.rigid_bodies)
        self.newton = newton_model(scene, model.device)
        self.state = self.newton.state()
        spins = [b.spin(scene.dim) for b in scene.rigid_bodies]
        speeds = [tuple(b.velocity or ()) + (0.0,) * (3 - len(b.velocity or ())) for b in scene.rigid_bodies]
        self.state.body_qd.assign(np.array([tuple(v) + tuple(w) for v, w in zip(speeds, spins)], np.float32))  # pyright: ignore[reportOptionalMemberAccess]
        # the state's arrays, named here so that a checkpoint (mpm.checkpoint) holds them
        self.body_q, self.body_qd = self.state.body_q, self.state.body_qd
        self.place_kernel, self.push_kernel = make_place_bodies(t), make_push_bodies(t)

    def kernels(self) -> list:
        return [self.place_kernel, self.push_kernel]

    def place(self) -> None:
        """The bodies' collider records from their state at the step's start."""
        data = self.conditions.data
        wp.launch(self.place_kernel, self.n, device=self.model.device, inputs=[
            self.state.body_q, self.state.body_qd, self.control, self.first, data.colliders])

    def push(self, status) -> None:
        """The bodies advanced over the step with minus the material's impulse
        and angular impulse (``status.collider_impulse``, ``collider_torque``,
        mpm.stepping.status), plus gravity."""
        nm = self.newton
        wp.launch(self.push_kernel, self.n, device=self.model.device, inputs=[
            self.state.body_q, self.state.body_qd, nm.body_com, nm.body_inertia, nm.body_inv_mass,
            nm.body_inv_inertia, nm.gravity, self.control, self.first, float(self.model.kernel.n_grids),
            status.collider_impulse, status.collider_torque, self.state.body_f])

    def poses(self) -> dict[str, np.ndarray]:
        """The bodies' state on the host: ``position`` (centre of mass) [m],
        ``quaternion`` (x, y, z, w), ``velocity`` [m/s], ``angular_velocity``
        [rad/s] (3-vectors), ``mass`` [kg], ``momentum`` [N s]."""
        q, qd = self.state.body_q.numpy().astype(np.float64), self.state.body_qd.numpy().astype(np.float64)  # pyright: ignore[reportOptionalMemberAccess]
        mass = self.newton.body_mass.numpy().astype(np.float64)  # pyright: ignore[reportOptionalMemberAccess]
        return dict(position=q[:, :3], quaternion=q[:, 3:], velocity=qd[:, :3], angular_velocity=qd[:, 3:],
                    mass=mass, momentum=mass[:, None] * qd[:, :3])
