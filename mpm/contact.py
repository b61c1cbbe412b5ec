"""Contact between bodies through a global Eulerian grid (multi-velocity
field, frictionless, separation free).

Every body has its own reference grid (mpm.layout), so bodies do not see each
other in the transfers. After the grid update, each body node i (mass m_i,
velocity v_i, current position q_i) is binned to the global lattice node g
nearest to q_i (spacing dx), one field per body b:
    M_bg = sum_{i in g} m_i,   P_bg = sum_{i in g} m_i v_i.
(For the Eulerian scheme q_i is a lattice node; a Lagrangian node's q_i is
anywhere, and spreading it over several lattice nodes would dilute the
correction it takes back, letting bodies creep into each other.)
Bodies are in contact at a global node where two or more are present and
their volume fractions fill it: sum_b M_bg / (rho_b dx^d) >= ``fill``
(rho_b the body's rest density). Without this test a node would register
contact as soon as the faint fringes of two stencils overlap, bodies several
cells apart. There, body b's outward normal is
    n_b = normalize(grad (M_others - M_b)),   M_others = sum of the other
bodies present at that node (central differences), which for two bodies is
the common normal, n_a = -n_b. With the
centre-of-mass velocity v_cm = sum P / sum M, a body approaching the others,
(v_b - v_cm) . n_b > 0, loses that normal component:
    dV_bg = -((v_b - v_cm) . n_b) n_b,
and each body node of that bin takes dv_i = dV_bg. The momentum change
sum_b M_bg dV_bg at a global node vanishes: for two bodies the normal impulses
are equal and opposite; where three or more meet, the mass-weighted mean
correction is taken off every body present. Each bin hands exactly that
momentum to its nodes.
"""

import functools

import warp as wp

from .types import Types


@functools.cache
def make_nearest(t: Types):
    """``nearest(q, inv_dx, cells, strides) -> flat``: the global node closest to q."""
    S = t.scalar

    @wp.func
    def nearest(q: t.vec, inv_dx: S, cells: t.ivec, strides: t.ivec):
        flat = int(0)
        for d in range(wp.static(t.dim)):
            flat += wp.clamp(int(wp.round(q[d] * inv_dx)), 0, cells[d]) * strides[d]
        return flat

    return nearest


@functools.cache
def make_node_body(t: Types):
    @wp.func
    def node_body(i: int, offset: wp.array(dtype=wp.int32), n_bodies: int, n_grids: int):
        """Body of flat node i (box b * n_grids + g starts at offset[box])."""
        b = int(0)
        for k in range(n_bodies * n_grids):
            if i >= offset[k]:
                b = k // n_grids
        return b

    return node_body


@functools.cache
def make_contact(t: Types):
    """The three contact passes: bin (body nodes), resolve (global nodes),
    take back (body nodes)."""
    S = t.scalar
    vec = t.vec
    dim = t.dim
    nearest = make_nearest(t)
    node_body = make_node_body(t)

    @wp.kernel(module="unique")
    def splat(
        grid_m: wp.array(dtype=S),
        grid_v: wp.array(dtype=t.vec),
        grid_q: wp.array(dtype=t.vec),
        offset: wp.array(dtype=wp.int32),
        n_bodies: int,
        n_grids: int,
        inv_dx: S,
        cells: t.ivec,
        strides: t.ivec,
        n_global: int,
        M: wp.array(dtype=S),
        P: wp.array(dtype=t.vec),
    ):
        i = wp.tid()
        m = grid_m[i]
        if m <= S(0.0):
            return
        b = node_body(i, offset, n_bodies, n_grids)
        g = nearest(grid_q[i], inv_dx, cells, strides)
        m = m / S(n_grids)  # every kernel grid carries the body's full mass
        wp.atomic_add(M, b * n_global + g, m)
        wp.atomic_add(P, b * n_global + g, m * grid_v[i])

    @wp.kernel(module="unique")
    def resolve(
        n_bodies: int,
        cells: t.ivec,
        strides: t.ivec,
        n_global: int,
        rest_mass: wp.array(dtype=S),  # rho_b dx^d per body
        fill: S,
        M: wp.array(dtype=S),
        P: wp.array(dtype=t.vec),
        dV: wp.array(dtype=t.vec),
    ):
        g = wp.tid()
        present = int(0)
        m_tot = S(0.0)
        p_tot = vec()
        volume = S(0.0)
        for b in range(n_bodies):
            m = M[b * n_global + g]
            if m > S(0.0):
                present += 1
                m_tot += m
                p_tot += P[b * n_global + g]
                volume += m / rest_mass[b]
        if present < 2 or volume < fill:
            return
        v_cm = p_tot / m_tot
        dp = vec()  # momentum the corrections add at this node
        for b in range(n_bodies):
            m_b = M[b * n_global + g]
            if m_b <= S(0.0):
                continue
            # mass gradients by central differences (one-sided at the lattice edge)
            n = vec()
            rest = g
            for d in range(wp.static(dim)):
                idx = rest // strides[d]
                rest -= idx * strides[d]
                minus = g - strides[d]
                plus = g + strides[d]
                if idx == 0:
                    minus = g
                if idx == cells[d]:
                    plus = g
                grad_b = M[b * n_global + plus] - M[b * n_global + minus]
                grad_tot = S(0.0)  # over the bodies present at g
                for c in range(n_bodies):
                    if M[c * n_global + g] > S(0.0):
                        grad_tot += M[c * n_global + plus] - M[c * n_global + minus]
                n[d] = grad_tot - S(2.0) * grad_b  # grad(M_others) - grad(M_b)
            length = wp.length(n)
            if length > S(0.0):
                n = n / length
                rel = wp.dot(P[b * n_global + g] / m_b - v_cm, n)
                if rel > S(0.0):
                    dV[b * n_global + g] = -rel * n
                    dp += (-rel * m_b) * n
        # two bodies: the normals are opposite and dp vanishes (to round-off);
        # with more, take the mean correction off every body present
        if present > 2:
            dv_mean = dp / m_tot
            for b in range(n_bodies):
                if M[b * n_global + g] > S(0.0):
                    dV[b * n_global + g] = dV[b * n_global + g] - dv_mean


    @wp.kernel(module="unique")
    def gather(
        grid_m: wp.array(dtype=S),
        grid_q: wp.array(dtype=t.vec),
        offset: wp.array(dtype=wp.int32),
        n_bodies: int,
        n_grids: int,
        inv_dx: S,
        cells: t.ivec,
        strides: t.ivec,
        n_global: int,
        dV: wp.array(dtype=t.vec),
        grid_v: wp.array(dtype=t.vec),
    ):
        i = wp.tid()
        if grid_m[i] <= S(0.0):
            return
        b = node_body(i, offset, n_bodies, n_grids)
        g = nearest(grid_q[i], inv_dx, cells, strides)
        grid_v[i] = grid_v[i] + dV[b * n_global + g]

    return splat, resolve, gather
