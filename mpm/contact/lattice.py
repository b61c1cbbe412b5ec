"""What the contact passes (mpm.contact, mpm.contact.constraint) read from
the global lattice (spacing dx, ``cells`` + 1 nodes per axis, flat index by
``strides``): the nearest lattice node, a cell's corners and their linear
weights, a flat node's body, a body's outward normal and a lattice node's
occupancy."""

import functools

import warp as wp

from ..stencil import make_node_box
from ..types import Types


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
def make_corners(t: Types):
    """``cell_of(q, inv_dx) -> (base, frac)``: the lattice cell holding q and
    q's place in it; ``corner(base, frac, k, cells, strides) -> (w, flat)``:
    corner k of that cell (bit d of k: +1 along axis d), its linear weight
    and flat index (clamped to the lattice). The 2^d weights sum to 1."""
    S = t.scalar

    @wp.func
    def cell_of(q: t.vec, inv_dx: S):
        base = t.ivec()
        frac = t.vec()
        for d in range(wp.static(t.dim)):
            s = q[d] * inv_dx
            c = wp.floor(s)
            base[d] = int(c)
            frac[d] = s - c
        return base, frac

    @wp.func
    def corner(base: t.ivec, frac: t.vec, k: int, cells: t.ivec, strides: t.ivec):
        w = S(1.0)
        flat = int(0)
        for d in range(wp.static(t.dim)):
            bit = (k >> d) & 1
            if bit == 1:
                w *= frac[d]
            else:
                w *= S(1.0) - frac[d]
            flat += wp.clamp(base[d] + bit, 0, cells[d]) * strides[d]
        return w, flat

    return cell_of, corner


@functools.cache
def make_node_body(t: Types):
    node_box = make_node_box(t)

    @wp.func
    def node_body(i: int, offset: wp.array(dtype=wp.int32), n_bodies: int, n_grids: int):
        """Body of flat node i (box b * n_grids + g starts at offset[box])."""
        return node_box(i, offset, n_bodies * n_grids) // n_grids

    return node_body


@functools.cache
def make_outward(t: Types):
    """``outward(b, g, n_bodies, cells, strides, n_global, M) -> n_b``: body
    b's unit outward normal at global node g, normalize(grad(M_others - M_b))
    by central differences (one-sided at the lattice edge), M_others the
    bodies present at g; 0 where the gradient vanishes."""
    S = t.scalar
    vec = t.vec

    @wp.func
    def outward(b: int, g: int, n_bodies: int, cells: t.ivec, strides: t.ivec, n_global: int,
                M: wp.array(dtype=S)):
        n = vec()
        rest = g
        for d in range(wp.static(t.dim)):
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
        return n

    return outward


@functools.cache
def make_occupancy(t: Types):
    """``occupancy(g, n_bodies, n_global, rest_mass, M, P) -> (present, M, P,
    volume)``: at global node g, the bodies present, their total mass and
    momentum and the volume fraction they fill, sum_b M_bg / (rho_b dx^d)."""
    S = t.scalar

    @wp.func
    def occupancy(g: int, n_bodies: int, n_global: int, rest_mass: wp.array(dtype=S), M: wp.array(dtype=S),
                  P: wp.array(dtype=t.vec)):
        present = int(0)
        m_tot = S(0.0)
        p_tot = t.vec()
        volume = S(0.0)
        for b in range(n_bodies):
            m = M[b * n_global + g]
            if m > S(0.0):
                present += 1
                m_tot += m
                p_tot += P[b * n_global + g]
                volume += m / rest_mass[b]
        return present, m_tot, p_tot, volume

    return occupancy
