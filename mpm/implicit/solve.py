"""Backward Euler on the grid velocities (A-ULMPM paper eq. 24-27), solved
as the minimisation of the incremental potential (Gast et al. 2015).

Every particle's deformation at the end of the step follows the grid
velocities v exactly as G2P will advance it, in the body's reference
configuration:

    F_p(v) = (F^sn_p + dt D_p(v)) F^0s_p,   D_p(v) = 1/G sum_g sum_i v_i g_ip^T,

with g_ip the force's weight gradient (MLS: K_p r_ip W_ip; APIC/PIC: the
kernel's gradient), the same as P2G's force and G2P's velocity gradient. The
step minimises, over the velocities of the nodes the boundary conditions
leave free,

    E(v) = sum_i 1/2 m_i |v_i - v*_i|^2
           + G sum_p V_p^0 [psi(F_p(v)) + dt J_p eta |sym L_p(v)|^2],

v* the explicit predictor without stress (momentum / mass + dt g), G the
kernel's number of grids (each receives the particles' full mass), J_p and
L_p(v) = D_p(v) (F^sn_p)^-1 the volume ratio and velocity gradient of a
viscous model (eta its viscosity; J lagged at the step's start). Its
gradient is the residual of backward Euler,

    R_i = m_i (v_i - v*_i) + dt sum_p S_p g_ip,
    S_p = V_p^0 [P(F_p) F^0s,T + J 2 eta sym(L_p) (F^sn)^-T],

(the explicit step is v = v* - dt/m sum S g at F^n), and its Hessian acts as

    (A dv)_i = m_i dv_i + dt sum_p dS_p g_ip,
    dS_p = V_p^0 [dP(dt D_p(dv) F^0s) F^0s,T + J 2 eta sym(D_p(dv) (F^sn)^-1) (F^sn)^-T],

with dP the material's stress differential (mpm.materials.differential),
projected to semi-definite per particle. Newton's method: A dv = -R by
conjugate gradients with the Jacobi preconditioner (the exact diagonal of
A), then a backtracking line search on E (Armijo, or a halving of |R|, which
is what progress looks like once E's decrease is below its round-off). Constrained nodes (mpm.grid
``make_constraints``) take part through the projector Pi_i onto their free
velocities: R, A dv and the preconditioner are projected. Bodies in contact
add the linear constraints B v = 0 of mpm.contact (equal normal velocities
of two approaching bodies in a global bin): the start is projected onto them
and CG runs projected (Gould, Hribar & Nocedal 2001), z = W (r - B^T lambda)
with W = Pi D^-1 Pi and lambda making B z = 0, so every iterate keeps them;
the residual is measured without the constraints' reaction. With Coulomb
friction between the bodies a bin sticks (its whole relative velocity
constrained) or slides (its normal row, and the Coulomb load in v*): the
solve starts with every frictional bin stuck and is repeated from its last
solution while a bin changes state or its load moves (mpm.contact.friction).
Coulomb friction at a collider is decided the same way per node under
the surface rule (mpm.implicit.rough; the node rule applies it after the
solve, as it was): a node in frictional contact starts stuck (its
surface point fixed to the collider, Pi = 0), and slides (its normal row,
the load mu R_n against its slip in v*) once its tangential reaction
leaves the cone. Applied after the solve with the solve's normal reaction,
as earlier versions did, it let a disk rolling on a collider slip 0.2-0.8
cells over 0.3 s.

One-sided constraints (a separating collider, a slip wall: held only while
the body moves into them) are first decided from the predictor, which
knows nothing of the stress. Under the surface rule (mpm.surface) the solve
is repeated from its solution while their classification at the velocity
without their reaction, v - reaction, changes: a held node whose reaction
pulls is let go, a free node the solution moves into the solid is held.
Decided once, a node the solution moved into a plate stayed free, the
body's surface entered the solid unopposed and its stress was never paid
for: a cylinder pressed by separating plates at 2 ms steps stored 72 %
more energy than the plates' work. All kinds of rounds together make at
most ROUNDS solves per step (RIGID_ROUNDS with rigid bodies); a step still
changing after them is counted (``NewtonReport.unsettled``, the nodes and
bins its last solve does not satisfy) and keeps its last solve.

A plastic model's return mapping has run in P2G: F^0s is the returned
elastic state, so the energy is the elastic predictor's for the step.
"""

import numpy as np
import warp as wp

from ..rigid import solids
from .system import (DOT_A, DOT_B, ENERGY, MOMENTUM2, RESIDUAL2, STIFFNESS2, make_apply,
                              make_boundary_work, make_evaluate, make_friction, make_node_kernels)
from ..materials.differential import make_tangent_type
from .rough import NONE, make_rough
from .rounds import Rounds
from ..stepping.status import NewtonReport

ARMIJO = 1.0e-4  # sufficient decrease of E along the Newton direction
BACKTRACKS = 12  # halvings of the Newton step before the line search gives up
ROUNDOFF = 10.0  # the residual's floor in units of its round-off (ImplicitSolve.solve)
ROUNDS = 8  # solves per step at most (friction's stick / slip changes, the one-sided constraints)
# with rigid bodies: a step that runs out of rounds keeps friction reactions beyond the cone, and the
# body takes all of them (a block sliding on an elastic slab, 32 cells, 1 ms steps: kicked back by
# 0.12 m/s in one step, the closed form missed by 14 %; settled within 30 rounds, by 3.3 %)
RIGID_ROUNDS = 32


class ImplicitSolve:
    """The Newton solve of one step on a solver's grid (mpm.solver.Solver
    owns the grid, the layout and the stencil cache)."""

    def __init__(self, solver, options):
        self.solver = solver
        self.options = options
        m = solver.model
        t, k = m.types, m.kernel
        self.t = t
        self._evaluate = [(make_evaluate(t, k, solver.options.transfer, g.cls, options.psd), g)
                          for g in m.groups]
        self.viscous = any(b.material.viscosity_param is not None for b in m.scene.bodies)
        self._apply = make_apply(t, k, solver.options.transfer, self.viscous)
        (self._finish_residual, self._finish_apply, self._cg_start, self._cg_step, self._cg_direction,
         self._trial) = make_node_kernels(t)
        # the colliders, then the rigid bodies' shapes (mpm.rigid), held at their pose and velocity of
        # the step's start during the solve; with rigid bodies the reactions' angular impulses are summed
        self.solids = solids(m.scene)
        rigid = bool(getattr(m.scene, "rigid_bodies", None))
        self.with_friction = any(c.friction > 0 for c in self.solids)
        # collider friction inside the solve (mpm.implicit.rough); the node rule's after it, as it was
        surface = m.scene.boundary_rule == "surface"
        self.rough: tuple = make_rough(t, rigid) if self.with_friction and surface else ()
        self._friction = make_friction(t, rigid) if self.with_friction and not surface else None
        self._work = make_boundary_work(t, rigid)
        self.max_rounds = RIGID_ROUNDS if rigid else ROUNDS
        self.eps = float(np.finfo(np.float32 if t.precision == "float32" else np.float64).eps)
        self.contact = solver.contact  # mpm.contact.Contact, or None
        self._contact: tuple = self.contact.constraint if self.contact is not None else ()
        self.sliding = self.contact.sliding if self.contact is not None else ()  # mpm.contact.friction
        with wp.ScopedDevice(m.device):
            if self.sliding:  # per bin: sums of vectors and d x d blocks, the state and load
                self.contact_num, self.rel = (wp.zeros(m.n_nodes, dtype=t.vec) for _ in range(2))
                self.contact_den, self.rel_den = (wp.zeros(m.n_nodes, dtype=t.mat) for _ in range(2))
                self.bnormal, self.force, self.force_after = (wp.zeros(m.n_nodes, dtype=t.vec) for _ in range(3))
                self.bmu = wp.zeros(m.n_nodes, dtype=t.scalar)
                self.bstate = wp.full(m.n_nodes, -1, dtype=wp.int32)
                self.changed = wp.zeros(1, dtype=wp.int32)
            elif self.contact is not None:
                self.contact_num = wp.zeros(m.n_nodes, dtype=t.scalar)
                self.contact_den = wp.zeros(m.n_nodes, dtype=t.scalar)
            self.tangent = wp.zeros(m.n_particles, dtype=make_tangent_type(t))
            self.visc = wp.zeros(m.n_particles if self.viscous else 1, dtype=t.scalar)
            self.acc = wp.zeros(6, dtype=wp.float64)
        self._capacity = 0
        self.rounds = Rounds(self)  # after a solve: what its solution changes (mpm.implicit.rounds)
        self._backup = None  # F^0s and history before the step (plastic models, for a retry)

    def save(self, state) -> None:
        """Keep F^0s and the history before a step of a plastic model: P2G's
        return mapping overwrites them, and a failed solve is retried from them."""
        if not self.solver.model.plastic:
            return
        if self._backup is None:
            self._backup = (wp.empty_like(state.F0s), wp.empty_like(state.history))
        wp.copy(self._backup[0], state.F0s)
        wp.copy(self._backup[1], state.history)

    def restore(self, state) -> None:
        """Undo a failed attempt (the grid is scratch; only P2G's plastic
        write-back changed the state)."""
        if self._backup is not None:
            wp.copy(state.F0s, self._backup[0])
            wp.copy(state.history, self._backup[1])

    def kernels(self) -> list:
        return ([k for k, _ in self._evaluate] + [self._apply, self._finish_residual, self._finish_apply,
                                                  self._cg_start, self._cg_step, self._cg_direction,
                                                  self._trial, self._work]
                + list(self.rough) + ([self._friction] if self._friction else [])
                + list(self.rounds.sides or ())
                + list(self._contact))

    def _grow(self, n: int) -> None:
        if n <= self._capacity:
            return
        self._capacity = n
        with wp.ScopedDevice(self.solver.model.device):
            vec = self.t.vec
            (self.v_star, self.v_trial, self.residual, self.diag, self.inv_diag, self.delta, self.r, self.z,
             self.d, self.Ad, self.reaction) = (wp.zeros(n, dtype=vec) for _ in range(11))
            self.free = wp.zeros(n, dtype=self.t.mat)
            k = n if self.with_friction else 1
            self.friction = wp.zeros(k, dtype=self.t.scalar)
            self.friction_u, self.friction_n = wp.zeros(k, dtype=vec), wp.zeros(k, dtype=vec)
            self.friction_shift = wp.zeros(k, dtype=vec)  # the surface's velocity minus the node's (mpm.surface)
            k = n if self.solids else 1
            self.contact_id = wp.full(k, -1, dtype=wp.int32)  # the collider in contact per node
            k = n if self.contact is not None else 1
            self.cbin = wp.full(k, -1, dtype=wp.int32)
            self.coef = wp.zeros(k, dtype=vec)
            self.v_star0 = wp.zeros(n if self.sliding else 1, dtype=vec)  # v* without the sliding loads
            # v* with the loads between bodies, without the colliders' (mpm.implicit.rough); the
            # collider nodes' state, load and projector on the constraints (and the next round's)
            self.v_base = wp.zeros(n, dtype=vec) if self.rough else self.v_star
            k = n if self.rough else 1
            self.cstate, self.cstate_after = (wp.full(k, NONE, dtype=wp.int32) for _ in range(2))
            self.cload, self.cload_after = (wp.zeros(k, dtype=vec) for _ in range(2))
            self.held = wp.zeros(k, dtype=self.t.mat)
        self.rounds.grow(n)

    def _sum(self) -> np.ndarray:
        return self.acc.numpy()

    # ------------------------------------------------------------ pieces
    def _energy_residual(self, state, v, dt) -> tuple[float, float]:
        """E(v) and |R(v)|, with R, the inverse diagonal and the tangents
        stored (and |m v*| in ``self.momentum``, |diag A| in ``self.stiffness``)."""
        s, m = self.solver, self.solver.model
        n = s.layout.n_nodes
        self.residual[:n].zero_()
        self.diag[:n].zero_()
        self.acc.zero_()
        for kernel, g in self._evaluate:
            wp.launch(kernel, g.count, device=m.device, inputs=[
                m.volume, m.body, m.body_params, s.layout.shape_d, state.F0s, state.Fsn, state.history,
                state.stencils, v, s.const.dx, s.const.K, dt, g.start, self.tangent, self.visc,
                self.residual, self.diag, self.acc])
        wp.launch(self._finish_residual, n, device=m.device, inputs=[
            s.grid.m, v, self.v_star, self.free, self.residual, self.diag, self.inv_diag, self.reaction,
            self.cbin, int(self.contact is not None), self.acc])
        if self.contact is not None:
            self.project(1, self.residual)
        a = self._sum()
        self.momentum = float(np.sqrt(a[MOMENTUM2]))
        self.stiffness = float(np.sqrt(a[STIFFNESS2]))
        return float(a[ENERGY]), float(np.sqrt(a[RESIDUAL2]))

    def _apply_A(self, state, dv, out, dt) -> float:
        """out = A dv; returns dv . A dv."""
        s, m = self.solver, self.solver.model
        n = s.layout.n_nodes
        out[:n].zero_()
        self.acc.zero_()
        wp.launch(self._apply, m.n_particles, device=m.device, inputs=[
            m.volume, m.body, s.layout.shape_d, state.F0s, state.Fsn, state.stencils, self.tangent,
            self.visc, dv, s.const.dx, s.const.K, dt, out])
        wp.launch(self._finish_apply, n, device=m.device, inputs=[s.grid.m, dv, self.free, out, self.acc])
        return float(self._sum()[DOT_A])

    def _cg(self, state, dt, tol: float) -> int:
        """A delta = -R by preconditioned CG, to |r| <= tol; iterations taken."""
        s, m = self.solver, self.solver.model
        n = s.layout.n_nodes
        S = self.t.scalar
        self.acc.zero_()
        wp.launch(self._cg_start, n, device=m.device, inputs=[
            self.residual, self.free, self.inv_diag, self.delta, self.r, self.z, self.d, self.cbin,
            int(self.contact is not None), self.acc])
        if self.contact is not None:
            self.project(2, self.r, self.z)
            wp.copy(self.d, self.z, count=n)
        rz = float(self._sum()[DOT_B])
        if rz <= 0.0:
            return 0
        for it in range(1, self.options.cg_max + 1):
            dAd = self._apply_A(state, self.d, self.Ad, dt)
            if not dAd > 0.0:  # no curvature left (or non-finite): keep what we have
                return it
            alpha = rz / dAd
            self.acc.zero_()
            wp.launch(self._cg_step, n, device=m.device, inputs=[
                S(alpha), self.d, self.Ad, self.free, self.inv_diag, self.delta, self.r, self.z, self.cbin,
                int(self.contact is not None), self.acc])
            if self.contact is not None:
                self.project(2, self.r, self.z)
            a = self._sum()
            if np.sqrt(a[RESIDUAL2]) <= tol:
                return it
            rz, rz_old = float(a[DOT_B]), rz
            wp.launch(self._cg_direction, n, device=m.device, inputs=[S(rz / rz_old), self.z, self.d])
        return self.options.cg_max

    def _activate(self) -> None:
        """The contact constraints of the step, from the constrained
        predictor in grid_v: the approaching two-body bins, each node's bin
        and coefficient c_i (mpm.contact; the bins are zero again after)."""
        s = self.solver
        if not self.sliding:
            s.contact.couple(s.grid, s.layout, self.cbin, self.coef)
            return
        self.bstate.fill_(-1)
        s.contact.couple(s.grid, s.layout, self.cbin, self.coef, (self.bnormal, self.bstate, self.bmu, self.force))

    def project(self, mode: int, x, z=None) -> None:
        """Project x onto the contact constraints
        (mpm.contact.constraint, modes 0-2)."""
        s, m = self.solver, self.solver.model
        n = s.layout.n_nodes
        self.contact_num.zero_()
        self.contact_den.zero_()
        if self.sliding:
            sums, project = self.sliding[1:3]
            wp.launch(sums, n, device=m.device, inputs=[
                mode, self.cbin, self.coef, self.bnormal, self.free, s.grid.m, self.inv_diag, x,
                self.contact_num, self.contact_den])
            wp.launch(project, n, device=m.device, inputs=[
                mode, self.cbin, self.coef, self.bnormal, self.bstate, self.free, s.grid.m, self.inv_diag,
                self.contact_num, self.contact_den, x, z if z is not None else x, self.acc, RESIDUAL2, DOT_B])
            return
        sums, project = self._contact[1:]
        common = [mode, self.cbin, self.coef, self.free, s.grid.m, self.inv_diag]
        wp.launch(sums, n, device=m.device, inputs=[*common, x, self.contact_num, self.contact_den])
        wp.launch(project, n, device=m.device, inputs=[
            *common, self.contact_num, self.contact_den, x, z if z is not None else x, self.acc,
            RESIDUAL2, DOT_B])

    def begin(self) -> None:
        """The solve's start: keep the predictor v*, constrain grid_v, and the
        projectors onto the free velocities (the nodes in frictional contact
        with a collider stuck, mpm.implicit.rough); with contact, the
        constraints between bodies and grid_v projected onto them."""
        s = self.solver
        n = s.layout.n_nodes
        self._grow(s.grid.capacity)
        wp.copy(self.v_star, s.grid.v, count=n)
        if self.sliding:
            wp.copy(self.v_star0, s.grid.v, count=n)
        s.conditions.constrain(s.grid, n, s.step_time, self.free, self.friction, self.friction_u, self.friction_n,
                               self.friction_shift, self.contact_id)
        if self.rough:  # every node in frictional contact with a collider starts stuck
            wp.copy(self.v_base, self.v_star, count=n)
            self.cstate.fill_(NONE)
            self.hold(fresh=True)
        if self.contact is not None:
            self._activate()
            self.project(0, s.grid.v)

    def finish(self) -> None:
        """The constraints' work (:func:`make_boundary_work`: a stuck node's
        friction is part of its reaction), the work of friction between
        sliding bodies (mpm.contact.friction ``work``) and that of the
        loads of the nodes sliding on a collider (mpm.implicit.rough
        ``work``); under the node rule, Coulomb friction at the colliders
        on the solution (mpm.implicit.system ``make_friction``)."""
        s, m = self.solver, self.solver.model
        status = s.buffer.status  # (the colliders' angular impulses: rigid bodies, mpm.rigid_coupling)
        lever = [s.grid.q, s.step_time, s.conditions.data.colliders, status.collider_torque]  # (the nodes' positions)
        wp.launch(self._work, s.layout.n_nodes, device=m.device, inputs=[
            s.grid.m, self.reaction, s.grid.v, self.contact_id, *lever, s.buffer.status])
        if self.sliding:  # the work of friction between bodies (mpm.contact.friction)
            wp.launch(self.sliding[5], s.layout.n_nodes, device=m.device, inputs=[
                self.cbin, self.coef, self.bnormal, self.bstate, self.force, self.free, m.kernel.n_grids,
                s.grid.v, s.buffer.status])
        if self.rough:
            wp.launch(self.rough[2], s.layout.n_nodes, device=m.device, inputs=[
                s.grid.m, self.cstate, self.cload, self.held, self.contact_id, s.grid.v, *lever, s.buffer.status])
        if self._friction is not None:  # the node rule's, after the solve
            wp.launch(self._friction, s.layout.n_nodes, device=m.device, inputs=[
                s.grid.m, self.free, self.reaction, self.friction, self.friction_u, self.friction_n,
                self.friction_shift, self.contact_id, s.grid.v, *lever, s.buffer.status])

    def hold(self, fresh: bool = False) -> None:
        """The collider nodes' states on the constraints and their loads in v*
        (mpm.implicit.rough ``hold``; ``fresh``: the constraints have just
        classified the nodes)."""
        s, m = self.solver, self.solver.model
        wp.launch(self.rough[0], s.layout.n_nodes, device=m.device, inputs=[
            int(fresh), s.grid.m, self.friction, self.friction_u, self.friction_shift, self.cstate, self.cload,
            self.held, self.free, s.grid.v, self.v_base, self.v_star])

    # ------------------------------------------------------------ solve
    def _classify(self, rep: NewtonReport, R: float, R_before: float, goal: float) -> None:
        """Out of iterations with the residual R above ``goal``: a near miss
        (R within ``newton_accept`` of the goal and still falling: the step
        may use it), missed (still falling, further off), or diverged (R
        rose in the last iteration, or above the initial residual)."""
        opt, r, n = self.options, R / rep.residual0, rep.newton
        said, tol = f"residual {r:.3g} of the initial after {n} iterations", f"tolerance {opt.newton_tol:g}"
        if R > R_before or R > rep.residual0:
            rep.outcome = "diverged"
            rep.reason = f"Newton diverged: {said}, up from {R_before / rep.residual0:.3g} in the last one ({tol})"
        elif R <= opt.newton_accept * goal:
            rep.outcome = "near_miss"
            rep.reason = f"Newton's near miss: {said} ({tol}; accepted within {opt.newton_accept:g}x of it)"
        else:
            rep.outcome = "missed"
            rep.reason = (f"Newton missed its tolerance: {said}, still falling ({tol}; a near miss is within "
                          f"{opt.newton_accept:g}x of it; integrator.newton_max allows more iterations)")

    def solve(self, state, dt) -> NewtonReport:
        """The grid velocities of the step: on entry ``solver.grid.v`` holds the
        predictor v* (momentum / mass + dt g) and ``solver.grid.q`` the node
        positions; on exit grid_v holds the solution, before the explicit
        contact pass (mpm.solver). With friction between bodies or at a
        collider, or one-sided constraints under the surface rule, the
        solve is repeated from its solution while a bin's or a node's
        stick / slip state or load, or a node's classification, changes
        (mpm.implicit.rounds)."""
        self.begin()
        rep = NewtonReport()
        goal = self._newton(state, dt, rep)
        while rep.converged:
            last = rep.rounds == self.max_rounds  # the last solve: count what it leaves unsettled, keep it
            changes = self.rounds.changes(commit=not last)
            if not changes:
                break
            if last:
                rep.unsettled = changes
                break
            rep.rounds += 1
            self._newton(state, dt, rep, goal)
        if rep.converged:
            self.finish()
        return rep

    def _newton(self, state, dt, rep: NewtonReport, goal: float | None = None) -> float:
        """Newton's method from grid_v to the residual ``goal`` (the first
        solve of a step sets it and ``rep.residual0``); the solution in grid_v,
        the iterations added to ``rep``. Returns the goal."""
        s, m, opt = self.solver, self.solver.model, self.options
        n = s.layout.n_nodes
        dtS = self.t.scalar(dt)
        v, v_try = s.grid.v, self.v_trial
        E, R = self._energy_residual(state, v, dtS)
        if goal is None:
            rep.residual0 = R
            # the residual's round-off floor: F = (F^sn + dt D) F^0s carries eps, i.e. the
            # velocities eps dx / dt, which A turns into a residual; v* carries eps |v*|
            floor = ROUNDOFF * self.eps * (self.stiffness * float(m.dx) / float(dt) + self.momentum)
            goal = max(opt.newton_tol * R, floor)
        start = rep.newton
        R_before = np.inf  # the residual before the last iteration
        while True:
            if not np.isfinite(R) or not np.isfinite(E):
                rep.outcome = "diverged"
                rep.reason = f"Newton diverged: non-finite residual or energy after {rep.newton} iterations"
                break
            if R <= goal:
                break
            if rep.newton - start >= opt.newton_max:
                if opt.newton_max > 1:  # (1: the semi-implicit update, one step by definition)
                    self._classify(rep, R, R_before, goal)
                break
            rep.cg += self._cg(state, dtS, opt.cg_tol * R)
            rep.newton += 1
            alpha, accepted = 1.0, False
            for k in range(BACKTRACKS + 1):
                self.acc.zero_()
                wp.launch(self._trial, n, device=m.device, inputs=[
                    v, self.delta, self.t.scalar(alpha), self.residual, v_try, self.acc])
                if k == 0:  # R . delta = dE/dalpha at 0 (< 0 along a descent direction)
                    slope = float(self._sum()[DOT_A])
                E_try, R_try = self._energy_residual(state, v_try, dtS)
                # near convergence E's decrease falls below its round-off (psi of a small strain
                # carries eps / |strain| relative error); a halved residual is then progress
                if not opt.line_search or E_try <= E + ARMIJO * alpha * slope or R_try <= 0.5 * R:
                    accepted = True
                    break
                alpha *= 0.5
                rep.backtracks += 1
            if not accepted:
                said = (f"the line search found no decrease of the incremental potential after {BACKTRACKS} "
                        f"halvings (residual {R / max(rep.residual0, 1e-300):.3g} of the initial, iteration "
                        f"{rep.newton}")
                if R <= opt.newton_accept * goal:
                    # as close as a near miss: the potential's decrease is below its round-off
                    rep.outcome = "near_miss"
                    rep.reason = (f"Newton's near miss: {said}; tolerance {opt.newton_tol:g}, accepted within "
                                  f"{opt.newton_accept:g}x of it)")
                else:
                    rep.outcome = "stalled"
                    rep.reason = f"Newton stalled: {said})"
                break
            v, v_try = v_try, v
            R_before, E, R = R, E_try, R_try
        # 0 when the predictor already solved the system to round-off
        rep.residual = R / rep.residual0 if rep.newton > 0 else 0.0
        if v is not s.grid.v:
            wp.copy(s.grid.v, v, count=n)
        return goal
