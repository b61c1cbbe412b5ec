"""Grid velocity update: momentum to velocity, gravity, boundary conditions.

On every node with mass:
    v_i = (m_i v_i) / m_i + dt g,    q_i = (m_i q_i) / m_i,
then (after contact, when bodies can touch: mpm.contact) the boundary
conditions, evaluated at the node's current position q_i:

* walls (mpm.walls) act where a body touches them: a wall is the solid
  behind its face, ``wall_cells`` cells inside the domain's face, and acts
  on the nodes where the body and the wall fill a node together
  (mpm.surface; ``Scene.boundary_rule`` "nodes": on the first
  ``wall_cells`` lattice nodes, as in earlier versions). Sticky walls set
  v_i = 0, slip walls remove the velocity component pointing into the wall
  (separation and tangential motion are free), open faces do nothing;
* kinematic regions (mpm.scene.KinematicRegion) set the velocity of every
  node that draws at least half its mass from a region's particles (less
  ``KINEMATIC_TIE``, so that an exact tie is kinematic in every precision),
  while the region is active: v_i = u + G (q_i - c(t)), with G the region's velocity
  gradient (the skew matrix of its angular velocity omega, so that
  G r = omega x r, plus any prescribed ``velocity_gradient``).

Between the two, rigid colliders (mpm.colliders) act on the nodes where a
body touches them, by the same rule (mpm.collider_device).

The impulse of the conditions on a node, J = m_i (v_bc - v_i), is summed
into the step's status (``boundary_impulse``, per axis: with gravity's
M g dt, the step's change of the bodies' momentum), and so is its work, the
positive part of J . v_bc (``boundary_work``, mpm.stepping.status): static walls and
colliders do none (J is normal to v_bc, or v_bc = 0; friction's is
negative), moving colliders and regions do J . u, and mpm.stepping.detection counts
it as energy put in.
"""

import functools

import warp as wp

from .launch import warp_kernel
from .stepping.status import StepControl, StepStatus

from .collider_device import make_collide, make_constrain
from .collider_shapes import make_collider_data
from .contact.lattice import make_node_body
from .lattice import make_lattice, make_node_mass
from .stencil import make_node_position
from .surface import make_profile_type
from .types import Types
from .walls import make_wall_constraints, make_walls


# A node is kinematic when the region's share of its mass is at least
# 1/2 - KINEMATIC_TIE. A region whose face lies between two rows of equally
# massive particles gives the nodes on that face exactly half (the rows'
# weights are mirror images), and the summation's rounding would decide the tie
# differently in float32 and float64 (a different clamp, several per cent of a
# bar's peak response). The margin is far above that rounding (a node sums at
# most (3 ppc)^d ~ 216 terms: about 1e-5 relative in float32) and far below
# any share a region's geometry makes on purpose.
KINEMATIC_TIE = 1e-3


@functools.cache
def make_kinematic(t: Types):
    """``kinematic(v, q, m, kin_m, kin_id, time, u, gradient, center, window)
    -> (active, v)``: whether a region prescribes the node's velocity, and the velocity."""
    S = t.scalar

    @wp.func
    def kinematic(v: t.vec, q: t.vec, m: S, kin_m: S, kin_id: int, time: S,
                  u: wp.array(dtype=t.vec), gradient: wp.array(dtype=t.mat),
                  center: wp.array(dtype=t.vec), window: wp.array(dtype=wp.types.vector(2, S))):
        if kin_id == 0 or kin_m < S(0.5 - KINEMATIC_TIE) * m:
            return False, v
        r = kin_id - 1
        if time < window[r][0] or time >= window[r][1]:
            return False, v
        c = center[r] + (time - window[r][0]) * u[r]
        return True, u[r] + gradient[r] * (q - c)

    return kinematic


def region_types(t: Types):
    """Types of the per-region tables: velocity, velocity gradient, centre, (start, end)."""
    return t.vec, t.mat, t.vec, wp.types.vector(2, t.scalar)


@functools.cache
def make_boundary_data(t: Types):
    """What the boundary conditions read: the walls, the colliders and the
    kinematic regions."""
    U, G, Cc, Win = region_types(t)
    Collider = make_collider_data(t)
    Profile = make_profile_type(t)

    @wp.struct
    class BoundaryData:
        domain: t.vec  # domain size [m]
        band: t.scalar  # wall band of the node rule [m]: (wall_cells - 1/2) dx
        wall_lo: t.ivec  # wall type of the low face per axis (mpm.scene.WALL_TYPES)
        wall_hi: t.ivec
        face_lo: t.vec  # the walls' faces [m] (the surface rule): wall_cells dx
        face_hi: t.vec  # domain - wall_cells dx
        profile: Profile  # the kernel's cumulative profile (mpm.surface)
        rest_mass: wp.array(dtype=t.scalar)  # per body rho dx^d [kg]
        region_u: wp.array(dtype=U)  # per region: velocity [m/s]
        region_gradient: wp.array(dtype=G)  # velocity gradient [1/s]
        region_center: wp.array(dtype=Cc)  # centre at start [m]
        region_window: wp.array(dtype=Win)  # (start, end) [s]
        colliders: wp.array(dtype=Collider)  # mpm.colliders records

    return BoundaryData


@functools.cache
def make_conditions(t: Types, with_regions: bool, colliders: tuple[str, ...] = (), rule: str = "surface",
                    gradients: bool = False):
    """``conditions(v, q, m, V, G, kin_m, kin_id, time, data, status) -> v``:
    walls, the colliders (the shapes named in ``colliders``; none: compiled
    out; each one's impulse into ``status.collider_impulse``), then regions,
    by the boundary ``rule`` (mpm.scene.BOUNDARY_RULES) on a node of mass
    ``m``, body volume fraction ``V`` and velocity gradient ``G`` (with
    ``gradients``; mpm.surface)."""
    S = t.scalar
    walls = make_walls(t, rule)
    kinematic = make_kinematic(t)
    collide = make_collide(t, colliders, rule, gradients)
    Data = make_boundary_data(t)

    @wp.func
    def conditions(v: t.vec, q: t.vec, m: S, V: S, G: t.mat, kin_m: S, kin_id: int, time: S, data: Data,
                   status: StepStatus):
        v = walls(v, q, V, data.domain, data.band, data.wall_lo, data.wall_hi, data.face_lo, data.face_hi,
                  data.profile)
        if wp.static(len(colliders) > 0):
            v = collide(v, q, m, V, G, time, data.colliders, data.profile, status.collider_impulse,
                        status.collider_torque)
        if wp.static(with_regions):
            active, v = kinematic(v, q, m, kin_m, kin_id, time, data.region_u, data.region_gradient,
                                  data.region_center, data.region_window)
        return v

    return conditions


@functools.cache
def make_node_state(t: Types, rule: str, gradients: bool):
    """``node_state(lat, i, m, data) -> (V, G)``: node i's body volume
    fraction m / (rho dx^d) and velocity gradient (summed in P2G with
    ``gradients``, else 0) for the surface rule; (0, 0) for the node rule."""
    S = t.scalar
    Lattice = make_lattice(t)
    Data = make_boundary_data(t)
    node_body = make_node_body(t)

    @wp.func
    def node_state(lat: Lattice, i: int, m: S, data: Data):
        V = S(0.0)
        G = t.mat()
        if wp.static(rule == "surface"):
            V = m / data.rest_mass[node_body(lat, i)]
            if wp.static(gradients):
                G = lat.G[i] / m
        return V, G

    return node_state


@functools.cache
def make_constraints(t: Types, with_regions: bool, colliders: tuple[str, ...] = (),
                     with_friction: bool = False, rule: str = "surface", gradients: bool = False,
                     first: int = 0):
    """The boundary conditions as constraints of the implicit solve
    (mpm.implicit): on every node with mass, from the predicted velocity v*,
    the constrained velocity and the orthogonal projector Pi onto the
    velocities the solve may still change (I: free, 0: fixed), where the
    ``rule`` puts a node in contact (mpm.walls, mpm.collider_device). Sticky
    walls and kinematic regions fix the node; a slip wall the node moves
    into, or a slip collider, fixes the normal component. ``with_friction``:
    per node the friction coefficient, velocity and normal of its frictional
    collider (mu = 0: none) and the extrapolation from the node to the
    surface, for the friction inside the solve (mpm.implicit.rough). Nodes
    without mass get Pi = 0 (not part of the system). ``first``: the index
    of the first rigid body's collider (mpm.collider_device ``make_constrain``)."""
    S = t.scalar
    mat = t.mat
    dim = t.dim
    kinematic = make_kinematic(t)
    constrain = make_constrain(t, colliders, rule, gradients, first)
    walls = make_wall_constraints(t, rule)
    node_state = make_node_state(t, rule, gradients)
    Data = make_boundary_data(t)
    Lattice = make_lattice(t)

    @warp_kernel
    def constraints(
        lat: Lattice,  # v: in, predicted; out, constrained
        time: S,
        data: Data,
        free: wp.array(dtype=t.mat),  # out: Pi
        friction: wp.array(dtype=S),  # out (with_friction): mu
        friction_u: wp.array(dtype=t.vec),  # out (with_friction): the collider's velocity
        friction_n: wp.array(dtype=t.vec),  # out (with_friction): its normal
        friction_shift: wp.array(dtype=t.vec),  # out (with_friction): the surface's velocity minus the node's
        contact_id: wp.array(dtype=wp.int32),  # out (colliders): the collider in contact, or -1
    ):
        i = wp.tid()
        m = lat.m[i]
        if wp.static(with_friction):
            friction[i] = S(0.0)
        if wp.static(len(colliders) > 0):
            contact_id[i] = -1
        if m <= S(0.0):
            free[i] = mat()
            return
        v = lat.v[i]
        q = lat.q[i]
        V, G = node_state(lat, i, m, data)  # pyright: ignore[reportArgumentType]
        Pi = wp.identity(n=dim, dtype=S)
        v, Pi = walls(v, Pi, q, V, data.domain, data.band, data.wall_lo, data.wall_hi, data.face_lo, data.face_hi,
                      data.profile)
        if wp.static(len(colliders) > 0):
            v, Pi, mu, uf, nf, sf, hit = constrain(v, Pi, q, V, G, time, data.colliders, data.profile)
            contact_id[i] = hit
            if wp.static(with_friction):
                friction[i] = mu
                friction_u[i] = uf
                friction_n[i] = nf
                friction_shift[i] = sf
        if wp.static(with_regions):
            active, vk = kinematic(v, q, m, lat.kin[i], lat.kin_id[i], time, data.region_u,
                                   data.region_gradient, data.region_center, data.region_window)
            if active:
                v = vk
                Pi = mat()
                if wp.static(with_friction):
                    friction[i] = S(0.0)
                if wp.static(len(colliders) > 0):
                    contact_id[i] = -1
        lat.v[i] = v
        free[i] = Pi

    return constraints


@functools.cache
def make_work(t: Types):
    """``work(m, v, v_bc, status)``: add the impulse J = m (v_bc - v) [N s]
    that turns v into v_bc to ``status.boundary_impulse`` (per axis), and the
    positive part of its work J . v_bc [J] (force times the distance the node
    moves at v_bc) to ``status.boundary_work``."""
    S = t.scalar

    @wp.func
    def work(m: S, v: t.vec, v_bc: t.vec, status: StepStatus):
        J = m * (v_bc - v)
        for d in range(wp.static(t.dim)):
            if J[d] != S(0.0):
                wp.atomic_add(status.boundary_impulse, d, wp.float64(J[d]))
        W = m * wp.dot(v_bc - v, v_bc)
        if W > S(0.0):
            wp.atomic_add(status.boundary_work, 0, wp.float64(W))

    return work


@functools.cache
def make_apply_conditions(t: Types, with_regions: bool, colliders: tuple[str, ...] = (), rule: str = "surface",
                          gradients: bool = False):
    """``apply_conditions(lat, i, m, v, q, time, data, status) -> v_bc``:
    the conditions at node i (mass m, velocity v, position q), their
    impulse and work into ``status`` (:func:`make_work`)."""
    S = t.scalar
    conditions = make_conditions(t, with_regions, colliders, rule, gradients)
    node_state = make_node_state(t, rule, gradients)
    Data = make_boundary_data(t)
    Lattice = make_lattice(t)
    work = make_work(t)

    @wp.func
    def apply_conditions(lat: Lattice, i: int, m: S, v: t.vec, q: t.vec, time: S, data: Data, status: StepStatus):
        V, G = node_state(lat, i, m, data)
        vb = conditions(v, q, m, V, G, lat.kin[i], lat.kin_id[i], time, data, status)
        work(m, v, vb, status)
        return vb

    return apply_conditions


@functools.cache
def make_grid_update(t: Types, with_boundary: bool, with_regions: bool,
                     colliders: tuple[str, ...] = (), lattice: bool = False, n_grids: int = 1,
                     batched: bool = False, rule: str = "surface", gradients: bool = False):
    """Momentum to velocity and gravity over the step ``control.dt``, at the
    step's start ``control.t``; the boundary conditions too unless
    ``with_boundary`` is False (contact comes first, then :func:`make_boundary`).
    The node positions are P2G's mass-weighted ones, or, ``lattice`` (the
    Eulerian scheme, whose reference grid is the current one), the lattice
    positions of the layout (mpm.stencil.make_node_position); with
    ``control.positions`` 0, P2G summed none, since no condition can reach a
    node in this step, and the conditions are skipped. ``batched``: nothing
    in a step the driver skips (mpm.stepping.driver)."""
    S = t.scalar
    node_position = make_node_position(t, n_grids)
    Gv = wp.types.vector(n_grids, S)
    Data = make_boundary_data(t)
    Lattice = make_lattice(t)
    node_mass = make_node_mass(t, batched)
    apply_conditions = make_apply_conditions(t, with_regions, colliders, rule, gradients)

    @warp_kernel
    def grid_update(
        lat: Lattice,  # v: momentum in, velocity out; q: mass-weighted position (not lattice) in, position out
        gravity: t.vec,
        grid_offsets: Gv,
        control: StepControl,
        data: Data,
        status: StepStatus,  # boundary_work += the energy the conditions gave
    ):
        i = wp.tid()
        m = node_mass(lat, control, i)  # pyright: ignore[reportArgumentType]
        if m <= S(0.0):
            return
        dt = S(control.dt[0])
        time = S(control.t[0])
        positioned = int(control.positions[0])
        vi = lat.v[i] / m + dt * gravity
        if positioned != 0:
            if wp.static(lattice):
                qi = node_position(i, lat.lo, lat.shape, lat.offset, lat.n_boxes, grid_offsets, lat.dx)  # pyright: ignore[reportArgumentType]
            else:
                qi = lat.q[i] / m
            if wp.static(with_boundary):
                vi = apply_conditions(lat, i, m, vi, qi, time, data, status)  # pyright: ignore[reportArgumentType]
            lat.q[i] = qi
        lat.v[i] = vi

    return grid_update


@functools.cache
def make_boundary(t: Types, with_regions: bool, colliders: tuple[str, ...] = (), batched: bool = False,
                  rule: str = "surface", gradients: bool = False):
    """The boundary conditions as a pass of their own (after contact), at the
    step's start ``control.t`` (``batched``: nothing in a skipped step)."""
    S = t.scalar
    Data = make_boundary_data(t)
    Lattice = make_lattice(t)
    node_mass = make_node_mass(t, batched)
    apply_conditions = make_apply_conditions(t, with_regions, colliders, rule, gradients)

    @warp_kernel
    def boundary(lat: Lattice, control: StepControl, data: Data, status: StepStatus):
        i = wp.tid()
        m = node_mass(lat, control, i)  # pyright: ignore[reportArgumentType]
        if m <= S(0.0):
            return
        lat.v[i] = apply_conditions(lat, i, m, lat.v[i], lat.q[i], S(control.t[0]), data, status)  # pyright: ignore[reportArgumentType]

    return boundary
