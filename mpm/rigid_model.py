"""The Newton model of a scene's free rigid bodies (mpm.rigid): each body's
shape, of the body's density, on a Newton body whose origin is its centre of
mass (2D: the shape one metre deep, a sphere a disc, a cylinder along z; a
mesh by its vertices about its centroid), for mpm.rigid_coupling and, with
joints, mpm.joints."""

import numpy as np
import warp as wp


def quaternion(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation vector [rad]."""
    theta = float(np.linalg.norm(rotation))
    if theta == 0.0:
        return (0.0, 0.0, 0.0, 1.0)
    axis = np.asarray(rotation, float) / theta
    s = np.sin(0.5 * theta)
    return (axis[0] * s, axis[1] * s, axis[2] * s, float(np.cos(0.5 * theta)))


def add_shape(builder, body: int, b, dim: int, contact=None) -> int:
    """Rigid body ``b``'s shape on the Newton body ``body``, of the body's
    density (its mass and inertia; module docstring); no collision, or that
    of ``contact`` (a ShapeConfig, mpm.rigid_contact). Its shape index."""
    import newton

    c = b.shape
    density = b.total_mass(dim) / b.volume(dim)
    if contact is None:
        cfg = newton.ModelBuilder.ShapeConfig(density=density, has_shape_collision=False, has_particle_collision=False)
    else:
        cfg = contact.copy()
        cfg.density = density
    if c.type == "box":
        h = tuple(c.half_size) + (0.5,) * (3 - dim)  # (2D: one metre deep)
        return builder.add_shape_box(body, hx=h[0], hy=h[1], hz=h[2], cfg=cfg)
    if c.type == "sphere" and dim == 2:
        return builder.add_shape_cylinder(body, radius=c.radius, half_height=0.5, cfg=cfg)  # a disc, along z
    if c.type == "sphere":
        return builder.add_shape_sphere(body, radius=c.radius, cfg=cfg)
    if c.type == "mesh":  # its vertices about the body's origin, the centroid (mpm.rigid.RigidBody.center)
        assert c.mesh is not None  # mpm.rigid.RigidBody.problems checks
        pts, tris = c.mesh.geometry
        mesh = newton.Mesh((pts - b.center()).astype(np.float32), tris.reshape(-1))
        return builder.add_shape_mesh(body, mesh=mesh, cfg=cfg)
    from .colliders import axis_vector

    turn = wp.quat_between_vectors(wp.vec3(0.0, 0.0, 1.0), wp.vec3(*axis_vector(c.axis, 3)))
    return builder.add_shape_cylinder(body, xform=wp.transform((0.0, 0.0, 0.0), turn), radius=c.radius,
                                      half_height=c.half_height, cfg=cfg)


def newton_model(scene, device):
    """The Newton model of ``scene``'s rigid bodies, each a free body
    (module docstring), with its gravity (2D: in the plane)."""
    import newton

    dim = scene.dim
    gravity = tuple(scene.gravity) + (0.0,) * (3 - dim)
    builder = newton.ModelBuilder(gravity=gravity)
    for i, b in enumerate(scene.rigid_bodies):
        centre = tuple(b.center()) + (0.0,) * (3 - dim)
        body = builder.add_body(xform=wp.transform(centre, wp.quat(*quaternion(b.turned(dim)))),
                                label=b.name or f"rigid{i}")
        add_shape(builder, body, b, dim)
    return builder.finalize(device=device)
