"""Contact between bodies through a global Eulerian grid (multi-velocity
field, frictionless, separation free).

Every body has its own reference grid (mpm.layout), so bodies do not see each
other in the transfers. After the grid update, each body node i (mass m_i,
velocity v_i, current position q_i) is put on the global lattice (spacing
dx), one field per body b. A node of the Eulerian scheme sits on a lattice
node g and is binned there:
    M_bg = sum_{i at g} m_i,   P_bg = sum_{i at g} m_i v_i.
A Lagrangian node (TLMPM, A-ULMPM) sits anywhere and is spread over the 2^d
lattice nodes around q_i with the linear weights w_ig = L(q_i / dx - g):
    M_bg = sum_i w_ig m_i,     P_bg = sum_i w_ig m_i v_i,
and takes back dv_i = sum_g w_ig dV_bg. Binning it to the nearest lattice
node instead let bodies interpenetrate: two bodies' nodes that round to one
lattice node from opposite sides, half a cell each, read each body's mass
there from half a cell further out, and under compression a body's nodes
bunch up and leave lattice nodes without a node of theirs (two TLMPM disks
at dx = 0.025 m overlapped by 0.24 dx, and by none with the weights). The
spreading costs no momentum (sum_i m_i dv_i = sum_g M_bg dV_bg, zero at each
g, below), though a node at the edge of the contact band takes only part of
its lattice nodes' correction: the correction is applied ``GATHER_PASSES``
times, each from the velocities the last left. Every pass runs over the body
nodes, never over the whole lattice.
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
and each body node binned at g takes dv_i = dV_bg. The momentum change
sum_b M_bg dV_bg at a global node vanishes: for two bodies the normal impulses
are equal and opposite; where three or more meet, the mass-weighted mean
correction is taken off every body present. Each lattice node hands exactly
that momentum to its nodes.

Under the implicit integrator (mpm.implicit) contact is also part of the
system: a bin where exactly two bodies a, b approach on the step's predictor
becomes the linear constraint

    B_g v = V_a . n_a + V_b . n_b = (V_a - V_b) . n_a = 0,
    V_b = sum_{i in (b, g)} (m_i / G) v_i / M_bg   (the bin's mean velocity),

i.e. row g of B has c_i = (m_i / G) / M_bg n_b at the bin's nodes of body b
(G the kernel's number of grids). For the constraints every node is binned
to its nearest lattice node, Lagrangian nodes too. The rows act on disjoint nodes, so B W B^T
is diagonal for any per-node metric W, and the W-orthogonal projection onto
B v = 0 is one bin sum and one node pass (:func:`make_contact_constraint`).
With W = M^-1 that projection is the explicit correction above. The
constraint's impulse B^T lambda gives the two bodies lambda n_a and
lambda n_b = -lambda n_a: momentum is exchanged, not created. Bins with
three or more bodies, and bins that start approaching during the solve, are
left to the explicit pass after it.
"""

import functools

import warp as wp

from .launch import warp_kernel
from .stencil import make_node_box
from .status import StepControl, StepStatus
from .types import Types

# Passes of the Lagrangian (spread) contact per step. Each pass is the
# correction above, momentum-exact; a second takes off what the first left at
# nodes on the edge of the contact band. Measured on two TLMPM disks
# (scene=two_disks, MLS, dx = 0.025 m; closest particles of the two disks in
# particle spacings, energy kept; EMPM 1.33 and 0.80): nearest binning 0.002
# and 0.58, one pass 0.92 and 0.62, two 1.56 and 0.69, three 1.83 and 0.71,
# four 1.98 and 0.72 (each pass stops the disks a little earlier).
GATHER_PASSES = 2


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


@functools.cache
def make_contact(t: Types, batched: bool = False, gather: bool = False):
    """The three contact passes, each over the body nodes (never over the
    whole lattice, which a scene of small bodies in a large domain would pay
    for every step): ``splat`` bins the nodes, ``correct`` gives each node
    its bin's correction dV_bg (every node of a bin computes it from the
    bin's sums: the same value, no per-bin array), ``clear`` zeroes the bins
    again (M and P are zero between steps: no fill of the lattice).
    ``gather`` (Lagrangian nodes): each node is spread over the 2^d lattice
    nodes around it and takes back their corrections with the same weights
    (the module docstring) instead of being binned at the nearest one.
    ``batched``: nothing in a step the driver skips (``control.skip``)."""
    S = t.scalar
    vec = t.vec
    nearest = make_nearest(t)
    cell_of, corner = make_corners(t)
    node_body = make_node_body(t)
    outward = make_outward(t)
    occupancy = make_occupancy(t)

    @warp_kernel
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
        control: StepControl,
    ):
        if wp.static(batched):
            if control.skip[0] != wp.float64(0.0):
                return
        i = wp.tid()
        m = grid_m[i]
        if m <= S(0.0):
            return
        b = node_body(i, offset, n_bodies, n_grids)
        m = m / S(n_grids)  # every kernel grid carries the body's full mass
        if wp.static(gather):
            base, frac = cell_of(grid_q[i], inv_dx)
            for k in range(wp.static(2**t.dim)):
                w, g = corner(base, frac, k, cells, strides)
                wp.atomic_add(M, b * n_global + g, w * m)
                wp.atomic_add(P, b * n_global + g, (w * m) * grid_v[i])
        else:
            g = nearest(grid_q[i], inv_dx, cells, strides)
            wp.atomic_add(M, b * n_global + g, m)
            wp.atomic_add(P, b * n_global + g, m * grid_v[i])

    @wp.func
    def correction(b: int, g: int, n_bodies: int, cells: t.ivec, strides: t.ivec, n_global: int,
                   M: wp.array(dtype=S), P: wp.array(dtype=t.vec), v_cm: t.vec):
        """Body b's dV_bg (0 unless it approaches), its momentum M_bg dV_bg, and whether it approaches."""
        dv = vec()
        dp = vec()
        hit = False
        m_b = M[b * n_global + g]
        n = outward(b, g, n_bodies, cells, strides, n_global, M)
        if wp.length(n) > S(0.0):
            rel = wp.dot(P[b * n_global + g] / m_b - v_cm, n)
            if rel > S(0.0):
                dv = -rel * n
                dp = (-rel * m_b) * n
                hit = True
        return dv, dp, hit

    @wp.func
    def bin_dv(b: int, g: int, n_bodies: int, cells: t.ivec, strides: t.ivec, n_global: int,
               rest_mass: wp.array(dtype=S), fill: S, M: wp.array(dtype=S), P: wp.array(dtype=t.vec)):
        """Body b's correction dV_bg at lattice node g, and whether g is in contact."""
        dv = vec()
        present, m_tot, p_tot, volume = occupancy(g, n_bodies, n_global, rest_mass, M, P)
        # (a node whose own share is not > 0 - a non-finite mass - takes nothing)
        if not (M[b * n_global + g] > S(0.0)) or present < 2 or volume < fill:
            return dv, False
        v_cm = p_tot / m_tot
        if present == 2:
            # the normals are opposite and the two corrections' momenta cancel (to round-off)
            dv, _dp, _hit = correction(b, g, n_bodies, cells, strides, n_global, M, P, v_cm)
        else:
            # three or more: the mean correction sum_c M_cg dV_cg / sum_c M_cg is taken off every body
            dp_sum = vec()
            for c in range(n_bodies):
                if M[c * n_global + g] > S(0.0):
                    dv_c, dp_c, hit_c = correction(c, g, n_bodies, cells, strides, n_global, M, P, v_cm)
                    if hit_c:
                        dp_sum += dp_c
                    if c == b:
                        dv = dv_c
            dv = dv - dp_sum / m_tot
        return dv, True

    @warp_kernel
    def correct(
        grid_m: wp.array(dtype=S),
        grid_q: wp.array(dtype=t.vec),
        offset: wp.array(dtype=wp.int32),
        n_bodies: int,
        n_grids: int,
        inv_dx: S,
        cells: t.ivec,
        strides: t.ivec,
        n_global: int,
        rest_mass: wp.array(dtype=S),  # rho_b dx^d per body
        fill: S,
        M: wp.array(dtype=S),
        P: wp.array(dtype=t.vec),
        grid_v: wp.array(dtype=t.vec),
        count: int,  # 1: count the nodes in contact (the first pass)
        status: StepStatus,  # contact_nodes += 1 per node taking a correction from a lattice node in contact
        control: StepControl,
    ):
        if wp.static(batched):
            if control.skip[0] != wp.float64(0.0):
                return
        i = wp.tid()
        if grid_m[i] <= S(0.0):
            return
        b = node_body(i, offset, n_bodies, n_grids)
        dv = vec()
        touching = False
        if wp.static(gather):
            # the corrections of the 2^d lattice nodes around q_i, with the weights it was spread with
            base, frac = cell_of(grid_q[i], inv_dx)
            for k in range(wp.static(2**t.dim)):
                w, g = corner(base, frac, k, cells, strides)
                dv_g, hit_g = bin_dv(b, g, n_bodies, cells, strides, n_global, rest_mass, fill, M, P)
                dv += w * dv_g
                touching = touching or hit_g
        else:
            g = nearest(grid_q[i], inv_dx, cells, strides)
            dv, touching = bin_dv(b, g, n_bodies, cells, strides, n_global, rest_mass, fill, M, P)
        if touching and count != 0:
            wp.atomic_add(status.contact_nodes, 0, wp.float64(1.0))
        grid_v[i] = grid_v[i] + dv

    @warp_kernel
    def clear(
        grid_m: wp.array(dtype=S),
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
        control: StepControl,
    ):
        if wp.static(batched):
            if control.skip[0] != wp.float64(0.0):
                return
        i = wp.tid()
        if grid_m[i] <= S(0.0):
            return
        b = node_body(i, offset, n_bodies, n_grids)
        if wp.static(gather):
            base, frac = cell_of(grid_q[i], inv_dx)
            for k in range(wp.static(2**t.dim)):
                _w, g = corner(base, frac, k, cells, strides)
                M[b * n_global + g] = S(0.0)
                P[b * n_global + g] = vec()
        else:
            g = nearest(grid_q[i], inv_dx, cells, strides)
            M[b * n_global + g] = S(0.0)
            P[b * n_global + g] = vec()

    return splat, correct, clear


@functools.cache
def make_contact_constraint(t: Types):
    """Contact as constraints of the implicit solve (the module docstring):
    ``couple`` (body nodes, after mpm.contact ``splat`` of the predictor and
    before its ``clear``: the node's active bin and c_i), ``sums`` and
    ``project`` (the W-orthogonal projection onto B v = 0).

    ``sums`` / ``project`` modes, Pi_i the node's boundary projector and
    c~_i = Pi_i c_i:
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
    nearest = make_nearest(t)
    node_body = make_node_body(t)
    outward = make_outward(t)

    @warp_kernel
    def couple(
        grid_m: wp.array(dtype=S),
        grid_q: wp.array(dtype=t.vec),
        offset: wp.array(dtype=wp.int32),
        n_bodies: int,
        n_grids: int,
        inv_dx: S,
        cells: t.ivec,
        strides: t.ivec,
        n_global: int,
        rest_mass: wp.array(dtype=S),
        fill: S,
        M: wp.array(dtype=S),
        P: wp.array(dtype=t.vec),
        cbin: wp.array(dtype=wp.int32),  # out: the node's active bin g, or -1
        coef: wp.array(dtype=t.vec),  # out: c_i = (m_i / G) / M_bg n_b
    ):
        """A node's constraint, if its bin is active: exactly two bodies a < c
        fill it and approach on the predictor, (V_a - V_c) . n_a > 0, with
        n_a = outward(a) and n_c = -n_a (every node of the bin finds the same)."""
        i = wp.tid()
        cbin[i] = -1
        if grid_m[i] <= S(0.0):
            return
        b = node_body(i, offset, n_bodies, n_grids)
        g = nearest(grid_q[i], inv_dx, cells, strides)
        present = int(0)
        volume = S(0.0)
        a = int(-1)  # the first and second body present
        c = int(-1)
        for d in range(n_bodies):
            m = M[d * n_global + g]
            if m > S(0.0):
                present += 1
                volume += m / rest_mass[d]
                if a < 0:
                    a = d
                else:
                    c = d
        if not (M[b * n_global + g] > S(0.0)) or present != 2 or volume < fill:
            return
        n = outward(a, g, n_bodies, cells, strides, n_global, M)
        if wp.length(n) <= S(0.0):
            return
        if not (wp.dot(P[a * n_global + g] / M[a * n_global + g] - P[c * n_global + g] / M[c * n_global + g], n)
                > S(0.0)):
            return
        if b != a:
            n = -n
        cbin[i] = g
        coef[i] = (grid_m[i] / (S(n_grids) * M[b * n_global + g])) * n

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
        r = x[i] - ct * lam
        x[i] = r
        wp.atomic_add(acc, r2, f64(wp.dot(r, r)))
        if mode == 2:
            zi = Pi * wp.cw_mul(inv_diag[i], r)
            z[i] = zi
            wp.atomic_add(acc, rz, f64(wp.dot(r, zi)))

    return couple, sums, project


class Contact:
    """Contact between the bodies of ``model`` on the device: the bins (M
    and P per body on the global lattice, zero between steps) and the passes
    over the body nodes (:meth:`resolve`; :meth:`couple` for the implicit
    solve's constraints, mpm.implicit). ``lagrangian``: the body nodes move
    with the bodies (TLMPM, A-ULMPM) and are spread with linear weights."""

    def __init__(self, model, launch, implicit: bool, control, batched: bool = False, lagrangian: bool = False):
        t = model.types
        self.model, self.launch, self.control = model, launch, control
        self.splat, self.correct, self.clear = make_contact(t, batched, gather=lagrangian)
        self.passes = GATHER_PASSES if lagrangian else 1
        # the implicit solve's constraints bin every node to one lattice node (disjoint rows)
        self.bin, _, self.unbin = make_contact(t, batched) if implicit else (None, None, None)
        self.constraint = make_contact_constraint(t) if implicit else ()
        n_bodies, n_global = len(model.scene.bodies), model.n_nodes
        self.inv_dx = t.scalar(1.0 / model.dx)
        self.cells, self.strides = t.ivec(*model.cells), t.ivec(*model.strides)
        self.fill = t.scalar(model.scene.contact_fill)
        with wp.ScopedDevice(model.device):
            self.M = wp.zeros(n_bodies * n_global, dtype=t.scalar)
            self.P = wp.zeros(n_bodies * n_global, dtype=t.vec)
            self.rest_mass = wp.array([b.material.rho * model.dx**t.dim for b in model.scene.bodies],
                                      dtype=t.scalar)

    def kernels(self) -> list:
        return list(dict.fromkeys([self.splat, self.correct, self.clear, *self.constraint]
                                  + ([self.bin, self.unbin] if self.constraint else [])))

    def common(self, layout) -> list:
        """What every pass reads: the layout's node boxes, the body count,
        the kernel's grids and the global lattice."""
        m = self.model
        return [layout.offset_d, len(m.scene.bodies), m.kernel.n_grids, self.inv_dx, self.cells,
                self.strides, m.n_nodes]

    def resolve(self, grid, layout, status) -> None:
        """Frictionless contact on the grid velocities (module docstring)."""
        common = self.common(layout)
        ctl = self.control
        bins = [self.M, self.P]
        for k in range(self.passes):
            self.launch(self.splat, layout.n_nodes, [grid.m, grid.v, grid.q, *common, *bins, ctl])
            self.launch(self.correct, layout.n_nodes, [
                grid.m, grid.q, *common, self.rest_mass, self.fill, *bins, grid.v, int(k == 0), status, ctl])
            self.launch(self.clear, layout.n_nodes, [grid.m, grid.q, *common, *bins, ctl])

    def couple(self, grid, layout, cbin, coef) -> None:
        """The implicit solve's constraints from the predictor in ``grid.v``:
        per node its active bin ``cbin`` and coefficient ``coef``
        (:func:`make_contact_constraint`; the bins are zero again after)."""
        common = self.common(layout)
        n = layout.n_nodes
        dev = self.model.device
        bins = [self.M, self.P]
        wp.launch(self.bin, n, device=dev, inputs=[grid.m, grid.v, grid.q, *common, *bins, self.control])
        wp.launch(self.constraint[0], n, device=dev, inputs=[
            grid.m, grid.q, *common, self.rest_mass, self.fill, *bins, cbin, coef])
        wp.launch(self.unbin, n, device=dev, inputs=[grid.m, grid.q, *common, *bins, self.control])
