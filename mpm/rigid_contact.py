"""Contact of rigid bodies (mpm.rigid) with the domain's walls and with one
another, through Newton's collision pipeline.

``Scene.rigid_contact`` (:data:`RIGID_CONTACTS`): ``none`` (the default: a
body meets only the material and its joints), ``walls`` (each closed wall,
as a Newton plane at its face, ``wall_cells`` cells inside the domain's
face: mpm.walls) or ``all`` (the walls, and the bodies one another; two
bodies a joint holds together do not collide). Open walls have no plane.

Newton's contact is a penalty one: each contact point pushes with
``rigid_contact_stiffness`` ke [N/m per point; 2D: per metre of depth] times
its penetration and ``rigid_contact_damping`` kd [N s/m] times its closing
speed, frictionless (walls are frictionless too). A body at rest on a
floor sinks by m g / (n ke) with n its contact points (a fraction of a
millimetre at the defaults for a body of 10 kg per metre); the penalty is
explicit, stable while dt sqrt(n ke / m) and dt n kd / m stay well below 2
(the defaults and one point: dt below about 2 ms for 1 kg; not checked
before the run). A scene with
contact is advanced as a scene with joints is (mpm.joints: Newton's
Featherstone solver, the step read back once per step), after Newton's
collision pipeline finds the contacts at the step's start.
"""

from __future__ import annotations

import numpy as np
import warp as wp

RIGID_CONTACTS = ("none", "walls", "all")
"""what rigid bodies meet besides the material: nothing, the closed walls, or the walls and each other"""


def scene_problems(scene) -> list[tuple[str, str]]:
    """(key, message) for a contact mode or penalty that cannot be used."""
    out = []
    mode = getattr(scene, "rigid_contact", "none")
    if mode not in RIGID_CONTACTS:
        out.append(("rigid_contact", f"{mode!r}; accepted: {', '.join(RIGID_CONTACTS)}"))
    for key, low in (("rigid_contact_stiffness", "> 0"), ("rigid_contact_damping", ">= 0")):
        value = getattr(scene, key, 1.0)
        ok = isinstance(value, (int, float)) and np.isfinite(value) and (value > 0 if low == "> 0" else value >= 0)
        if not ok:
            out.append((key, f"{value!r}; accepted: a finite number {low}"))
    return out


def shape_config(scene):
    """Newton's shape settings of a body that collides (penalty, frictionless; mass from its density is
    set per body)."""
    import newton

    return newton.ModelBuilder.ShapeConfig(ke=float(scene.rigid_contact_stiffness),
                                           kd=float(scene.rigid_contact_damping), kf=0.0, mu=0.0,
                                           has_particle_collision=False)


def add_walls(builder, scene) -> None:
    """A Newton plane at each closed wall's face, its normal into the domain (2D: the x and y faces)."""
    dx = scene.dx
    cfg = shape_config(scene)
    for face, kind in enumerate(scene.walls):
        if kind == "open":
            continue
        axis, high = divmod(face, 2)
        at = scene.domain[axis] - scene.wall_cells * dx if high else scene.wall_cells * dx
        # the plane's frame: its local z the normal into the domain, its origin on the face
        sign = -1.0 if high else 1.0
        normal = wp.vec3(*(sign if a == axis else 0.0 for a in range(3)))
        turn = (wp.quat(1.0, 0.0, 0.0, 0.0) if axis == 2 and high  # (z onto -z: half a turn about x)
                else wp.quat_between_vectors(wp.vec3(0.0, 0.0, 1.0), normal))
        origin = wp.vec3(*(at if a == axis else 0.0 for a in range(3)))
        builder.add_shape_plane(plane=None, xform=wp.transform(origin, turn), width=0.0, length=0.0, cfg=cfg,
                                label=f"wall{face}")


def filter_bodies(builder, shapes: list[int]) -> None:
    """No contact between the bodies' shapes (``walls``: they meet only the walls)."""
    for i, a in enumerate(shapes):
        for b in shapes[i + 1:]:
            builder.add_shape_collision_filter_pair(a, b)
