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
the residual is measured without the constraints' reaction.

A plastic model's return mapping has run in P2G: F^0s is the returned
elastic state, so the energy is the elastic predictor's for the step.
"""

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from .grid import make_work
from .kernels import Kernel
from .launch import warp_kernel
from .status import StepStatus
from .materials.differential import (make_principal_stress, make_tangent_action, make_tangent_quadratic,
                                     make_tangent_type)
from .stencil import (make_cached, make_node, make_node_gradient, make_stencil_cache,
                      weight_matrix_type)
from .types import Types

ARMIJO = 1.0e-4  # sufficient decrease of E along the Newton direction
BACKTRACKS = 12  # halvings of the Newton step before the line search gives up
ENERGY, RESIDUAL2, DOT_A, DOT_B, MOMENTUM2, STIFFNESS2 = range(6)  # slots of the float64 accumulator
ROUNDOFF = 10.0  # the residual's floor in units of its round-off (ImplicitSolve.solve)


@dataclass
class NewtonReport:
    """What one implicit solve did."""

    newton: int = 0  # Newton iterations
    cg: int = 0  # conjugate-gradient iterations, all Newton iterations together
    residual: float = 0.0  # final |R| / initial |R| (0 when no iteration was needed)
    residual0: float = 0.0  # initial |R| [kg m/s]
    converged: bool = True
    backtracks: int = 0  # line-search halvings, all iterations together
    reason: str = ""  # why it failed


@functools.cache
def make_weight_gradient(t: Types, kernel: Kernel, mls: bool):
    """``weight_gradient(a, b, c, W, dW, r, w, Kp, K, inv_dx) -> g_ip`` [1/m]."""
    node_gradient = make_node_gradient(t, kernel)
    per_particle_K = kernel.moment is None
    Wm = weight_matrix_type(t, kernel)
    S = t.scalar

    @wp.func
    def weight_gradient(a: int, b: int, c: int, W: Wm, dW: Wm, r: t.vec, w: S, Kp: t.mat, K: S,
                        inv_dx: S):
        if wp.static(mls):
            if wp.static(per_particle_K):
                return w * (Kp * r)
            else:
                return (w * K) * r
        else:
            return node_gradient(a, b, c, W, dW, inv_dx)

    return weight_gradient


def _specialisation(t: Types, kernel: Kernel, transfer: str):
    mls = transfer == "mls" and not kernel.gradient_affine
    return mls, *make_cached(t, kernel, not mls), make_node(t, kernel), make_weight_gradient(t, kernel, mls)


@functools.cache
def make_gather(t: Types, kernel: Kernel, transfer: str):
    """``gather(p, body, shape, cache, v, dx, K, Kp) -> D_p(v) = 1/G sum_g sum_i
    v_i g_ip^T``: the velocity gradient in the reference configuration that
    G2P will take (F^sn += dt D), for grid velocities (or a direction) v."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    mls, reference, cached, node, weight_gradient = _specialisation(t, kernel, transfer)
    Cache = make_stencil_cache(t, kernel)
    inv_G = 1.0 / G
    mat = t.mat

    @wp.func
    def gather(p: int, b: int, shape: wp.array(dtype=t.ivec), cache: Cache, v: wp.array(dtype=t.vec),
               dx: S, K: S, Kp: t.mat):
        inv_dx = S(1.0) / dx
        D = mat()
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            for a in range(Ks):
                for bb in range(Ks):
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        D += wp.outer(v[i], weight_gradient(a, bb, c, W, dW, r, w, Kp, K, inv_dx))
        return S(inv_G) * D

    return gather


@functools.cache
def make_evaluate(t: Types, kernel: Kernel, transfer: str, material, psd: bool):
    """Per particle of one material model at the iterate v: F_p(v), the
    energy, the tangent (stored), the viscous factor V^0 J 2 eta (stored),
    and the scatter of dt S_p g_ip into the residual and of the elastic and
    viscous parts of A's diagonal."""
    f64 = wp.float64
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    mls, reference, cached, node, weight_gradient = _specialisation(t, kernel, transfer)
    Cache = make_stencil_cache(t, kernel)
    Tangent = make_tangent_type(t)
    principal_stress = make_principal_stress(t, material, psd)
    quadratic = make_tangent_quadratic(t)
    gather = make_gather(t, kernel, transfer)
    per_particle_K = kernel.moment is None
    viscous = material.viscosity_param is not None
    eta_index = material.viscosity_param or 0
    inv_G = 1.0 / G
    half_inv_G = 0.5 / G
    n_grids = float(G)
    vec, mat = t.vec, t.mat

    @warp_kernel
    def evaluate(
        volume: wp.array(dtype=S),
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        shape: wp.array(dtype=t.ivec),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        history: wp.array(dtype=t.history),
        cache: Cache,
        v: wp.array(dtype=t.vec),
        dx: S,
        K: S,
        dt: S,
        start: int,
        tangent: wp.array(dtype=Tangent),
        visc: wp.array(dtype=S),
        residual: wp.array(dtype=t.vec),
        diag: wp.array(dtype=t.vec),
        acc: wp.array(dtype=f64),
    ):
        p = wp.tid() + start
        b = body[p]
        Fs = Fsn[p]
        F0 = F0s[p]
        V0 = volume[p]
        inv_dx = S(1.0) / dx
        Kp = mat()
        if wp.static(per_particle_K):
            Kp = cache.K[p]
        D = gather(p, b, shape, cache, v, dx, K, Kp)
        P, psi, T = principal_stress((Fs + dt * D) * F0, body_params[b], history[p])
        tangent[p] = T
        stress = V0 * P * wp.transpose(F0)
        e = psi
        k_visc = S(0.0)
        FinvT = mat()
        if wp.static(viscous):
            Finv = wp.inverse(Fs)
            FinvT = wp.transpose(Finv)
            L = D * Finv
            symL = S(0.5) * (L + wp.transpose(L))
            eta = body_params[b][eta_index]
            J = wp.determinant(Fs) * wp.determinant(F0)
            k_visc = V0 * J * S(2.0) * eta
            stress += k_visc * symL * FinvT
            e += dt * J * eta * wp.ddot(symL, symL)
            visc[p] = k_visc
        wp.atomic_add(acc, ENERGY, f64(S(n_grids) * V0 * e))
        # A's diagonal, (dt^2 / G) V0 e_k . dP(e_k wv^T) wv with wv = F0^T g, in the
        # principal frames: u_k = U^T e_k (row k of U), z = V^T wv
        VF0T = wp.transpose(T.V) * wp.transpose(F0)
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            for a in range(Ks):
                for bb in range(Ks):
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        gi = weight_gradient(a, bb, c, W, dW, r, w, Kp, K, inv_dx)
                        wp.atomic_add(residual, i, dt * (stress * gi))
                        z = VF0T * gi
                        y = FinvT * gi
                        dg = vec()
                        for k in range(wp.static(dim)):
                            dg[k] = (dt * dt * S(inv_G) * V0) * quadratic(T, T.U[k], z)
                            if wp.static(viscous):
                                dg[k] += dt * k_visc * (wp.dot(y, y) + y[k] * y[k]) * S(half_inv_G)
                        wp.atomic_add(diag, i, dg)

    return evaluate


@functools.cache
def make_apply(t: Types, kernel: Kernel, transfer: str, viscous: bool):
    """Per particle: the scatter of dt dS_p g_ip for the direction dv (A's
    stress part; the mass part is added per node by :func:`make_node_kernels`)."""
    S = t.scalar
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    mls, reference, cached, node, weight_gradient = _specialisation(t, kernel, transfer)
    Cache = make_stencil_cache(t, kernel)
    Tangent = make_tangent_type(t)
    action = make_tangent_action(t)
    gather = make_gather(t, kernel, transfer)
    per_particle_K = kernel.moment is None
    mat = t.mat

    @warp_kernel
    def apply(
        volume: wp.array(dtype=S),
        body: wp.array(dtype=wp.int32),
        shape: wp.array(dtype=t.ivec),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        cache: Cache,
        tangent: wp.array(dtype=Tangent),
        visc: wp.array(dtype=S),
        dv: wp.array(dtype=t.vec),
        dx: S,
        K: S,
        dt: S,
        out: wp.array(dtype=t.vec),
    ):
        p = wp.tid()
        b = body[p]
        F0 = F0s[p]
        inv_dx = S(1.0) / dx
        Kp = mat()
        if wp.static(per_particle_K):
            Kp = cache.K[p]
        D = gather(p, b, shape, cache, dv, dx, K, Kp)
        dS = volume[p] * action(tangent[p], dt * D * F0) * wp.transpose(F0)
        if wp.static(viscous):
            Finv = wp.inverse(Fsn[p])
            L = D * Finv
            dS += visc[p] * S(0.5) * (L + wp.transpose(L)) * wp.transpose(Finv)
        dS = dt * dS
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            for a in range(Ks):
                for bb in range(Ks):
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        wp.atomic_add(out, i, dS * weight_gradient(a, bb, c, W, dW, r, w, Kp, K, inv_dx))

    return apply


@functools.cache
def make_node_kernels(t: Types):
    """The per-node halves of the solve (all float64 sums in ``acc``)."""
    f64 = wp.float64
    S = t.scalar
    vec = t.vec
    dim = t.dim

    @warp_kernel
    def finish_residual(m: wp.array(dtype=S), v: wp.array(dtype=vec), v_star: wp.array(dtype=vec),
                        free: wp.array(dtype=t.mat), residual: wp.array(dtype=vec),
                        diag: wp.array(dtype=vec), inv_diag: wp.array(dtype=vec),
                        reaction: wp.array(dtype=vec), cbin: wp.array(dtype=wp.int32), contact: int,
                        acc: wp.array(dtype=f64)):
        """R = Pi (m (v - v*) + R_stress), the kinetic part of E, |R|^2 (but at
        the nodes of contact constraints, ``contact`` and cbin >= 0), the
        inverse of A's diagonal (0 on fixed components) and the constraints'
        reaction (I - Pi) (m (v - v*) + R_stress) / m [m/s]."""
        i = wp.tid()
        mi = m[i]
        if mi <= S(0.0):
            residual[i] = vec()
            inv_diag[i] = vec()
            return
        dv = v[i] - v_star[i]
        Pi = free[i]
        full = mi * dv + residual[i]
        R = Pi * full
        residual[i] = R
        reaction[i] = (full - R) / mi
        wp.atomic_add(acc, ENERGY, f64(S(0.5) * mi * wp.dot(dv, dv)))
        if contact == 0 or cbin[i] < 0:
            wp.atomic_add(acc, RESIDUAL2, f64(wp.dot(R, R)))
        wp.atomic_add(acc, MOMENTUM2, f64(mi * mi * wp.dot(v_star[i], v_star[i])))
        d = diag[i]
        inv = vec()
        a2 = S(0.0)
        for k in range(wp.static(dim)):
            a2 += (mi + d[k]) * (mi + d[k])
            if Pi[k, k] > S(0.0):
                inv[k] = S(1.0) / (mi + d[k])
        wp.atomic_add(acc, STIFFNESS2, f64(a2))
        inv_diag[i] = inv

    @warp_kernel
    def finish_apply(m: wp.array(dtype=S), dv: wp.array(dtype=vec), free: wp.array(dtype=t.mat),
                     out: wp.array(dtype=vec), acc: wp.array(dtype=f64)):
        """out = Pi (m dv + out), and dv . out."""
        i = wp.tid()
        mi = m[i]
        if mi <= S(0.0):
            out[i] = vec()
            return
        Ad = free[i] * (mi * dv[i] + out[i])
        out[i] = Ad
        wp.atomic_add(acc, DOT_A, f64(wp.dot(dv[i], Ad)))

    @warp_kernel
    def cg_start(residual: wp.array(dtype=vec), free: wp.array(dtype=t.mat), inv_diag: wp.array(dtype=vec),
                 delta: wp.array(dtype=vec), r: wp.array(dtype=vec), z: wp.array(dtype=vec),
                 d: wp.array(dtype=vec), cbin: wp.array(dtype=wp.int32), contact: int,
                 acc: wp.array(dtype=f64)):
        """delta = 0, r = -R, z = Pi (inv_diag . r), d = z, r . z (as finish_residual)."""
        i = wp.tid()
        ri = -residual[i]
        zi = free[i] * wp.cw_mul(inv_diag[i], ri)
        delta[i] = vec()
        r[i] = ri
        z[i] = zi
        d[i] = zi
        if contact == 0 or cbin[i] < 0:
            wp.atomic_add(acc, DOT_B, f64(wp.dot(ri, zi)))

    @warp_kernel
    def cg_step(alpha: S, d: wp.array(dtype=vec), Ad: wp.array(dtype=vec), free: wp.array(dtype=t.mat),
                inv_diag: wp.array(dtype=vec), delta: wp.array(dtype=vec), r: wp.array(dtype=vec),
                z: wp.array(dtype=vec), cbin: wp.array(dtype=wp.int32), contact: int,
                acc: wp.array(dtype=f64)):
        """delta += alpha d, r -= alpha A d, z = Pi (inv_diag . r), |r|^2 and r . z
        (as finish_residual)."""
        i = wp.tid()
        delta[i] = delta[i] + alpha * d[i]
        ri = r[i] - alpha * Ad[i]
        r[i] = ri
        zi = free[i] * wp.cw_mul(inv_diag[i], ri)
        z[i] = zi
        if contact == 0 or cbin[i] < 0:
            wp.atomic_add(acc, RESIDUAL2, f64(wp.dot(ri, ri)))
            wp.atomic_add(acc, DOT_B, f64(wp.dot(ri, zi)))

    @warp_kernel
    def cg_direction(beta: S, z: wp.array(dtype=vec), d: wp.array(dtype=vec)):
        i = wp.tid()
        d[i] = z[i] + beta * d[i]

    @warp_kernel
    def trial(v: wp.array(dtype=vec), delta: wp.array(dtype=vec), alpha: S, residual: wp.array(dtype=vec),
              out: wp.array(dtype=vec), acc: wp.array(dtype=f64)):
        """out = v + alpha delta, and R . delta (the directional derivative of E)."""
        i = wp.tid()
        out[i] = v[i] + alpha * delta[i]
        wp.atomic_add(acc, DOT_A, f64(wp.dot(residual[i], delta[i])))

    return finish_residual, finish_apply, cg_start, cg_step, cg_direction, trial


@functools.cache
def make_boundary_work(t: Types):
    """Kernel: the work of the constraints on each node at the solution, the
    positive part of J . v with J = m reaction their impulse (v - reaction:
    the velocity without it), into the step's ``status.boundary_work``
    (mpm.grid ``make_work``, mpm.stability)."""
    S = t.scalar
    vec = t.vec
    work = make_work(t)

    @warp_kernel
    def boundary_work(m: wp.array(dtype=S), reaction: wp.array(dtype=vec), v: wp.array(dtype=vec),
                      status: StepStatus):
        i = wp.tid()
        if m[i] > S(0.0):
            work(m[i], v[i] - reaction[i], v[i], status)

    return boundary_work


@functools.cache
def make_friction(t: Types):
    """Kernel: Coulomb friction after the solve (ImplicitSolve.finish)."""
    S = t.scalar
    vec = t.vec

    @warp_kernel
    def friction(m: wp.array(dtype=S), free: wp.array(dtype=t.mat), reaction: wp.array(dtype=vec),
                 mu: wp.array(dtype=S), u: wp.array(dtype=vec), normal: wp.array(dtype=vec),
                 v: wp.array(dtype=vec)):
        i = wp.tid()
        if m[i] <= S(0.0) or mu[i] <= S(0.0):
            return
        push = wp.dot(reaction[i], normal[i])  # > 0: the constraint held the node out of the collider
        if push <= S(0.0):
            return
        vr = v[i] - u[i]
        vt = free[i] * vr
        lt = wp.length(vt)
        if lt > S(0.0):
            v[i] = u[i] + (vr - vt) + vt * wp.max(S(0.0), S(1.0) - mu[i] * push / lt)

    return friction


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
        self.with_friction = any(c.friction > 0 for c in m.scene.colliders)
        self._friction = make_friction(t) if self.with_friction else None
        self._work = make_boundary_work(t)
        self.eps = float(np.finfo(np.float32 if t.precision == "float32" else np.float64).eps)
        self.contact = solver.contact  # mpm.contact.Contact, or None
        self._contact = self.contact.constraint if self.contact is not None else ()
        with wp.ScopedDevice(m.device):
            if self.contact is not None:
                self.contact_num = wp.zeros(m.n_nodes, dtype=t.scalar)
                self.contact_den = wp.zeros(m.n_nodes, dtype=t.scalar)
            self.tangent = wp.zeros(m.n_particles, dtype=make_tangent_type(t))
            self.visc = wp.zeros(m.n_particles if self.viscous else 1, dtype=t.scalar)
            self.acc = wp.zeros(6, dtype=wp.float64)
        self._capacity = 0

    def kernels(self) -> list:
        return ([k for k, _ in self._evaluate] + [self._apply, self._finish_residual, self._finish_apply,
                                                  self._cg_start, self._cg_step, self._cg_direction,
                                                  self._trial, self._work]
                + ([self._friction] if self._friction else [])
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
            k = n if self._friction is not None else 1
            self.friction = wp.zeros(k, dtype=self.t.scalar)
            self.friction_u, self.friction_n = wp.zeros(k, dtype=vec), wp.zeros(k, dtype=vec)
            k = n if self.contact is not None else 1
            self.cbin = wp.full(k, -1, dtype=wp.int32)
            self.coef = wp.zeros(k, dtype=vec)

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
            self._project(1, self.residual)
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
            self._project(2, self.r, self.z)
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
                self._project(2, self.r, self.z)
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
        s.contact.couple(s.grid, s.layout, self.cbin, self.coef)

    def _project(self, mode: int, x, z=None) -> None:
        """Project x onto the contact constraints (mpm.contact
        ``make_contact_constraint``, modes 0-2)."""
        s, m = self.solver, self.solver.model
        n = s.layout.n_nodes
        sums, project = self._contact[1:]
        self.contact_num.zero_()
        self.contact_den.zero_()
        common = [mode, self.cbin, self.coef, self.free, s.grid.m, self.inv_diag]
        wp.launch(sums, n, device=m.device, inputs=[*common, x, self.contact_num, self.contact_den])
        wp.launch(project, n, device=m.device, inputs=[
            *common, self.contact_num, self.contact_den, x, z if z is not None else x, self.acc,
            RESIDUAL2, DOT_B])

    def begin(self) -> None:
        """The solve's start: keep the predictor v*, constrain grid_v, and the
        projectors onto the free velocities (and the frictional contacts);
        with contact, the constraints between bodies and grid_v projected
        onto them."""
        s = self.solver
        n = s.layout.n_nodes
        self._grow(s.grid.capacity)
        wp.copy(self.v_star, s.grid.v, count=n)
        s.conditions.constrain(s.grid, n, s.step_time, self.free, self.friction, self.friction_u, self.friction_n)
        if self.contact is not None:
            self._activate()
            self._project(0, s.grid.v)

    def finish(self) -> None:
        """The constraints' work (:func:`make_boundary_work`), then Coulomb
        friction on the solved velocities of the nodes in frictional
        contact: the tangential velocity relative to the collider loses mu
        times the normal velocity the constraint removed (|(I - Pi) R| / m at
        the solution, while it pushes into the collider) - the explicit
        step's rule with the implicit normal impulse."""
        s, m = self.solver, self.solver.model
        wp.launch(self._work, s.layout.n_nodes, device=m.device, inputs=[
            s.grid.m, self.reaction, s.grid.v, s.buffer.status])
        if self._friction is not None:
            wp.launch(self._friction, s.layout.n_nodes, device=m.device, inputs=[
                s.grid.m, self.free, self.reaction, self.friction, self.friction_u, self.friction_n,
                s.grid.v])

    # ------------------------------------------------------------ solve
    def solve(self, state, dt) -> NewtonReport:
        """The grid velocities of the step: on entry ``solver.grid.v`` holds the
        predictor v* (momentum / mass + dt g) and ``solver.grid.q`` the node
        positions; on exit grid_v holds the solution, before the boundary
        conditions' friction and the explicit contact pass (mpm.solver)."""
        s, m, opt = self.solver, self.solver.model, self.options
        n = s.layout.n_nodes
        dtS = self.t.scalar(dt)
        self.begin()
        v, v_try = s.grid.v, self.v_trial
        E, R = self._energy_residual(state, v, dtS)
        rep = NewtonReport(residual0=R)
        # the residual's round-off floor: F = (F^sn + dt D) F^0s carries eps, i.e. the
        # velocities eps dx / dt, which A turns into a residual; v* carries eps |v*|
        floor = ROUNDOFF * self.eps * (self.stiffness * float(m.dx) / float(dt) + self.momentum)
        goal = max(opt.newton_tol * R, floor)
        while True:
            if not np.isfinite(R) or not np.isfinite(E):
                rep.converged, rep.reason = False, "non-finite residual or energy"
                break
            if R <= goal:
                break
            if rep.newton >= opt.newton_max:
                rep.converged = opt.newton_max == 1  # the semi-implicit update: one step by definition
                if not rep.converged:
                    rep.reason = (f"Newton did not converge in {opt.newton_max} iterations: residual "
                                  f"{R / rep.residual0:.3g} of the initial one (tolerance {opt.newton_tol:g})")
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
                rep.converged = False
                rep.reason = (f"line search found no decrease of the incremental potential after "
                              f"{BACKTRACKS} halvings (residual {R / max(rep.residual0, 1e-300):.3g} of the initial)")
                break
            v, v_try = v_try, v
            E, R = E_try, R_try
        # 0 when the predictor already solved the system to round-off
        rep.residual = R / rep.residual0 if rep.newton > 0 else 0.0
        if v is not s.grid.v:
            wp.copy(s.grid.v, v, count=n)
        if rep.converged:
            self.finish()
        return rep
