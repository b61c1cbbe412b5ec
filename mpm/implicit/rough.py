"""Coulomb friction at the colliders inside the implicit solve
(mpm.implicit), as between bodies (mpm.contact.friction), under the
surface rule (mpm.surface; the node rule applies it after the solve, as
earlier versions did: mpm.implicit.system ``make_friction``).

A node that a slip or separating collider with mu > 0 holds along its
normal n (mpm.collider_device ``constrain``: friction ``mu``, the
collider's velocity u and the shift from the node to the body's surface
point, v_s = v + shift) is in one of two states:

* stick: the surface point moves with the collider, v = u - shift, the
  node fixed in every direction (Pi = 0);
* slip: the normal row only (Pi the constraints' projector ``held``), and
  a tangential impulse of magnitude mu m R_n against the slip, applied as
  a known load: v* = v*_base + Pi L, L = -mu R_n u_t / |u_t| [m/s]
  (u_t = Pi (v + shift - u), the surface point's slip).

Every such node starts stuck. With R = reaction the constraints' reaction
at the solution [m/s] (its impulse m R) and R_n = R . n (> 0 pushing the
body out), after a solve (:func:`make_rough` ``classify``): a stuck node
whose tangential reaction |Pi R| exceeds mu R_n slides, with
L = mu R_n Pi R / |Pi R| (a node whose normal reaction pulls slides with
no load); a sliding node whose slip the load turned round (u_t . L > 0)
sticks; a sliding node's L follows its new R_n and slip (settled within
mpm.implicit.rounds FRICTION_TOL of mu R_n). A node that the one-sided
rounds let go leaves friction; one they newly hold starts stuck. The
solve is repeated from its last solution while any of them changes
(mpm.implicit.rounds, at most mpm.implicit.solve ROUNDS solves).

A stuck node's tangential reaction is part of its reaction, which the
constraints' work counts (mpm.implicit.system ``make_boundary_work``); a
sliding node's load is not, and ``work`` adds its impulse m Pi L and work
to the step's books and to its collider's ``collider_impulse``.
"""

import functools

import warp as wp

from ..collider_device import make_add_reaction
from ..collider_shapes import make_collider_data
from ..contact.friction import STICK, SLIP, make_coulomb_round
from ..grid import make_work
from ..launch import warp_kernel
from ..stepping.status import StepStatus
from ..types import Types

NONE = -1  # a node not in frictional contact (STICK, SLIP: mpm.contact.friction's)


@functools.cache
def make_rough(t: Types, rigid: bool = False):
    """``hold``, ``classify``, ``work``: the kernels of collider friction
    inside the implicit solve (module docstring); ``rigid``: ``work`` sums
    the loads' angular impulses too (mpm.collider_device ``make_add_reaction``)."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    work_of = make_work(t)
    add_reaction = make_add_reaction(t, rigid)
    coulomb_round = make_coulomb_round(t)  # the same rule as between bodies
    Data = make_collider_data(t)

    @warp_kernel
    def hold(fresh: int, m: wp.array(dtype=S), mu: wp.array(dtype=S), u: wp.array(dtype=vec),
             shift: wp.array(dtype=vec), state: wp.array(dtype=wp.int32), load: wp.array(dtype=vec),
             held: wp.array(dtype=mat), free: wp.array(dtype=mat), v: wp.array(dtype=vec),
             v_base: wp.array(dtype=vec), v_star: wp.array(dtype=vec)):
        """Each node's state on the constraints: with ``fresh`` (the
        constraints just classified the nodes) the projector they gave is
        kept in ``held``, a node newly in frictional contact starts stuck
        and one no longer in it leaves friction; a stuck node is fixed at
        v = u - shift (Pi = 0), a sliding one free along ``held``, and
        v* = v*_base + the sliding nodes' loads."""
        i = wp.tid()
        if m[i] <= S(0.0) or mu[i] <= S(0.0):
            state[i] = NONE
            load[i] = vec()
            v_star[i] = v_base[i]
            return
        if fresh != 0:
            held[i] = free[i]
            if state[i] == NONE:
                state[i] = STICK
                load[i] = vec()
        vs = v_base[i]
        if state[i] == STICK:
            free[i] = mat()
            v[i] = u[i] - shift[i]
        else:
            free[i] = held[i]
            vs = vs + held[i] * load[i]
        v_star[i] = vs

    @warp_kernel
    def classify(m: wp.array(dtype=S), mu: wp.array(dtype=S), u: wp.array(dtype=vec),
                 normal: wp.array(dtype=vec), shift: wp.array(dtype=vec), held: wp.array(dtype=mat),
                 reaction: wp.array(dtype=vec), v: wp.array(dtype=vec), state: wp.array(dtype=wp.int32),
                 load: wp.array(dtype=vec), tol: S, state_after: wp.array(dtype=wp.int32),
                 load_after: wp.array(dtype=vec), changed: wp.array(dtype=wp.int32)):
        """Per node, after a solve: its next state and load into the
        ``_after`` arrays (module docstring), counting the nodes that
        changed state or whose load moved by more than ``tol`` of mu R_n."""
        i = wp.tid()
        st = state[i]
        L = load[i]
        state_after[i] = st
        load_after[i] = L
        if st == NONE or m[i] <= S(0.0):
            return
        limit = mu[i] * wp.max(wp.dot(reaction[i], normal[i]), S(0.0))
        P = held[i]
        st_new, L_new, moved = coulomb_round(st, P * reaction[i], limit, P * (v[i] + shift[i] - u[i]), L, tol)
        state_after[i] = st_new
        load_after[i] = L_new
        if moved != 0:
            wp.atomic_add(changed, 0, 1)

    @warp_kernel
    def work(m: wp.array(dtype=S), state: wp.array(dtype=wp.int32), load: wp.array(dtype=vec),
             held: wp.array(dtype=mat), contact_id: wp.array(dtype=wp.int32), v: wp.array(dtype=vec),
             q: wp.array(dtype=vec), time: S, colliders: wp.array(dtype=Data),
             torque: wp.array(dtype=wp.float64), status: StepStatus):
        """A sliding node's load at the solution: its impulse m Pi L and
        work into ``status`` as the constraints' (mpm.grid ``make_work``),
        and into its collider's row of ``collider_impulse`` (``rigid``: its
        angular impulse about the collider's centre into ``torque``, the
        node at ``q``)."""
        i = wp.tid()
        if m[i] <= S(0.0) or state[i] != SLIP:
            return
        dv = held[i] * load[i]
        work_of(m[i], v[i] - dv, v[i], status)
        if contact_id[i] >= 0:
            add_reaction(status.collider_impulse, torque, colliders, contact_id[i], q[i], time, m[i] * dv)

    return hold, classify, work
