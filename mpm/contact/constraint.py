"""Contact as constraints of the implicit solve (mpm.implicit).

Under the implicit integrator contact (mpm.contact) is also part of the
system: a bin where exactly two bodies a, b approach on the step's predictor
becomes the linear constraint

    B_g v = V_a . n_a + V_b . n_b = (V_a - V_b) . n_a = 0,
    V_b = sum_{i in (b, g)} (m_i / G) v_i / M_bg   (the bin's mean velocity),

i.e. row g of B has c_i = (m_i / G) / M_bg n_b at the bin's nodes of body b
(G the kernel's number of grids). For the constraints every node is binned
to its nearest lattice node, Lagrangian nodes too. The rows act on disjoint
nodes, so B W B^T is diagonal for any per-node metric W, and the
W-orthogonal projection onto B v = 0 is one bin sum and one node pass
(:func:`make_contact_constraint`). With W = M^-1 that projection is
mpm.contact's explicit correction of a binned node. The
constraint's impulse B^T lambda gives the two bodies lambda n_a and
lambda n_b = -lambda n_a: momentum is exchanged, not created. Bins with
three or more bodies, and bins that start approaching during the solve, are
left to the explicit pass after it.

Coulomb friction between the bodies (``Scene.contact = "friction"``) is
part of the solve too: a stuck bin's relative velocity vanishes, a sliding
bin carries the Coulomb load (mpm.contact.friction).
"""

import functools

import warp as wp

from .lattice import make_bins, make_nearest, make_node_body, make_occupancy, make_outward, make_present
from ..lattice import make_lattice
from ..launch import warp_kernel
from ..types import Types


def make_contact_constraint(t: Types, normal: str = "difference", touching: bool = False):
    """Contact as constraints of the implicit solve (the module docstring):
    ``couple`` (body nodes, after mpm.contact ``splat`` of the predictor and
    before its ``clear``: the node's active bin and c_i), ``sums`` and
    ``project`` (the W-orthogonal projection onto B v = 0,
    :func:`make_projection`). ``touching``: every two-body bin is a
    constraint, approaching or not (friction, mpm.contact.friction, which
    lets go of the bins that pull)."""
    return (make_couple(t, normal, touching), *make_projection(t))


@functools.cache
def make_couple(t: Types, normal: str = "difference", touching: bool = False):
    """``couple``: a node's constraint, if its bin is active: exactly two
    bodies a < c fill it and approach on the predictor, (V_a - V_c) . n_a >
    0 (or touch, ``touching``), with n_a = outward(a) and n_c = -n_a (every
    node of the bin finds the same)."""
    S = t.scalar
    Lattice = make_lattice(t)
    Bins = make_bins(t)
    nearest = make_nearest(t)
    node_body = make_node_body(t)
    outward = make_outward(t, normal)
    occupancy = make_occupancy(t)
    present_at = make_present(t)

    @warp_kernel
    def couple(
        lat: Lattice,
        bins: Bins,
        cbin: wp.array(dtype=wp.int32),  # out: the node's active bin g, or -1
        coef: wp.array(dtype=t.vec),  # out: c_i = (m_i / G) / M_bg n_b
    ):
        i = wp.tid()
        cbin[i] = -1
        if lat.m[i] <= S(0.0):
            return
        b = node_body(lat, i)  # pyright: ignore[reportArgumentType]
        g = nearest(lat, lat.q[i])
        present, _m, _p, volume, a, c = occupancy(lat, bins, g)  # a, c: the first and second body present
        n_global = lat.n_global
        if not present_at(lat, bins, b, g) or present != 2 or volume < bins.fill:
            return
        n = outward(lat, bins, a, g)
        if wp.length(n) <= S(0.0):
            return
        if wp.static(not touching):
            if not (wp.dot(bins.P[a * n_global + g] / bins.M[a * n_global + g]
                           - bins.P[c * n_global + g] / bins.M[c * n_global + g], n) > S(0.0)):
                return
        if b != a:
            n = -n
        cbin[i] = g
        coef[i] = (lat.m[i] / (S(lat.n_grids) * bins.M[b * n_global + g])) * n

    return couple


@functools.cache
def make_remove(t: Types):
    """``remove(mode, i, reaction, Pi, inv_diag, x, z, acc, r2, rz)``: modes 1
    and 2 of a projection at node i (:func:`make_projection`): r = x_i - the
    constraint's reaction, |r|^2 into ``acc[r2]``; mode 2 also z_i = Pi W r
    and r . z into ``acc[rz]``."""
    f64 = wp.float64

    @wp.func
    def remove(mode: int, i: int, reaction: t.vec, Pi: t.mat, inv_diag: wp.array(dtype=t.vec),
               x: wp.array(dtype=t.vec), z: wp.array(dtype=t.vec), acc: wp.array(dtype=f64), r2: int, rz: int):
        r = x[i] - reaction
        x[i] = r
        wp.atomic_add(acc, r2, f64(wp.dot(r, r)))
        if mode == 2:
            zi = Pi * wp.cw_mul(inv_diag[i], r)
            z[i] = zi
            wp.atomic_add(acc, rz, f64(wp.dot(r, zi)))

    return remove


@functools.cache
def make_projection(t: Types):
    """``sums`` and ``project``: the W-orthogonal projection onto B v = 0
    in three modes, Pi_i the node's boundary projector and c~_i = Pi_i c_i:
      0 velocities, W = M^-1: lambda = B v / (B W B^T), v -= c~ lambda / m
        (v then satisfies the constraints; prescribed components keep);
      1 a residual r in range(Pi), W = Pi D^-1 Pi (D = ``inv_diag``^-1):
        lambda = B W r / (B W B^T), r -= c~ lambda (the constraint's reaction
        removed: the part of r the solve can still reduce);
      2 as 1, and z = W r (the preconditioned residual of projected CG).
    Modes 1 and 2 add the constrained nodes' |r|^2 (and r . z) to ``acc`` at
    slots ``r2`` and ``rz`` (the node passes of mpm.implicit leave them out:
    a difference of the reaction's square would drown a converged residual)."""
    S = t.scalar
    f64 = wp.float64
    remove = make_remove(t)

    @warp_kernel
    def sums(
        mode: int,
        cbin: wp.array(dtype=wp.int32),
        coef: wp.array(dtype=t.vec),
        free: wp.array(dtype=t.mat),
        m: wp.array(dtype=S),
        inv_diag: wp.array(dtype=t.vec),
        x: wp.array(dtype=t.vec),
        num: wp.array(dtype=S),  # per bin: B W x (mode 0: B x)
        den: wp.array(dtype=S),  # per bin: B W B^T
    ):
        i = wp.tid()
        g = cbin[i]
        if g < 0:
            return
        c = coef[i]
        ct = free[i] * c
        if mode == 0:
            wp.atomic_add(num, g, wp.dot(c, x[i]))
            wp.atomic_add(den, g, wp.dot(ct, ct) / m[i])
        else:
            w = inv_diag[i]
            wp.atomic_add(num, g, wp.dot(ct, wp.cw_mul(w, x[i])))
            wp.atomic_add(den, g, wp.dot(ct, wp.cw_mul(w, ct)))

    @warp_kernel
    def project(
        mode: int,
        cbin: wp.array(dtype=wp.int32),
        coef: wp.array(dtype=t.vec),
        free: wp.array(dtype=t.mat),
        m: wp.array(dtype=S),
        inv_diag: wp.array(dtype=t.vec),
        num: wp.array(dtype=S),
        den: wp.array(dtype=S),
        x: wp.array(dtype=t.vec),  # in/out: v (mode 0) or r
        z: wp.array(dtype=t.vec),  # out (mode 2): W r
        acc: wp.array(dtype=f64),
        r2: int,
        rz: int,
    ):
        i = wp.tid()
        g = cbin[i]
        if g < 0:
            return
        lam = S(0.0)
        if den[g] > S(0.0):
            lam = num[g] / den[g]
        Pi = free[i]
        ct = Pi * coef[i]
        if mode == 0:
            x[i] = x[i] - ct * (lam / m[i])
            return
        remove(mode, i, ct * lam, Pi, inv_diag, x, z, acc, r2, rz)  # pyright: ignore[reportArgumentType]

    return sums, project
