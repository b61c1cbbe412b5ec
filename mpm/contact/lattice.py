"""What the contact passes (mpm.contact, mpm.contact.constraint) read from
the global lattice (mpm.lattice: spacing dx, ``cells`` + 1 nodes per axis,
flat index by ``strides``): the bins, the nearest lattice node, a cell's
corners and their linear weights, a flat node's body, a body's outward
normal and a lattice node's occupancy."""

import functools

import warp as wp

from ..lattice import make_lattice
from ..scene import CONTACT_NORMALS
from ..stencil import make_node_box
from ..types import Types


@functools.cache
def make_bins(t: Types):
    """The struct type ``Bins``: per body b and lattice node g, at
    b * n_global + g, the mass M_bg and momentum P_bg binned there (zero
    between steps), and what the contact test reads per body."""
    S = t.scalar

    @wp.struct
    class Bins:
        M: wp.array(dtype=S)  # [kg]
        P: wp.array(dtype=t.vec)  # [kg m/s]
        rest_mass: wp.array(dtype=S)  # per body: rho_b dx^d [kg]
        fill: S  # the volume fraction of a lattice node in contact
        share: S  # the volume fraction a body must fill at a lattice node to be present there
        mu: wp.array(dtype=S)  # Coulomb mu between bodies a and b at a * n_bodies + b (friction; else unused)
        rank: wp.array(dtype=wp.int32)  # per body: its place by stiffness, equal moduli equal ("stiffer"; else unused)

    return Bins


@functools.cache
def make_nearest(t: Types):
    """``nearest(lat, q) -> flat``: the global node closest to q."""
    Lattice = make_lattice(t)

    @wp.func
    def nearest(lat: Lattice, q: t.vec):
        flat = int(0)
        for d in range(wp.static(t.dim)):
            flat += wp.clamp(int(wp.round(q[d] * lat.inv_dx)), 0, lat.cells[d]) * lat.strides[d]
        return flat

    return nearest


@functools.cache
def make_corners(t: Types):
    """``cell_of(lat, q) -> (base, frac)``: the lattice cell holding q and
    q's place in it; ``corner(lat, base, frac, k) -> (w, flat)``: corner k
    of that cell (bit d of k: +1 along axis d), its linear weight and flat
    index (clamped to the lattice). The 2^d weights sum to 1."""
    S = t.scalar
    Lattice = make_lattice(t)

    @wp.func
    def cell_of(lat: Lattice, q: t.vec):
        base = t.ivec()
        frac = t.vec()
        for d in range(wp.static(t.dim)):
            s = q[d] * lat.inv_dx
            c = wp.floor(s)
            base[d] = int(c)
            frac[d] = s - c
        return base, frac

    @wp.func
    def corner(lat: Lattice, base: t.ivec, frac: t.vec, k: int):
        w = S(1.0)
        flat = int(0)
        for d in range(wp.static(t.dim)):
            bit = (k >> d) & 1
            if bit == 1:
                w *= frac[d]
            else:
                w *= S(1.0) - frac[d]
            flat += wp.clamp(base[d] + bit, 0, lat.cells[d]) * lat.strides[d]
        return w, flat

    return cell_of, corner


@functools.cache
def make_lattice_point(t: Types, gather: bool):
    """``lattice_point(lat, q, k) -> (w, flat)``: the k-th lattice node of a
    body node at q and its weight: corner k of q's cell with its linear
    weight (``gather``: k < 2^d), or the nearest node with weight 1 (k = 0)."""
    S = t.scalar
    Lattice = make_lattice(t)
    nearest = make_nearest(t)
    cell_of, corner = make_corners(t)

    @wp.func
    def lattice_point(lat: Lattice, q: t.vec, k: int):
        if wp.static(gather):
            base, frac = cell_of(lat, q)
            return corner(lat, base, frac, k)
        return S(1.0), nearest(lat, q)

    return lattice_point


@functools.cache
def make_node_body(t: Types):
    """``node_body(lat, i) -> b``: the body of flat node i (box b * n_grids
    + g starts at offset[box])."""
    Lattice = make_lattice(t)
    node_box = make_node_box(t)

    @wp.func
    def node_body(lat: Lattice, i: int):
        return node_box(i, lat.offset, lat.n_bodies * lat.n_grids) // lat.n_grids

    return node_body


@functools.cache
def make_present(t: Types):
    """``present_at(lat, bins, c, g) -> bool``: body c is present at global
    node g, M_cg > share rho_c dx^d (``Bins.share``: 0, any mass; above
    it, the fringe of a stencil reaching a node beside the body is not)."""
    Lattice = make_lattice(t)
    Bins = make_bins(t)

    @wp.func
    def present_at(lat: Lattice, bins: Bins, c: int, g: int):
        return bins.M[c * lat.n_global + g] > bins.share * bins.rest_mass[c]

    return present_at


@functools.cache
def make_outward(t: Types, normal: str = "difference"):
    """``outward(lat, bins, b, g) -> n_b``: body b's unit outward normal at
    global node g (mpm.scene.CONTACT_NORMALS; "stiffer" reads ``Bins.rank``),
    gradients by central differences (one-sided at the lattice edge) over
    the bodies present at g; 0 where the gradient vanishes."""
    S = t.scalar
    vec = t.vec
    Lattice = make_lattice(t)
    Bins = make_bins(t)
    if normal not in CONTACT_NORMALS:
        raise ValueError(f"contact normal {normal!r}; accepted: {', '.join(CONTACT_NORMALS)}")
    present_at = make_present(t)

    @wp.func
    def gradient(lat: Lattice, bins: Bins, c: int, g: int):
        """grad M_c at g (central differences, one-sided at the lattice edge) [kg / lattice spacing]."""
        n = vec()
        rest = g
        for d in range(wp.static(t.dim)):
            idx = rest // lat.strides[d]
            rest -= idx * lat.strides[d]
            minus = g - lat.strides[d]
            plus = g + lat.strides[d]
            if idx == 0:
                minus = g
            if idx == lat.cells[d]:
                plus = g
            n[d] = bins.M[c * lat.n_global + plus] - bins.M[c * lat.n_global + minus]
        return n

    @wp.func
    def outward(lat: Lattice, bins: Bins, b: int, g: int):
        n = vec()
        n_global = lat.n_global
        if wp.static(normal == "max_gradient"):
            best = S(-1.0)
            for c in range(lat.n_bodies):
                if present_at(lat, bins, c, g):
                    grad = gradient(lat, bins, c, g)
                    size = wp.length(grad) / bins.rest_mass[c]
                    if size > best:
                        best = size
                        n = grad  # into body c: body b's outward normal, unless c is b
                        if c == b:
                            n = -grad
        elif wp.static(normal == "stiffer"):
            best = S(-1.0)
            top = int(-1)
            for c in range(lat.n_bodies):
                if present_at(lat, bins, c, g):
                    grad = gradient(lat, bins, c, g)
                    size = wp.length(grad) / bins.rest_mass[c]
                    r = bins.rank[c]
                    if r > top or (r == top and size > best):  # the stiffest; of equals, the largest gradient
                        top = r
                        best = size
                        n = grad
                        if c == b:
                            n = -grad
        else:
            rest = g
            for d in range(wp.static(t.dim)):
                idx = rest // lat.strides[d]
                rest -= idx * lat.strides[d]
                minus = g - lat.strides[d]
                plus = g + lat.strides[d]
                if idx == 0:
                    minus = g
                if idx == lat.cells[d]:
                    plus = g
                grad_b = bins.M[b * n_global + plus] - bins.M[b * n_global + minus]
                grad_tot = S(0.0)  # over the bodies present at g
                for c in range(lat.n_bodies):
                    if present_at(lat, bins, c, g):
                        grad_tot += bins.M[c * n_global + plus] - bins.M[c * n_global + minus]
                n[d] = grad_tot - S(2.0) * grad_b  # grad(M_others) - grad(M_b)
        length = wp.length(n)
        if length > S(0.0):
            n = n / length
        return n

    return outward


@functools.cache
def make_occupancy(t: Types):
    """``occupancy(lat, bins, g) -> (present, M, P, volume, a, c)``: at
    global node g, the bodies present, their total mass and momentum, the
    volume fraction they fill, sum_b M_bg / (rho_b dx^d), and the first
    and last body present (-1: none; a = c: one)."""
    S = t.scalar
    Lattice = make_lattice(t)
    Bins = make_bins(t)
    present_at = make_present(t)

    @wp.func
    def occupancy(lat: Lattice, bins: Bins, g: int):
        present = int(0)
        m_tot = S(0.0)
        p_tot = t.vec()
        volume = S(0.0)
        a = int(-1)
        c = int(-1)
        for b in range(lat.n_bodies):
            m = bins.M[b * lat.n_global + g]
            if present_at(lat, bins, b, g):
                present += 1
                m_tot += m
                p_tot += bins.P[b * lat.n_global + g]
                volume += m / bins.rest_mass[b]
                if a < 0:
                    a = b
                c = b
        return present, m_tot, p_tot, volume, a, c

    return occupancy
