"""Particles kept out of the solids, at the end of G2P (the surface rule,
mpm.surface).

The grid rule holds a body where it touches a wall or a collider, but a
particle on its own - a drop of a splash, a particle in a sheet a cell
thin - fills too little of any node for the rule to see it, and a moving
collider can overrun a particle between two steps. A particle whose new
position x lies inside a solid (signed distance phi(x) < 0, the solid at
the step's end) is put back on its surface, x <- x - phi n, and loses the
part of its velocity into the solid relative to the solid's velocity u
(all of it relative to a sticky collider). The impulse m (v' - v) joins the
conditions' (``boundary_impulse``, and a collider's ``collider_impulse``, as
on every kernel grid; where the scene has rigid bodies, also its angular
impulse about the collider's centre, r x m (v' - v), mpm.rigid_coupling). A body in
contact leans on the grid rule and keeps its particles outside, so this
acts only on those the rule missed. Under the node rule (earlier versions)
nothing is compiled. Elastic colliders (mpm.elastic_contact) hold their
particles by springs, whose rest may lie a little inside: they are left out.

A particle farther from a rigid body's centre of mass than 1.01 times the
body's reach (its surface's farthest point from there, ``reach`` in its
record, mpm.rigid.RigidBody.reach; mpm.collider_motion.make_beyond) is
outside the body: it is not placed against it (a turning body's placement
costs four rotations a particle), which changes no result, since only a
particle inside (phi < 0) is acted on.
"""

import functools

import warp as wp

from .collider_device import SPRINGS, STICKY, make_add_impulse, make_add_torque
from .collider_motion import make_beyond, make_centre, make_place
from .colliders import ELASTIC, RIGID
from .grid import make_boundary_data
from .scene import WALL_TYPES
from .stepping.status import StepStatus
from .types import Types

OPEN = WALL_TYPES.index("open")


@functools.cache
def make_keep_out(t: Types, kinds: tuple[str, ...], n_grids: int):
    """``keep_out(x, v, m, time, data, inside_lo, inside_hi, status) -> (x',
    v')``: the particle at ``x`` with velocity ``v`` and mass ``m`` put back
    on the surface of every closed wall (unless it went beyond the interior's
    bound ``inside_lo``, ``inside_hi``: through the wall) and every collider
    (the shapes ``kinds``) it lies behind at ``time`` (module docstring)."""
    S, vec = t.scalar, t.vec
    f64 = wp.float64
    Data = make_boundary_data(t)
    place = make_place(t, kinds)
    add_impulse, add_torque, centre = make_add_impulse(t), make_add_torque(t), make_centre(t)
    beyond = make_beyond(t)

    @wp.func
    def put_back(x: vec, v: vec, phi: S, n: vec, u: vec, sticky: bool):
        x = x - phi * n
        if sticky:
            return x, u
        vn = wp.dot(v - u, n)
        if vn < S(0.0):
            v = v - vn * n
        return x, v

    @wp.func
    def keep_out(x: vec, v: vec, m: S, time: S, data: Data, inside_lo: vec, inside_hi: vec, status: StepStatus):
        v0 = v
        for d in range(wp.static(t.dim)):
            n = vec()
            n[d] = S(1.0)
            # (beyond the interior's bound a particle has gone through the wall: G2P counts it outside)
            if data.wall_lo[d] != OPEN and x[d] < data.face_lo[d] and x[d] >= inside_lo[d]:
                x, v = put_back(x, v, x[d] - data.face_lo[d], n, vec(), False)
            if data.wall_hi[d] != OPEN and x[d] > data.face_hi[d] and x[d] <= inside_hi[d]:
                x, v = put_back(x, v, data.face_hi[d] - x[d], -n, vec(), False)
        if wp.static(len(kinds) > 0):
            for k in range(data.colliders.shape[0]):
                c = data.colliders[k]
                if wp.static(ELASTIC in kinds):
                    if c.boundary == SPRINGS:
                        continue  # its springs hold the particles (mpm.elastic_contact)
                if wp.static(RIGID in kinds):
                    if c.body != 0:  # a rigid body: a particle beyond its reach is outside (module docstring)
                        if beyond(c, x, time, S(0.0)):
                            continue
                phi, n, u = place(c, x, time)
                if phi < S(0.0):
                    v_in = v
                    x, v = put_back(x, v, phi, n, u, c.boundary == STICKY)
                    Jk = (m * S(n_grids)) * (v - v_in)
                    add_impulse(status.collider_impulse, k, Jk)
                    if wp.static(RIGID in kinds):
                        add_torque(status.collider_torque, k, x - centre(c, time), Jk)
        J = (m * S(n_grids)) * (v - v0)
        for d in range(wp.static(t.dim)):
            if J[d] != S(0.0):
                wp.atomic_add(status.boundary_impulse, d, f64(J[d]))
        return x, v

    return keep_out
