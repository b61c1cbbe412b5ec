"""The rigid bodies of a scene (mpm.rigid) coupled both ways to the material
through Newton, a stage of the step only where a scene has any.

:class:`Coupler` builds a Newton model of the bodies (one free body each,
its origin the centre of mass, its mass and inertia from a box, sphere,
cylinder or mesh shape of the body's density; 2D: the shape one metre deep,
a sphere a disc, a cylinder along z) and holds its state (``body_q``: the pose, ``body_qd``: the velocity of the
centre of mass and the angular velocity, world frame). Each step, on the
device and with no read-back:

* :meth:`Coupler.place`, at the step's start: each body's collider record
  (rigid body b is collider ``len(scene.colliders) + b``) takes the pose and
  the velocities of the Newton state at the step's time ``control.t``
  (mpm.collider_motion places it at any time of the step from them), and
  the fastest point of each body's surface, |v| + |omega| reach, enters
  the step's largest speed (``status.max_v2``) that the step rule reads
  for the next step, and its reach (``reach`` in the record, for
  mpm.collider_motion.make_beyond);
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
at the step's start, the body answers after the step (every scheme and
kernel). Under the implicit integrator (mpm.implicit) the body is one of
the solve's colliders, held at that pose and velocity during the whole
solve (its normal constraints and, mpm.implicit.rough, Coulomb friction act
with the surface velocity v + omega x r of the step's start; it holds the
nodes in contact only, not the deeper ones, mpm.collider_device
``make_constrain``); the reactions of the solution at the nodes it holds
(the residual m (v - v*) + dt sum S g on their fixed directions), a sliding
node's friction load, the boundary pass after the solve and the keep-out
are its impulse J and angular impulse (q - c) x J about its centre c (q
the node, mpm.implicit.system ``make_boundary_work``), and the body answers
after the solve as under the explicit one. The Newton solve's residual on
the free directions (its tolerance) is momentum the body does not see. 2D
bodies stay in the plane: the forces have no z component, the torques only
a z one, and the out-of-plane components of the state are zeroed after
each step.
"""


import functools

import numpy as np
import warp as wp

from .collider_shapes import make_collider_data
from .launch import warp_kernel
from .rigid_model import newton_model
from .stepping.status import StepControl
from .types import Types


@functools.cache
def make_place_bodies(t: Types):
    """Kernel: rigid body b's collider record (index ``first + b``) from the
    Newton state at the step's time (module docstring)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    V3, W2, dim = wp.types.vector(3, S), wp.types.vector(2, S), t.dim

    @warp_kernel
    def place_bodies(body_q: wp.array(dtype=wp.transform), body_qd: wp.array(dtype=wp.spatial_vector),
                     control: StepControl, first: int, colliders: wp.array(dtype=Data),
                     reach: wp.array(dtype=wp.float64), max_v2: wp.array(dtype=wp.float64)):
        b = wp.tid()
        if control.skip[0] != wp.float64(0.0):
            return
        # the fastest point of its surface, |v| + |omega| reach, for the step rule (as a particle's speed)
        fastest = wp.float64(wp.length(wp.spatial_top(body_qd[b]))) + wp.float64(
            wp.length(wp.spatial_bottom(body_qd[b]))) * reach[b]
        wp.atomic_max(max_v2, 0, fastest * fastest)
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
        c.reach = S(reach[b])
        colliders[k] = c

    return place_bodies


@functools.cache
def make_material_wrench(t: Types):
    """``material_wrench(k, dt, n_grids, impulse, torque)``: collider ``k``'s
    wrench on its body over the step ``dt`` [s], minus the material's impulse
    and angular impulse (summed over the kernel's ``n_grids`` grids) as a mean
    force [N] and torque [N m] (a spatial vector, float32 as Newton's state)."""
    dim = t.dim

    @wp.func
    def material_wrench(k: int, dt: wp.float64, n_grids: float, impulse: wp.array(dtype=wp.float64),
                        torque: wp.array(dtype=wp.float64)):
        per = wp.float64(-1.0) / (wp.float64(n_grids) * dt)  # minus the material's share, as a mean force
        f = wp.vec3()
        tau = wp.vec3()
        for d in range(wp.static(dim)):
            f[d] = float(impulse[k * dim + d] * per)
        for a in range(3):
            tau[a] = float(torque[3 * k + a] * per)
        return wp.spatial_vector(f, tau)  # pyright: ignore[reportArgumentType]

    return material_wrench


@functools.cache
def make_push_bodies(t: Types):
    """Kernel: each rigid body advanced by Newton's integrator over the
    step ``control.dt`` with minus the material's impulse and angular
    impulse (module docstring); 2D: the out-of-plane components zeroed."""
    from newton._src.solvers.solver import integrate_rigid_body

    dim = t.dim
    material_wrench = make_material_wrench(t)

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
        dt = control.dt[0]
        wrench = material_wrench(first + b, dt, n_grids, impulse, torque)  # pyright: ignore[reportOperatorIssue]
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


@functools.cache
def make_wrench(t: Types):
    """Kernel (scenes with joints, mpm.joints): each body's ``body_f``, minus
    the material's impulse and angular impulse over the step as a force and
    a torque (as :func:`make_push_bodies` takes them), and the step into
    ``clock[0]`` for the host (0 where the driver skips it)."""
    material_wrench = make_material_wrench(t)

    @warp_kernel
    def wrench(control: StepControl, first: int, n_grids: float, impulse: wp.array(dtype=wp.float64),
               torque: wp.array(dtype=wp.float64), body_f: wp.array(dtype=wp.spatial_vector),
               clock: wp.array(dtype=wp.float64)):
        b = wp.tid()
        if control.skip[0] != wp.float64(0.0):
            if b == 0:
                clock[0] = wp.float64(0.0)
            return
        dt = control.dt[0]
        body_f[b] = material_wrench(first + b, dt, n_grids, impulse, torque)  # pyright: ignore[reportOperatorIssue]
        if b == 0:
            clock[0] = dt

    return wrench


class Coupler:
    """``model``'s rigid bodies in Newton and the two stages of a step that
    couple them to the material (module docstring): :meth:`place` before the
    grid update (mpm.conditions.Conditions.update_grid), :meth:`push` after
    G2P (mpm.transfer.Transfers.interpolate); ``conditions`` holds the
    packed records, the angular impulses and the step's recorded launches
    (``conditions.launch``, mpm.launch.Launches, which both stages use),
    ``control`` the step's clock.
    ``newton``: the Newton model; ``state``: its state (``body_q``,
    ``body_qd``, also named here for checkpoints; ``body_f`` the wrench the
    material applied over the last step). A scene with joints (mpm.joints)
    or rigid contact (mpm.rigid_contact) has ``joints``, the
    :class:`mpm.joints.Articulation` that Newton's
    Featherstone solver advances (its generalized state ``joint_q``,
    ``joint_qd`` named here too), and reads each step back once
    (``reads``); else ``joints`` is None and nothing is read."""

    def __init__(self, model, conditions, control):
        t, scene = model.types, model.scene
        self.model, self.conditions, self.control = model, conditions, control
        self.first = len(scene.colliders)
        self.n = len(scene.rigid_bodies)
        self.place_kernel = make_place_bodies(t)
        if getattr(scene, "joints", None) or getattr(scene, "rigid_contact", "none") != "none":
            from .joints import Articulation

            self.joints = Articulation(scene, model.device)
            self.newton, self.state = self.joints.model, self.joints.state
            self.push_kernel = make_wrench(t)
            self.clock = wp.zeros(1, dtype=wp.float64, device=model.device)  # the step, for the host [s]
            self.reads = 0  # steps read back to the host
            self.joint_q, self.joint_qd = self.state.joint_q, self.state.joint_qd
        else:
            self.joints = None
            self.newton = newton_model(scene, model.device)
            self.state = self.newton.state()
            spins = [b.spin(scene.dim) for b in scene.rigid_bodies]
            speeds = [tuple(b.velocity or ()) + (0.0,) * (3 - len(b.velocity or ())) for b in scene.rigid_bodies]
            self.state.body_qd.assign(np.array([tuple(v) + tuple(w) for v, w in zip(speeds, spins)], np.float32))  # pyright: ignore[reportOptionalMemberAccess]
            self.push_kernel = make_push_bodies(t)
        # the state's arrays, named here so that a checkpoint (mpm.checkpoint) holds them
        self.body_q, self.body_qd = self.state.body_q, self.state.body_qd
        self.reach = wp.array([b.reach(scene.dim) for b in scene.rigid_bodies], dtype=wp.float64,
                              device=model.device)  # [m] each body's surface from its centre of mass

    @property
    def reads_step(self) -> bool:
        """Whether each step is read back to the host (a scene with joints: mpm.joints)."""
        return self.joints is not None

    def kernels(self) -> list:
        return [self.place_kernel, self.push_kernel]

    def place(self, status) -> None:
        """The bodies' collider records from their state at the step's start;
        the fastest point of their surfaces in the step's largest speed
        (``status.max_v2``, which the step rule reads as it reads the particles')."""
        data = self.conditions.data
        self.conditions.launch(self.place_kernel, self.n, [
            self.state.body_q, self.state.body_qd, self.control, self.first, data.colliders, self.reach,
            status.max_v2])

    def speed(self) -> float:
        """[m/s] the fastest point of the bodies' surfaces at the start (mpm.rigid.RigidBody.surface_speed)."""
        scene = self.model.scene
        return max(b.surface_speed(scene.dim) for b in scene.rigid_bodies)

    def push(self, status) -> None:
        """The bodies advanced over the step with minus the material's impulse
        and angular impulse (``status.collider_impulse``, ``collider_torque``,
        mpm.stepping.status), plus gravity: by Newton's integrator on the
        device, or (joints) by Newton's Featherstone solver over the step
        read back (none where the driver skips it)."""
        nm = self.newton
        if self.joints is not None:
            self.conditions.launch(self.push_kernel, self.n, [
                self.control, self.first, float(self.model.kernel.n_grids), status.collider_impulse,
                status.collider_torque, self.state.body_f, self.clock])
            dt = float(self.clock.numpy()[0])
            self.reads += 1
            if dt > 0.0:
                self.joints.step(dt)
            return
        self.conditions.launch(self.push_kernel, self.n, [
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

    def energies(self, poses: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Per body, from its Newton state (``poses``: :meth:`poses`, read
        now where None) [J; 2D: J/m, the body one metre deep]: ``kinetic``,
        the translation's 1/2 m |v|^2; ``rotational``, 1/2 w . I w with w the
        angular velocity in the body's frame (R^T omega, R its orientation)
        and I its inertia about the centre of mass there (Newton's
        ``body_inertia``); ``potential``, -m g . x (x the centre of mass:
        zero at the origin, as the material's, mpm.diagnostics)."""
        p = self.poses() if poses is None else poses
        g = np.zeros(3)
        g[:self.model.dim] = self.model.scene.gravity
        inertia = self.newton.body_inertia.numpy().astype(np.float64)  # pyright: ignore[reportOptionalMemberAccess]
        u, w = -p["quaternion"][:, :3], p["quaternion"][:, 3:]  # the inverse rotation's (x, y, z) and w
        omega = p["angular_velocity"]
        t = 2.0 * np.cross(u, omega)
        body = omega + w * t + np.cross(u, t)  # R^T omega
        m = p["mass"]
        return dict(kinetic=0.5 * m * np.sum(p["velocity"] ** 2, axis=1),
                    rotational=0.5 * np.einsum("bi,bij,bj->b", body, inertia, body),
                    potential=-m * (p["position"] @ g))
