"""Joints: rigid bodies (mpm.rigid) hinged to the world or to one another,
enforced by Newton.

A :class:`Joint` holds its ``child``, a rigid body (its index in
``Scene.rigid_bodies`` or its name), to its ``parent`` (another rigid body,
or None: the world) at ``anchor`` [m], a point given in world coordinates at
the bodies' initial pose. ``type``:

* ``revolute``: a hinge, one rotation about the ``axis`` through the anchor
  (2D: about z, ``axis`` null; 3D: ``axis`` a direction in world
  coordinates at the initial pose, carried with the parent);
* ``ball`` (3D): the anchor held, any rotation about it;
* ``prismatic``: a slider, one translation along ``axis`` (``dim``
  numbers, a direction in world coordinates at the initial pose, carried
  with the parent), no rotation relative to the parent;
* ``fixed``: the child welded to its parent (or held still in the world).

``Scene.joints`` lists them (default none). The joints form trees: each body
is the child of at most one joint and no chain of parents comes back to
itself. A child's initial ``velocity`` follows from its parent's motion and
must be left out (prismatic: its rate relative to the parent, along the
axis); its ``angular_velocity`` is its rate relative to the parent
(revolute: along the axis; ball: any; prismatic and fixed: none).

A scene with joints builds a Newton model with one articulation per tree
(mpm.joints.articulated_model): each joint's child a link of its parent;
a body no joint holds, or the root of a tree of bodies, joined to the world
by a free joint (3D) or a planar one (2D: x, y and the rotation about z), so
2D bodies stay in the plane exactly. Newton's SolverFeatherstone advances it
in reduced coordinates, so the joints hold by construction (to the float32
rounding of the state), with the material's wrench in ``state.body_f``
(mpm.rigid_coupling; no damping, no joint limit or drive).

The step: Newton's solvers take it as a Python float, while the driver
chooses it on the device (mpm.stepping.policy). A scene with joints reads it
back once per step, after G2P: one float64 copied to the host per step
(``Coupler.reads`` counts them; 0 where the driver skips the step), then
Newton steps by it; the steps of a batch otherwise run as before. That read
cannot sit in a CUDA graph: the Driver does not capture one for a scene with
joints (``graph=True`` is refused). A scene whose rigid bodies meet the
walls or one another (mpm.rigid_contact) takes the same path, with
collision shapes and Newton's collision pipeline. Scenes without joints or
rigid contact keep the device-only path (mpm.rigid_coupling).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

JOINT_TYPES = ("revolute", "ball", "prismatic", "fixed")
"""the kinds of joint (ball: 3D only)"""


@dataclass(frozen=True)
class Joint:
    """One joint (module docstring): ``child`` and ``parent`` a rigid body's
    index or name (parent None: the world), ``anchor`` [m] in world
    coordinates at the initial pose, ``axis`` the 3D revolute's or the
    prismatic's direction (world coordinates at the initial pose; else None)."""

    child: int | str
    """the rigid body the joint holds (an index in Scene.rigid_bodies, or a name)"""
    anchor: Sequence[float]
    """the joint's point [m], world coordinates at the initial pose"""
    type: str = "revolute"
    """revolute, ball (3D), prismatic or fixed (JOINT_TYPES)"""
    parent: int | str | None = None
    """the rigid body it is held to (index or name); None: the world"""
    axis: Sequence[float] | None = None
    """3D revolute: the hinge's direction (3 numbers, any length > 0); prismatic: the slide's (dim
    numbers); else None"""
    name: str = ""
    """a name for reports"""


def _body(value, names: list[str]) -> int | None:
    """The rigid body ``value`` names (an index or a name), or None."""
    if isinstance(value, str):
        return names.index(value) if value in names else None
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool) and 0 <= value < len(names):
        return int(value)
    return None


def _vector(value, size: int) -> np.ndarray | None:
    """``value`` as ``size`` finite numbers, or None."""
    try:
        v = np.asarray(value, float)
    except (TypeError, ValueError):
        return None
    return v if v.shape == (size,) and np.all(np.isfinite(v)) else None


def resolved(scene) -> list[tuple[int, int]]:
    """(child, parent) of each joint as rigid-body indices (parent -1: the world); after
    :func:`scene_problems` found none."""
    names = [b.name or f"rigid{i}" for i, b in enumerate(scene.rigid_bodies)]
    out = []
    for j in scene.joints:
        child = _body(j.child, names)
        parent = -1 if j.parent is None else _body(j.parent, names)
        assert child is not None and parent is not None, "scene_problems: a joint's bodies"
        out.append((child, parent))
    return out


def scene_problems(scene) -> list[tuple[str, str]]:
    """(key, message) for each joint that cannot be used (module docstring):
    an unknown type, a child or parent that is no rigid body, a body held by
    two joints, a loop, an anchor that is not a point of the domain, an axis
    that is not a direction (or given where none is used), a child given a
    velocity or (revolute, 3D) an angular velocity off its axis."""
    joints = getattr(scene, "joints", None) or []
    if not joints:
        return []
    dim, bodies = scene.dim, list(getattr(scene, "rigid_bodies", None) or [])
    names = [b.name or f"rigid{i}" for i, b in enumerate(bodies)]
    which = (f"a rigid body's index (0 to {len(bodies) - 1}) or name ({', '.join(names)})" if bodies
             else "a rigid body, but the scene has none (rigid_bodies)")
    kinds = JOINT_TYPES if dim == 3 else tuple(k for k in JOINT_TYPES if k != "ball")
    box = " x ".join(f"[0, {L:g}]" for L in scene.domain)
    out: list[tuple[str, str]] = []
    held: dict[int, int] = {}  # child -> its joint
    links: dict[int, int] = {}  # child -> parent (-1: the world)
    for i, j in enumerate(joints):
        key = f"joints[{i}]"
        if not isinstance(j, Joint):
            out.append((key, f"{type(j).__name__}; accepted: mpm.Joint"))
            continue
        if j.type not in kinds:
            out.append((f"{key}.type", f"{j.type!r}; accepted: {', '.join(kinds)}"
                                       + (" (in 2D; ball in 3D)" if dim == 2 else "")))
        child = _body(j.child, names)
        if child is None:
            out.append((f"{key}.child", f"{j.child!r} is no rigid body; accepted: {which}"))
        elif child in held:
            out.append((f"{key}.child", f"{j.child!r} is already the child of joints[{held[child]}]; accepted: "
                                        "each rigid body the child of one joint at most"))
        parent = -1 if j.parent is None else _body(j.parent, names)
        if parent is None:
            out.append((f"{key}.parent", f"{j.parent!r} is no rigid body; accepted: null (the world) or {which}"))
        elif child is not None and parent == child:
            out.append((f"{key}.parent", f"{j.parent!r} is the child itself; accepted: null (the world) or "
                                         "another rigid body"))
        if child is not None and child not in held:
            held[child] = i
            if parent is not None and parent != child:
                links[child] = parent
        anchor = _vector(j.anchor, dim)
        if anchor is None:
            out.append((f"{key}.anchor", f"{j.anchor!r}; accepted: {dim} finite numbers [m]"))
        elif not all(0.0 <= x <= L for x, L in zip(anchor, scene.domain)):
            out.append((f"{key}.anchor", f"{list(j.anchor)} lies outside the domain; accepted: a point in {box} [m]"))
        slide = j.type == "prismatic"
        if not (slide or (j.type == "revolute" and dim == 3)):
            if j.axis is not None:
                why = {"ball": "a ball", "fixed": "a fixed joint"}.get(j.type, "about z in 2D")
                out.append((f"{key}.axis", f"{j.axis!r}; accepted: null ({why})"))
        else:
            axis = _vector(j.axis, dim) if j.axis is not None else None
            if axis is None or not np.linalg.norm(axis) > 0.0:
                out.append((f"{key}.axis", f"{j.axis!r}; accepted: {dim} finite numbers, not all 0 (the "
                                           f"{'slide' if slide else 'hinge'}'s direction)"))
            elif slide and child is not None and child < len(bodies) and bodies[child].velocity is not None:
                v = np.asarray(bodies[child].velocity, float)
                if np.linalg.norm(v - (v @ axis) / (axis @ axis) * axis) > 1e-9 * max(np.linalg.norm(v), 1.0):
                    out.append((f"rigid_bodies[{child}].velocity",
                                f"{bodies[child].velocity!r} is not along joints[{i}].axis; accepted: a multiple "
                                "of the axis (the rate along the slide), or null"))
            elif not slide and child is not None and child < len(bodies) and bodies[child].angular_velocity is not None:
                w = np.asarray(bodies[child].spin(dim), float)
                if np.linalg.norm(np.cross(w, axis)) > 1e-9 * max(np.linalg.norm(w), 1.0) * np.linalg.norm(axis):
                    out.append((f"rigid_bodies[{child}].angular_velocity",
                                f"{bodies[child].angular_velocity!r} is not along joints[{i}].axis; accepted: a "
                                "multiple of the axis (the rate about the hinge)"))
        if child is not None and child < len(bodies) and bodies[child].velocity is not None and not slide:
            out.append((f"rigid_bodies[{child}].velocity", f"{bodies[child].velocity!r} on the child of joints[{i}]; "
                                                           "accepted: null (it follows from the parent's motion)"))
        if (child is not None and child < len(bodies) and j.type in ("prismatic", "fixed")
                and bodies[child].angular_velocity is not None and np.any(bodies[child].spin(dim) != 0.0)):
            out.append((f"rigid_bodies[{child}].angular_velocity",
                        f"{bodies[child].angular_velocity!r} on the child of a {j.type} joints[{i}]; accepted: "
                        "null (it turns with its parent)"))
    for child in links:  # a chain of parents must reach the world or a body no joint holds
        seen, b = {child}, links[child]
        while b in links:
            if b in seen:
                out.append((f"joints[{held[child]}].parent", "closes a loop of joints; accepted: joints that form "
                                                             "trees (no body its own ancestor)"))
                break
            seen.add(b)
            b = links[b]
        else:
            continue
        break
    return out


def articulated_model(scene, device):
    """The Newton model of a scene with joints (module docstring) and its
    initial generalized state: (model, joint_q, joint_qd), every joint's
    coordinates 0 at the initial pose (each joint's frames aligned with the
    world there), its rates from the bodies' initial motion."""
    import newton
    import warp as wp

    from . import rigid_contact
    from .colliders import rotation_of
    from .rigid_model import add_shape, quaternion

    dim = scene.dim
    builder = newton.ModelBuilder(gravity=tuple(scene.gravity) + (0.0,) * (3 - dim))
    Cfg = newton.ModelBuilder.JointDofConfig
    bodies = scene.rigid_bodies
    centres = [np.pad(b.center(), (0, 3 - dim)) for b in bodies]
    turns = [quaternion(b.turned(dim)) for b in bodies]
    mode = getattr(scene, "rigid_contact", "none")
    contact = None if mode == "none" else rigid_contact.shape_config(scene)
    shapes = []
    for i, b in enumerate(bodies):
        link = builder.add_link(xform=wp.transform(tuple(centres[i]), wp.quat(*turns[i])), label=b.name or f"rigid{i}")
        shapes.append(add_shape(builder, link, b, dim, contact))
    if mode != "none":
        rigid_contact.add_walls(builder, scene)
    if mode == "walls":
        rigid_contact.filter_bodies(builder, shapes)

    def frame(body: int, point: np.ndarray):
        """The frame at ``point`` aligned with the world, in ``body``'s frame at its initial pose (-1: the
        world's)."""
        if body < 0:
            return wp.transform(tuple(point), wp.quat_identity())
        inverse = (-turns[body][0], -turns[body][1], -turns[body][2], turns[body][3])
        local = rotation_of(bodies[body].turned(dim), 3).T @ (point - centres[body])  # R^T (p - c)
        return wp.transform(tuple(local), wp.quat(*inverse))

    links = resolved(scene)
    children: dict[int, list[int]] = {}
    for k, (_, parent) in enumerate(links):
        children.setdefault(parent, []).append(k)
    held = {child: k for k, (child, _) in enumerate(links)}
    q: list[float] = []
    qd: list[float] = []

    def add(k: int) -> int:
        """Joint ``k`` of the scene, its coordinates and rates; its Newton index."""
        j, (child, parent) = scene.joints[k], links[k]
        anchor = np.pad(np.asarray(j.anchor, float), (0, 3 - dim))
        pf, cf, label = frame(parent, anchor), frame(child, anchor), j.name or f"joint{k}"
        w = bodies[child].spin(dim)
        if j.type == "fixed":
            return builder.add_joint_fixed(parent, child, parent_xform=pf, child_xform=cf, label=label)
        if j.type == "prismatic":
            axis = np.pad(np.asarray(j.axis, float), (0, 3 - dim))
            axis = axis / np.linalg.norm(axis)
            v = np.pad(np.asarray(bodies[child].velocity or (0.0,) * dim, float), (0, 3 - dim))
            q.append(0.0)
            qd.append(float(v @ axis))
            return builder.add_joint_prismatic(parent, child, axis=wp.vec3(*axis), parent_xform=pf, child_xform=cf,
                                               label=label)
        if j.type == "ball":
            q.extend((0.0, 0.0, 0.0, 1.0))
            qd.extend(w)
            return builder.add_joint_ball(parent, child, parent_xform=pf, child_xform=cf, label=label)
        axis = np.array([0.0, 0.0, 1.0]) if dim == 2 else np.asarray(j.axis, float)
        axis = axis / np.linalg.norm(axis)
        q.append(0.0)
        qd.append(float(w @ axis))
        return builder.add_joint_revolute(parent, child, axis=wp.vec3(*axis), parent_xform=pf, child_xform=cf,
                                          label=label)

    def tree(body: int, out: list[int]) -> None:
        for k in children.get(body, []):
            out.append(add(k))
            tree(links[k][0], out)

    for root in range(len(bodies)):
        if root in held and links[held[root]][1] >= 0:
            continue  # held by another body: in its parent's tree
        if root in held:  # hinged to the world
            joints = [add(held[root])]
        else:  # free: planar in 2D (x, y, the rotation about z), else 6 degrees of freedom
            v = np.pad(np.asarray(bodies[root].velocity or (0.0,) * dim, float), (0, 3 - dim))
            w = bodies[root].spin(dim)
            pf, cf = frame(-1, centres[root]), frame(root, centres[root])
            if dim == 2:
                q.extend((0.0, 0.0, 0.0))
                qd.extend((v[0], v[1], w[2]))
                joints = [builder.add_joint_d6(-1, root, linear_axes=[Cfg(axis=newton.Axis.X), Cfg(axis=newton.Axis.Y)],
                                               angular_axes=[Cfg(axis=newton.Axis.Z)], parent_xform=pf,
                                               child_xform=cf)]
            else:
                q.extend((0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
                qd.extend((*v, *w))
                joints = [builder.add_joint_free(root, parent_xform=pf, child_xform=cf)]
        tree(root, joints)
        builder.add_articulation(joints)
    return builder.finalize(device=device), np.array(q, np.float32), np.array(qd, np.float32)


class Articulation:
    """A scene's rigid bodies, joints and (mpm.rigid_contact) contact in Newton (module docstring):
    ``model``, ``state`` (``joint_q``, ``joint_qd``: the generalized state;
    ``body_q``, ``body_qd``: the bodies' poses and velocities from it;
    ``body_f``: the wrench on each body over the step, world frame, at its
    centre of mass), advanced by :meth:`step`."""

    def __init__(self, scene, device):
        import newton

        self.model, q, qd = articulated_model(scene, device)
        self.state = self.model.state()
        assert self.state.joint_q is not None and self.state.joint_qd is not None
        self.state.joint_q.assign(q)
        self.state.joint_qd.assign(qd)
        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)
        self.solver = newton.solvers.SolverFeatherstone(self.model, angular_damping=0.0)
        self.control = self.model.control()
        # contact (mpm.rigid_contact): Newton's collision pipeline, run at each step's start
        self.pipeline = newton.CollisionPipeline(self.model) if getattr(scene, "rigid_contact", "none") != "none" \
            else None
        self.contacts = self.pipeline.contacts() if self.pipeline is not None else None

    def step(self, dt: float) -> None:
        """Advance by ``dt`` [s] with the wrench in ``state.body_f``, gravity and (mpm.rigid_contact) the
        contacts found at the step's start (in place)."""
        if self.pipeline is not None:
            self.pipeline.collide(self.state, self.contacts)  # pyright: ignore[reportArgumentType]
        self.solver.step(self.state, self.state, self.control, self.contacts, dt)  # pyright: ignore[reportArgumentType]
