"""Contact between bodies through a global Eulerian grid (multi-velocity
field, separation free, frictionless or with Coulomb friction).

Every body has its own reference grid (mpm.reference_grids), so bodies do not see each
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
cells apart. A body is present at g where M_bg > share rho_b dx^d
(``Scene.contact_share``, 0 by default: any mass). There, body b's outward
normal is (``Scene.contact_normal``, mpm.contact.lattice ``make_outward``)
    n_b = normalize(grad (M_others - M_b)),   M_others = sum of the other
bodies present at that node (central differences), which for two bodies is
the common normal, n_a = -n_b ("difference"), or the normal of the body
present with the largest grad M_c / (rho_c dx^d) ("max_gradient"), or of
the stiffest body present, the largest gradient among equals ("stiffer":
the face of a stiff body keeps its normal under a softer body's corner,
whose tilted normal turned sliding into approach: a block at 30 deg with
mu = 0.5 went 0.055 m/s^2 against 0.657 with max_gradient, EMPM, 128
cells). With the
centre-of-mass velocity v_cm = sum P / sum M, a body approaching the others,
(v_b - v_cm) . n_b > 0, loses that normal component:
    dV_bg = -((v_b - v_cm) . n_b) n_b,
and each body node binned at g takes dv_i = dV_bg. The momentum change
sum_b M_bg dV_bg at a global node vanishes: for two bodies the normal impulses
are equal and opposite; where three or more meet, the mass-weighted mean
correction is taken off every body present. Each lattice node hands exactly
that momentum to its nodes.

With Coulomb friction (Bardenhagen, Brackbill and Sulsky 2000, Comput.
Methods Appl. Mech. Eng. 187, 529-541) an approaching body also loses
tangential velocity relative to v_cm, u_t = (v_b - v_cm) - rel n_b with
rel = (v_b - v_cm) . n_b > 0, up to mu times the normal change:
    dV_bg = -rel n_b - min(1, mu rel / |u_t|) u_t,
so the body sticks (moves with v_cm) while |u_t| <= mu rel and slides
otherwise. For two bodies mu is their pair's (Scene.friction_table) and
M_a u_a = -M_b u_b, so the two tangential impulses cancel as the normal ones
do; with three or more, mu is the mass-weighted mean over the others present
and the mean correction keeps momentum. Every correction takes kinetic
energy relative to v_cm only: the contact's work (``contact_work``,
mpm.stepping.status) is never positive but for round-off.

Under the implicit integrator contact is also a constraint of the system
(mpm.contact.constraint), and friction part of the solve
(mpm.contact.friction); the lattice reads shared by all are in
mpm.contact.lattice.
"""

import functools

import numpy as np
import warp as wp

from .constraint import make_contact_constraint
from .friction import make_friction_constraint
from .lattice import make_bins, make_lattice_point, make_node_body, make_occupancy, make_outward, make_present
from ..lattice import make_lattice, make_node_mass
from ..launch import warp_kernel
from ..stepping.status import StepControl, StepStatus
from ..types import Types

# Passes of the Lagrangian (spread) contact per step. Each pass is the
# correction above, momentum-exact; a second takes off what the first left at
# nodes on the edge of the contact band. Measured on two TLMPM disks
# (scene=two_disks, MLS, dx = 0.025 m; closest particles of the two disks in
# particle spacings, energy kept; EMPM 1.33 and 0.80): nearest binning 0.002
# and 0.58, one pass 0.92 and 0.62, two 1.56 and 0.69, three 1.83 and 0.71,
# four 1.98 and 0.72 (each pass stops the disks a little earlier).
GATHER_PASSES = 2


@functools.cache
def make_bin_dv(t: Types, friction: bool = False, normal: str = "difference"):
    """``bin_dv(lat, bins, b, g) -> (dV_bg, in contact)``: body b's
    correction at lattice node g (the module docstring), and whether g is
    in contact. ``friction``: Coulomb friction on the tangential part (the
    module docstring); frictionless code otherwise."""
    S = t.scalar
    vec = t.vec
    Lattice = make_lattice(t)
    Bins = make_bins(t)
    outward = make_outward(t, normal)
    occupancy = make_occupancy(t)
    present_at = make_present(t)

    @wp.func
    def correction(lat: Lattice, bins: Bins, b: int, g: int, v_cm: t.vec, mu: S):
        """Body b's dV_bg (0 unless it approaches), its momentum M_bg dV_bg, and whether it approaches."""
        dv = vec()
        dp = vec()
        hit = False
        m_b = bins.M[b * lat.n_global + g]
        n = outward(lat, bins, b, g)
        if wp.length(n) > S(0.0):
            u = bins.P[b * lat.n_global + g] / m_b - v_cm
            rel = wp.dot(u, n)
            if rel > S(0.0):
                dv = -rel * n
                dp = (-rel * m_b) * n
                if wp.static(friction):
                    ut = u - rel * n  # the tangential velocity relative to the bin's centre of mass
                    lt = wp.length(ut)
                    if lt > S(0.0):
                        dv = dv - ut * wp.min(S(1.0), mu * rel / lt)  # stick, or slide with |dV_t| = mu |dV_n|
                        dp = m_b * dv
                hit = True
        return dv, dp, hit

    @wp.func
    def friction_of(lat: Lattice, bins: Bins, b: int, g: int, m_tot: S):
        """mu of body b against the others present at g, weighted by their mass there."""
        num = S(0.0)
        for c in range(lat.n_bodies):
            m_c = bins.M[c * lat.n_global + g]
            if c != b and present_at(lat, bins, c, g):
                num += m_c * bins.mu[b * lat.n_bodies + c]
        return num / (m_tot - bins.M[b * lat.n_global + g])

    @wp.func
    def bin_dv(lat: Lattice, bins: Bins, b: int, g: int):
        dv = vec()
        present, m_tot, p_tot, volume, a, c = occupancy(lat, bins, g)
        # (a body not present at g - a fringe, or a non-finite mass - takes nothing)
        if not present_at(lat, bins, b, g) or present < 2 or volume < bins.fill:
            return dv, False
        v_cm = p_tot / m_tot
        mu = S(0.0)
        if present == 2:
            if wp.static(friction):
                mu = bins.mu[a * lat.n_bodies + c]  # the pair's (symmetric)
            # the normals are opposite and the two corrections' momenta cancel (to round-off)
            dv, _dp, _hit = correction(lat, bins, b, g, v_cm, mu)
        else:
            # three or more: the mean correction sum_c M_cg dV_cg / sum_c M_cg is taken off every body
            dp_sum = vec()
            for k in range(lat.n_bodies):
                if present_at(lat, bins, k, g):
                    if wp.static(friction):
                        mu = friction_of(lat, bins, k, g, m_tot)
                    dv_k, dp_k, hit_k = correction(lat, bins, k, g, v_cm, mu)
                    if hit_k:
                        dp_sum += dp_k
                    if k == b:
                        dv = dv_k
            dv = dv - dp_sum / m_tot
        return dv, True

    return bin_dv


@functools.cache
def make_contact(t: Types, batched: bool = False, gather: bool = False, friction: bool = False,
                 normal: str = "difference"):
    """The three contact passes, each over the body nodes (never over the
    whole lattice, which a scene of small bodies in a large domain would pay
    for every step): ``splat`` bins the nodes, ``correct`` gives each node
    its bin's correction dV_bg (every node of a bin computes it from the
    bin's sums: the same value, no per-bin array), ``clear`` zeroes the bins
    again (M and P are zero between steps: no fill of the lattice).
    ``gather`` (Lagrangian nodes): each node is spread over the 2^d lattice
    nodes around it and takes back their corrections with the same weights
    (the module docstring) instead of being binned at the nearest one.
    ``batched``: nothing in a step the driver skips (``control.skip``).
    ``friction``: Coulomb friction between the bodies (:func:`make_bin_dv`);
    ``normal``: the rule of the bodies' normals (mpm.CONTACT_NORMALS)."""
    S = t.scalar
    vec = t.vec
    Lattice = make_lattice(t)
    Bins = make_bins(t)
    node_mass = make_node_mass(t, batched)
    node_body = make_node_body(t)
    lattice_point = make_lattice_point(t, gather)
    bin_dv = make_bin_dv(t, friction, normal)
    n_points = 2**t.dim if gather else 1  # the lattice nodes a body node is put on

    @warp_kernel
    def splat(lat: Lattice, bins: Bins, control: StepControl):
        i = wp.tid()
        m = node_mass(lat, control, i)  # pyright: ignore[reportArgumentType]
        if m <= S(0.0):
            return
        b = node_body(lat, i)  # pyright: ignore[reportArgumentType]
        m = m / S(lat.n_grids)  # every kernel grid carries the body's full mass
        for k in range(wp.static(n_points)):
            w, g = lattice_point(lat, lat.q[i], k)
            wp.atomic_add(bins.M, b * lat.n_global + g, w * m)
            wp.atomic_add(bins.P, b * lat.n_global + g, (w * m) * lat.v[i])

    @warp_kernel
    def correct(
        lat: Lattice,  # v: the corrected velocities
        bins: Bins,
        count: int,  # 1: count the nodes in contact (the first pass)
        status: StepStatus,  # contact_nodes += 1 per node taking a correction from a lattice node in contact;
        # contact_work += (m_i / G) (|v_i + dv_i|^2 - |v_i|^2) / 2 [J]
        control: StepControl,
    ):
        i = wp.tid()
        m = node_mass(lat, control, i)  # pyright: ignore[reportArgumentType]
        if m <= S(0.0):
            return
        b = node_body(lat, i)  # pyright: ignore[reportArgumentType]
        dv = vec()
        touching = False
        for k in range(wp.static(n_points)):  # the corrections, with the weights the node was spread with
            w, g = lattice_point(lat, lat.q[i], k)
            dv_g, hit_g = bin_dv(lat, bins, b, g)
            dv += w * dv_g
            touching = touching or hit_g
        if touching and count != 0:
            wp.atomic_add(status.contact_nodes, 0, wp.float64(1.0))
        v = lat.v[i]
        v_new = v + dv
        if touching:
            m_body = wp.float64(m) / wp.float64(lat.n_grids)  # every kernel grid carries the body's full mass
            wp.atomic_add(status.contact_work, 0, wp.float64(0.5) * m_body
                          * (wp.float64(wp.dot(v_new, v_new)) - wp.float64(wp.dot(v, v))))
        lat.v[i] = v_new

    @warp_kernel
    def clear(lat: Lattice, bins: Bins, control: StepControl):
        i = wp.tid()
        if node_mass(lat, control, i) <= S(0.0):  # pyright: ignore[reportArgumentType]
            return
        b = node_body(lat, i)  # pyright: ignore[reportArgumentType]
        for k in range(wp.static(n_points)):
            _w, g = lattice_point(lat, lat.q[i], k)
            bins.M[b * lat.n_global + g] = S(0.0)
            bins.P[b * lat.n_global + g] = vec()

    return splat, correct, clear


def stiffness_rank(bodies) -> np.ndarray:
    """Per body, its place among the bodies by P-wave modulus rho c^2 [Pa]
    at rest (c the material's wave speed), 0 the softest; bodies of equal
    modulus (to 12 digits: rho (sqrt(M / rho))^2 differs from M in the last
    bits) share a place (the contact normal "stiffer", mpm.CONTACT_NORMALS)."""
    moduli = [float(f"{b.material.rho * b.material.wave_speed() ** 2:.12g}") for b in bodies]
    return np.unique(moduli, return_inverse=True)[1].astype(np.int32)


class Contact:
    """Contact between the bodies of ``model`` on the device: the bins (M
    and P per body on the global lattice, zero between steps) and the passes
    over the body nodes (:meth:`resolve`; :meth:`couple` for the implicit
    solve's constraints, mpm.implicit). ``lagrangian``: the body nodes move
    with the bodies (TLMPM, A-ULMPM) and are spread with linear weights.
    Coulomb friction is compiled in only where a pair of bodies has mu > 0
    (``Scene.contact = "friction"``)."""

    def __init__(self, model, launch, implicit: bool, control, batched: bool = False, lagrangian: bool = False):
        t = model.types
        self.model, self.launch, self.control = model, launch, control
        mu = model.scene.friction_table() if model.scene.contact == "friction" else np.zeros((1, 1))
        self.friction = bool(mu.max() > 0.0)
        normal = model.scene.contact_normal
        self.splat, self.correct, self.clear = make_contact(t, batched, gather=lagrangian, friction=self.friction,
                                                            normal=normal)
        self.passes = GATHER_PASSES if lagrangian else 1
        # the implicit solve's constraints bin every node to one lattice node (disjoint rows)
        self.bin, _, self.unbin = make_contact(t, batched) if implicit else (None, None, None)
        self.constraint: tuple = make_contact_constraint(t, normal, touching=self.friction) if implicit else ()
        # with friction the solve's projection has a stuck bin's d rows (mpm.contact.friction)
        self.sliding: tuple = make_friction_constraint(t, normal) if implicit and self.friction else ()
        n_bodies, n_global = len(model.scene.bodies), model.n_nodes
        self.inv_dx = t.scalar(1.0 / model.dx)
        self.fill = t.scalar(model.scene.contact_fill)
        with wp.ScopedDevice(model.device):
            self.M = wp.zeros(n_bodies * n_global, dtype=t.scalar)
            self.P = wp.zeros(n_bodies * n_global, dtype=t.vec)
            self.rest_mass = wp.array([b.material.rho * model.dx**t.dim for b in model.scene.bodies],
                                      dtype=t.scalar)
            self.mu = wp.array(mu.ravel() if self.friction else [0.0], dtype=t.scalar)
            self.rank = wp.array(stiffness_rank(model.scene.bodies), dtype=wp.int32)
        self.bins = make_bins(t)()
        self.bins.M, self.bins.P, self.bins.rest_mass, self.bins.fill = self.M, self.P, self.rest_mass, self.fill
        self.bins.mu = self.mu
        self.bins.rank = self.rank
        self.bins.share = t.scalar(model.scene.contact_share)

    def kernels(self) -> list:
        return list(dict.fromkeys([self.splat, self.correct, self.clear, *self.constraint]
                                  + ([self.bin, self.unbin] if self.constraint else [])
                                  + list(self.sliding)))

    def resolve(self, grid, layout, status) -> None:
        """Contact on the grid velocities (module docstring)."""
        args = [grid.lattice, self.bins]
        for k in range(self.passes):
            self.launch(self.splat, layout.n_nodes, [*args, self.control])
            self.launch(self.correct, layout.n_nodes, [*args, int(k == 0), status, self.control])
            self.launch(self.clear, layout.n_nodes, [*args, self.control])

    def couple(self, grid, layout, cbin, coef, friction=None) -> None:
        """The implicit solve's constraints from the predictor in ``grid.v``:
        per node its active bin ``cbin`` and coefficient ``coef``
        (:func:`make_contact_constraint`; the bins are zero again after);
        with friction, ``friction`` = (bin normal, state, mu, load) per bin
        (mpm.contact.friction ``frame``)."""
        args = [grid.lattice, self.bins]
        n = layout.n_nodes
        dev = self.model.device
        wp.launch(self.bin, n, device=dev, inputs=[*args, self.control])
        wp.launch(self.constraint[0], n, device=dev, inputs=[*args, cbin, coef])
        if friction is not None:
            wp.launch(self.sliding[0], n, device=dev, inputs=[*args, cbin, *friction])
        wp.launch(self.unbin, n, device=dev, inputs=[*args, self.control])
