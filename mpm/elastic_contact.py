"""Colliders whose ``boundary`` is ``elastic``: they act on the particles
that touch them, through springs, instead of on the grid's nodes.

A particle p of half spacing r_p (half the distance between neighbouring
particles at sampling, mpm.scene.Scene.spacings) at the signed distance phi from
the solid's surface (mpm.collider_motion: outward normal n, the solid's
velocity u at the surface point) overlaps it, at mid-step, by

    d = r_p - lap - phi - (dt / 2) v_r . n,

v_r its velocity relative to the solid at the surface point (extrapolated
by C, as mpm.surface does at a node; taken at mid-step, a strike gained
energy with the overlap of the step's start). Where d > 0 the collider
pushes it out with the normal force

    f_n = max(0, k d - eta v_n) n,    k = stiffness M_b dx^(d-2)   [N/m; 2D: N/m per m],
    eta = min(2 damping sqrt(k m_p), m_p / dt)   [kg/s; 2D: per m],

M_b = rho c^2 its body's P-wave modulus at rest (mpm.materials),
``stiffness`` the collider's factor, v_n = v_r . n the particle's normal
velocity relative to the solid (v_r above; < 0 approaching) and
``damping`` zeta the collider's normal dashpot, a fraction of the critical
damping of the particle (mass m_p) on its spring (Cundall and Strack's
dashpot: it resists the approach and the recovery alike, and the force
never pulls; 0, the default, none), and holds it by Coulomb friction as a
tangential spring: the particle's tangential travel relative to the solid
while it touches, w (reset when it leaves), gives f_t = -k w, capped at
mu |f_n| (w then shortened to the cap: the particle slides). The force
enters P2G as a body force f / m_p (mpm.p2g). Its impulse f dt (the
dashpot's with it) goes to the collider's row of the step's status, with
its angular impulse about the
collider's centre (taken at the surface point x_p - phi n), and to the
conditions' impulse, each summed over the kernel's grids as the grid rule's
are; a rigid body takes them back (mpm.rigid_coupling). The work a moving
solid does on the springs, f . u dt where positive, joins the boundary
conditions' (the blow-up detection allows for it,
mpm.stepping.detection). The springs' normal energy at the step's start,
(1/2) k (max(0, r_p - phi) - lap)^2 a particle, joins the step's elastic
energy (mpm.stepping.status ``elastic``), so the run's total holds what the
springs store (the tangential springs' is left out, and so is all of it
from a P2G pass over a state alone, mpm.Solver.measure).

lap: a body sampled overlapping an elastic solid (particles laid on the
lattice, a face between them: up to r_p) would be thrown off by its
springs' energy at the first step; the overlap each particle has at its
first pass (lap < 0 until then) is taken as its rest instead, and it
gives it up as it leaves: lap never grows, and shrinks to the particle's
overlap as that shrinks (against each solid, the smaller of lap and its
overlap with that solid is its rest).

Why: the grid rule (mpm.surface) stops the material's approach at the nodes
within half a cell of the surface, a band of the kernel's width wider than
a rolling body's contact patch, and each step's P2G brings back the
approach it took out; the loss is per step, so a body rolling on a collider
lost more at shorter steps (RESULTS.md, "Why contact resists rolling"). A
spring stores what it takes and gives it back. Its cost: a stiffness to
choose (the step rule is unchanged: the spring's frequency, 2 sqrt(k / m_p),
stays below the wave's at stiffness <= 1), an overlap of f / k, and no
contact before the particles reach the surface. Explicit integrator only:
an implicit step would need the springs in its system (mpm.implicit).

The dashpot and the step: explicitly, one step takes eta dt / m_p of the
particle's normal velocity away, and 2 zeta sqrt(k / m_p) dt is 2 zeta 0.8
sqrt(stiffness) in 2D (ppc 4) and 2 zeta 1.13 sqrt(stiffness) in 3D (ppc
8) at the step rule's cfl 0.4: above 2 (the velocity reversed, energy
added) for zeta = 1 from stiffness 1.6 in 2D and 0.8 in 3D; unbounded, a
block dropped at 1 m/s on a collider of stiffness 4 and damping 1 stopped
as unstable within 60 steps in 2D and 3D. eta is therefore capped at
m_p / dt (eta dt / m_p <= 1: a step's dashpot at most stops the particle's
normal approach, never turns it round, so it adds no energy), and the step
rule is unchanged (that block bounces back slower with the dashpot than
without it, at stiffness 0.5 and 4, 2D and 3D: tests/mpm/test_elastic_contact.py).
The dashpot damps the particles on their springs; a body's own elastic
modes, whose mass is its own, it barely reaches (RESULTS.md: the rolling
disk's hop is about as large at damping 1 as at 0).
"""

import functools

import numpy as np
import warp as wp

from .collider_device import make_add_impulse, make_add_torque
from .collider_motion import make_centre, make_place
from .collider_shapes import make_collider_data
from .colliders import BOUNDARIES, ELASTIC, RIGID
from .launch import warp_kernel
from .rigid import solids
from .stepping.status import StepControl, StepStatus
from .types import Types

SPRINGS = BOUNDARIES.index(ELASTIC)


@functools.cache
def make_coulomb_spring(t: Types):
    """wp.func (w, vr, n, dt, k, cap) -> (f_t, w'): a particle's tangential
    spring of stiffness k [N/m] on its travel w along the surface of normal
    n, moved by the relative velocity vr over dt, its force capped at ``cap``
    (mu |f_n|) where it slides, the travel then shortened to the cap."""
    S, vec = t.scalar, t.vec

    @wp.func
    def coulomb_spring(w: vec, vr: vec, n: vec, dt: S, k: S, cap: S):
        s = w + (vr - wp.dot(vr, n) * n) * dt
        s = s - wp.dot(s, n) * n
        ft = -k * s
        lt = wp.length(ft)
        if lt > cap:
            ft = ft * (cap / lt)
            s = -ft / k
        return ft, s

    return coulomb_spring


@functools.cache
def make_springs(t: Types, elastic_kinds: tuple[str, ...], loads: bool):
    """Kernel: every particle's spring force from the elastic colliders, as
    the body force of P2G (added to the external loads' with ``loads``:
    they wrote it first), the tangential travel ``w`` kept per particle,
    the impulses into the colliders' rows (module docstring).
    ``elastic_kinds``: the scene's collider kinds (mpm.collider_device.kinds_of; ELASTIC among them)."""
    S, vec, Data = t.scalar, t.vec, make_collider_data(t)
    kinds = elastic_kinds
    place, centre = make_place(t, kinds), make_centre(t)
    add_impulse, add_torque = make_add_impulse(t), make_add_torque(t)
    tangential = make_coulomb_spring(t)

    @warp_kernel
    def springs(x: wp.array(dtype=vec), v: wp.array(dtype=vec), C: wp.array(dtype=t.mat),
                Fsn: wp.array(dtype=t.mat), mass: wp.array(dtype=S),
                body: wp.array(dtype=wp.int32), modulus: wp.array(dtype=S), half: wp.array(dtype=S),
                colliders: wp.array(dtype=Data), w: wp.array(dtype=vec), lap: wp.array(dtype=S), grids: S,
                control: StepControl, status: StepStatus, body_force: wp.array(dtype=vec)):
        p = wp.tid()
        if control.skip[0] != wp.float64(0.0):
            return
        m = mass[p]
        if m <= S(0.0):
            return
        time = S(control.t[0])
        dt = S(control.dt[0])
        b = vec()
        if wp.static(loads):
            b = body_force[p]
        xp, vp, bp = x[p], v[p], body[p]
        travel = vec()
        sampled = lap[p]  # the overlap it was sampled with, still held (module docstring; < 0: its first pass)
        overlap = S(0.0)  # the deepest overlap with an elastic solid now
        for k in range(colliders.shape[0]):
            c = colliders[k]
            if c.boundary == SPRINGS:
                phi, n, u = place(c, xp, time)
                overlap = wp.max(overlap, half[bp] - phi)
                held = wp.max(S(0.0), half[bp] - phi)
                if sampled >= S(0.0):
                    held = wp.min(sampled, held)
                vr = vp - phi * (C[p] * (wp.inverse(Fsn[p]) * n)) - u  # at the surface point
                d = half[bp] - held - phi - S(0.5) * dt * wp.dot(vr, n)  # at mid-step (module docstring)
                kp = c.stiffness * modulus[bp]
                # the overlap at the step's start, beyond its rest (module docstring)
                stored = wp.max(S(0.0), half[bp] - phi) - held  # pyright: ignore[reportOperatorIssue]
                if stored > S(0.0):
                    wp.atomic_add(status.elastic, 0, wp.float64(S(0.5) * kp * stored * stored))
                if d > S(0.0):
                    # the dashpot: 2 zeta sqrt(k m_p), at most m_p / dt (module docstring); never pulls
                    eta = wp.min(S(2.0) * c.damping * wp.sqrt(kp * m), m / dt)
                    fn = wp.max(S(0.0), kp * d - eta * wp.dot(vr, n))
                    ft, travel = tangential(w[p], vr, n, dt, kp, c.friction * fn)
                    f = fn * n + ft
                    b = b + f / m
                    J = (grids * dt) * f  # the rows sum every kernel grid's, as the grid rule's do
                    add_impulse(status.collider_impulse, k, J)
                    for a in range(wp.static(t.dim)):
                        wp.atomic_add(status.boundary_impulse, a, wp.float64(J[a]))
                    work = wp.dot(J, u)  # what a moving solid puts in
                    if work > S(0.0):
                        wp.atomic_add(status.boundary_work, 0, wp.float64(work))
                    if wp.static(RIGID in kinds):
                        add_torque(status.collider_torque, k, xp - phi * n - centre(c, time), J)
        if sampled >= S(0.0):
            overlap = wp.min(sampled, overlap)
        lap[p] = overlap
        w[p] = travel
        body_force[p] = b

    return springs


def elastic(scene) -> bool:
    """Whether any collider or rigid body of ``scene`` is elastic."""
    return any(c.boundary == "elastic" for c in solids(scene))


class Springs:
    """The elastic colliders' pass at a step's start (after the external
    loads), writing P2G's body force."""

    def __init__(self, model, launch, buffer, body_force, kinds: tuple[str, ...], colliders):
        t = model.types
        self.model, self.launch, self.buffer, self.body_force = model, launch, buffer, body_force
        self.colliders = colliders  # the packed records (mpm.conditions), rewritten for rigid bodies
        self.kernel = make_springs(t, kinds, model.loads is not None)
        scene = model.scene
        dtype = np.float32 if t.precision == "float32" else np.float64
        moduli = [b.material.rho * b.material.wave_speed() ** 2 * model.dx ** (t.dim - 2) for b in scene.bodies]
        halves = [0.5 * s for s in scene.spacings()]
        with wp.ScopedDevice(model.device):
            self.modulus = wp.array(np.array(moduli, dtype), dtype=t.scalar)
            self.half = wp.array(np.array(halves, dtype), dtype=t.scalar)
            self.w = wp.zeros(model.n_particles, dtype=t.vec)  # the tangential travel [m]
            # the overlap sampled, still held [m] (-1: not seen yet)
            self.lap = wp.full(model.n_particles, -1.0, dtype=t.scalar)
        self.grids = t.scalar(model.kernel.n_grids)  # the status rows sum every kernel grid's

    def kernels(self) -> list:
        return [self.kernel]

    def apply(self, state) -> None:
        b = self.buffer
        self.launch(self.kernel, self.model.n_particles,
                    [state.x, state.v, state.C, state.Fsn, self.model.mass, self.model.body, self.modulus, self.half,
                     self.colliders, self.w, self.lap, self.grids, b.control, b.status, self.body_force])
