"""Contact between bodies through springs on their particles
(``Scene.contact = "elastic"``), the bodies' counterpart of mpm.elastic_contact.

The bodies keep grids of their own (as with ``contact="none"``); where
they touch, a particle p of body a (half spacing r_a, mpm.scene.Scene.spacings)
is pushed out of the surface of a body b it meets, and the push's reaction
goes to the particles of b under it. Of two bodies in contact, the softer
(the smaller P-wave modulus rho c^2 at rest) meets the stiffer's surface
(a slave against a master); bodies of equal modulus meet each other's, each
at half the stiffness.

b's surface under p is taken from b's particles near p (within the reach
R = 2 s_b, s_b b's spacing): its outward normal

    n = normalize(sum_q (R - |x_pq|) x_pq / |x_pq|),    x_pq = x_p - x_q,

and, among b's particles whose column along n passes within s_b of p
(lateral distance l_q = |x_pq - (x_pq . n) n| < s_b) and lie in its top
layer (x_pq . n within s_b / 2 of the smallest), the height of p over
their centres h = sum_q w_q x_pq . n / sum_q w_q with w_q = s_b - l_q:
a flat face of b is flat wherever p lies over it (the distance to the
nearest particle would dip by (2 - sqrt 3) r_b, about a quarter of r_b,
between two of them, bumps that a rolling body rolls over). p's overlap at mid-step is

    d = r_a + r_b - lap - h - (dt / 2) (v_p - u) . n,    u = sum_q w_q v_q / sum_q w_q,

and where d > 0, p takes the normal force k d n, k = stiffness M_a
dx^(d-2) (times 1/2 between equals), and a tangential spring on its travel
relative to u, capped at mu k d (mu: Scene.friction_table), as
mpm.elastic_contact's. The particles q under it take -f in the shares
w_q / sum w: the two sides' forces cancel exactly, so the contact keeps
momentum. The forces enter P2G as body forces. The springs' energy at the
step's start, (1/2) k d^2 a particle (d without the mid-step term), joins
the step's elastic energy (mpm.stepping.status ``elastic``), so that the
step's total energy holds what the contact stores (a P2G pass over a state
alone, mpm.Solver.measure, leaves it out). ``lap`` is the overlap a
particle was sampled with (mpm.elastic_contact).

The neighbours come from a hash grid of the particles rebuilt at each
step's start (``wp.HashGrid``, grouped by body so that a query visits one
body's particles); a particle queries a body only within the reach of its
bounding box (taken in the same pass). Explicit integrator only.

Why: the grid's contact between bodies (mpm.contact) stops the approach at
the nodes of a band as wide as the kernel, wider than a rolling body's
contact patch, and each step's P2G brings it back: a disk rolling on a slab
lost 4.6 % (EMPM) and 11.4 % (TLMPM) of its acceleration at 64 cells,
more at shorter steps (RESULTS.md, "Why contact resists rolling").
"""

import functools

import numpy as np
import warp as wp

from .elastic_contact import make_coulomb_spring
from .launch import warp_kernel
from .stepping.status import StepControl, StepStatus
from .types import Types

REACH = 2.0
"""how far a particle looks for another body's particles, in that body's spacings"""


@functools.cache
def make_points(t: Types):
    """Kernel: the particles' positions as 3-vectors (2D: z = 0), for the hash grid, and
    each body's bounding box ``lo``, ``hi`` (reset to +-inf before)."""
    vec3 = wp.types.vector(3, t.scalar)

    @warp_kernel
    def points(x: wp.array(dtype=t.vec), mass: wp.array(dtype=t.scalar), body: wp.array(dtype=wp.int32),
               out: wp.array(dtype=vec3), lo: wp.array(dtype=t.vec), hi: wp.array(dtype=t.vec)):
        p = wp.tid()
        q = vec3()
        for a in range(wp.static(t.dim)):
            q[a] = x[p][a]
        out[p] = q
        if mass[p] > t.scalar(0.0):
            wp.atomic_min(lo, body[p], x[p])
            wp.atomic_max(hi, body[p], x[p])

    return points


@functools.cache
def make_body_springs(t: Types):
    """Kernel: every particle's spring force from the bodies it meets, added
    to P2G's body force (module docstring)."""
    S, vec = t.scalar, t.vec
    vec3 = wp.types.vector(3, S)

    tangential = make_coulomb_spring(t)

    @wp.func
    def under(xq: vec, n: vec, s: S, top: S, mq: S):
        """The weight s - l of a particle of b at x_p - xq in p's column (lateral
        distance l < s) and b's top layer (height within s / 2 of ``top``); 0 elsewhere."""
        along = wp.dot(xq, n)
        lat = wp.length(xq - along * n)
        if mq > S(0.0) and lat < s and along < top + S(0.5) * s:
            return s - lat
        return S(0.0)

    @wp.func
    def inside(x: vec, a: vec, b: vec):
        for i in range(wp.static(t.dim)):
            if x[i] < a[i] or x[i] > b[i]:
                return False
        return True

    @warp_kernel
    def body_springs(grid: wp.uint64, points: wp.array(dtype=vec3), x: wp.array(dtype=vec), v: wp.array(dtype=vec),
                     mass: wp.array(dtype=S), body: wp.array(dtype=wp.int32), n_bodies: int,
                     share: wp.array(dtype=S), friction: wp.array(dtype=S), modulus: wp.array(dtype=S),
                     half: wp.array(dtype=S), spacing: wp.array(dtype=S), lo: wp.array(dtype=vec),
                     hi: wp.array(dtype=vec), w: wp.array(dtype=vec),
                     lap: wp.array(dtype=S), control: StepControl, status: StepStatus,
                     body_force: wp.array(dtype=vec)):
        p = wp.tid()
        if control.skip[0] != wp.float64(0.0):
            return
        m = mass[p]
        if m <= S(0.0):
            return
        a = body[p]
        xp, vp, P = x[p], v[p], points[p]
        dt = S(control.dt[0])
        # the nearest particle of a body that a meets (module docstring)
        near = S(-1.0)
        bb = int(-1)
        q = int(0)
        for b in range(n_bodies):
            reach = S(REACH) * spacing[b]
            margin = vec(reach)
            if share[a * n_bodies + b] > S(0.0) and inside(xp, lo[b] - margin, hi[b] + margin):
                query = wp.hash_grid_query(grid, P, reach, b)
                while wp.hash_grid_query_next(query, q):
                    if mass[q] > S(0.0):
                        r = wp.length(xp - x[q])
                        if r < reach and (near < S(0.0) or r < near):
                            near = r
                            bb = b
        travel = vec()
        overlap = S(0.0)
        sampled = lap[p]  # the overlap it was sampled with, still held (< 0: its first pass)
        if bb >= 0:
            s = spacing[bb]
            reach = S(REACH) * s
            n = vec()
            query = wp.hash_grid_query(grid, P, reach, bb)
            while wp.hash_grid_query_next(query, q):
                xq = xp - x[q]
                r = wp.length(xq)
                if mass[q] > S(0.0) and r < reach and r > S(0.0):
                    n = n + ((reach - r) / r) * xq
            ln = wp.length(n)
            if ln > S(0.0):
                n = n / ln
                top = S(1.0e30)  # the smallest height over b's particles in p's column: b's top layer
                query = wp.hash_grid_query(grid, P, reach, bb)
                while wp.hash_grid_query_next(query, q):
                    xq = xp - x[q]
                    along = wp.dot(xq, n)
                    if mass[q] > S(0.0) and wp.length(xq - along * n) < s and along < top:
                        top = along
                ws, h = S(0.0), S(0.0)
                u = vec()
                query = wp.hash_grid_query(grid, P, reach, bb)
                while wp.hash_grid_query_next(query, q):
                    xq = xp - x[q]
                    wq = under(xq, n, s, top, mass[q])
                    ws += wq
                    h += wq * wp.dot(xq, n)
                    u = u + wq * v[q]
                if ws > S(0.0):
                    h = h / ws
                    u = u / ws
                    gap = h - half[a] - half[bb]  # between the two bodies' material
                    overlap = wp.max(S(0.0), -gap)
                    held = overlap
                    if sampled >= S(0.0):
                        held = wp.min(sampled, held)
                    vr = vp - u
                    d = -gap - held - S(0.5) * dt * wp.dot(vr, n)  # at mid-step
                    k = share[a * n_bodies + bb] * modulus[a]
                    # at the step's start: its energy joins the elastic energy
                    stored = overlap - held  # pyright: ignore[reportOperatorIssue]
                    if stored > S(0.0):
                        wp.atomic_add(status.elastic, 0, wp.float64(S(0.5) * k * stored * stored))
                    if d > S(0.0):
                        fn = k * d
                        ft, travel = tangential(w[p], vr, n, dt, k, friction[a * n_bodies + bb] * fn)
                        f = fn * n + ft
                        wp.atomic_add(body_force, p, f / m)  # pyright: ignore[reportArgumentType]
                        query = wp.hash_grid_query(grid, P, reach, bb)
                        while wp.hash_grid_query_next(query, q):
                            wq = under(xp - x[q], n, s, top, mass[q])
                            if wq > S(0.0):
                                wp.atomic_add(body_force, q, -(wq / ws / mass[q]) * f)
        if sampled >= S(0.0):
            overlap = wp.min(sampled, overlap)
        lap[p] = overlap
        w[p] = travel

    return body_springs


def shares(moduli: list[float]) -> np.ndarray:
    """[a, b]: the share of the stiffness with which body a meets body b's
    surface: 1 where b is stiffer, 1/2 between equals, 0 where b is softer
    and on the diagonal (module docstring)."""
    M = np.asarray(moduli, float)
    share = np.where(M[None, :] > M[:, None], 1.0, np.where(M[None, :] == M[:, None], 0.5, 0.0))
    np.fill_diagonal(share, 0.0)
    return share


class BodySprings:
    """The bodies' contact springs at a step's start (after the external loads and
    the elastic colliders' springs), adding to P2G's body force."""

    def __init__(self, model, launch, buffer, body_force):
        t, scene = model.types, model.scene
        self.model, self.launch, self.buffer, self.body_force = model, launch, buffer, body_force
        self.points_kernel, self.kernel = make_points(t), make_body_springs(t)
        dtype = np.float32 if t.precision == "float32" else np.float64
        moduli = [b.material.rho * b.material.wave_speed() ** 2 for b in scene.bodies]
        spacings = scene.spacings()
        nb = len(scene.bodies)
        self.n_bodies = nb
        scale = scene.contact_stiffness * model.dx ** (t.dim - 2)
        with wp.ScopedDevice(model.device):
            self.share = wp.array(shares(moduli).ravel().astype(dtype), dtype=t.scalar)
            self.friction = wp.array(scene.friction_table().ravel().astype(dtype), dtype=t.scalar)
            self.modulus = wp.array(np.array(moduli, dtype) * dtype(scale), dtype=t.scalar)
            self.half = wp.array(0.5 * np.array(spacings, dtype), dtype=t.scalar)
            self.spacing = wp.array(np.array(spacings, dtype), dtype=t.scalar)
            self.w = wp.zeros(model.n_particles, dtype=t.vec)  # the tangential travel [m]
            self.lap = wp.full(model.n_particles, -1.0, dtype=t.scalar)  # the overlap sampled, still held [m]
            self.points = wp.zeros(model.n_particles, dtype=wp.types.vector(3, t.scalar))
            self.lo = wp.zeros(nb, dtype=t.vec)  # each body's bounding box [m], at each step's start
            self.hi = wp.zeros(nb, dtype=t.vec)
            cell = REACH * max(spacings)
            self.grid = wp.HashGrid(*[max(1, int(np.ceil(L / cell))) for L in (list(model.domain) + [cell])[:3]],
                                    dtype=t.scalar)
        self.cell = cell

    def kernels(self) -> list:
        return [self.points_kernel, self.kernel]

    def apply(self, state) -> None:
        m = self.model
        self.lo.fill_(np.inf)
        self.hi.fill_(-np.inf)
        self.launch(self.points_kernel, m.n_particles, [state.x, m.mass, m.body, self.points, self.lo, self.hi])
        self.grid.build(self.points, self.cell, groups=m.body)
        self.launch(self.kernel, m.n_particles,
                    [self.grid.id, self.points, state.x, state.v, m.mass, m.body, self.n_bodies, self.share,
                     self.friction, self.modulus, self.half, self.spacing, self.lo, self.hi, self.w, self.lap,
                     self.buffer.control,
                     self.buffer.status, self.body_force])
