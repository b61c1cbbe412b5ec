"""The kernels of the implicit integrator's system (mpm.implicit): per
particle the energy, residual and Hessian action of the incremental
potential (``make_evaluate``, ``make_apply``), per node the passes of
Newton's method and of conjugate gradients (``make_node_kernels``), the
constraints' work, Coulomb friction at the colliders after a solve under
the node rule (``make_friction``; the surface rule's is inside the solve,
mpm.implicit.rough), and the rounds of the one-sided constraints
(``make_side_kernels``). Sums go into one
float64 accumulator at the slots below.
"""

import functools

import warp as wp

from ..collider_device import make_add_reaction
from ..collider_shapes import make_collider_data
from ..grid import make_work
from ..kernels import Kernel
from ..launch import warp_kernel
from ..stepping.status import StepStatus
from ..materials.differential import (make_principal_stress, make_tangent_action, make_tangent_quadratic,
                                     make_tangent_type)
from ..stencil import make_node_gradient, make_stencil_cache, make_walk, weight_matrix_type
from ..types import Types

ENERGY, RESIDUAL2, DOT_A, DOT_B, MOMENTUM2, STIFFNESS2 = range(6)  # slots of the float64 accumulator


@functools.cache
def make_walk_args(t: Types):
    """What the stencil walks of :func:`make_walks` read and write per
    particle: K_p [1/m^2] (a kernel whose moment varies), K, 1/dx, the nodal
    field gathered from or scattered into (``field``), the step dt, M (the
    matrix scattered as M g_ip), and for evaluate's scatter of A's diagonal
    ``diag`` with the tangent T, V^T F^0s,T, F^sn,-T, V^0 and the viscous
    factor."""
    S = t.scalar
    Tangent = make_tangent_type(t)

    @wp.struct
    class WalkArgs:
        Kp: t.mat
        K: S
        inv_dx: S
        field: wp.array(dtype=t.vec)
        dt: S
        M: t.mat
        diag: wp.array(dtype=t.vec)
        T: Tangent
        VF0T: t.mat
        FinvT: t.mat
        V0: S
        k_visc: S

    return WalkArgs


@functools.cache
def make_walks(t: Types, kernel: Kernel, transfer: str, viscous: bool = False):
    """``args_at(p, cache, K, dx) -> args`` (:func:`make_walk_args`, K_p and
    the scales set) and the walks over particle p's stencils
    (mpm.stencil.make_walk) with the weight gradient g_ip [1/m] (MLS: K_p r
    w_ip; otherwise the kernel's own): ``gather(...) -> sum_g sum_i v_i
    g_ip^T`` of ``args.field``; ``scatter``: ``args.field`` takes in M g_ip;
    ``evaluate``: the residual ``args.field`` takes in dt (M g_ip) and
    ``args.diag`` A's diagonal, (dt^2 / G) V0 e_k . dP(e_k wv^T) wv with wv =
    F0^T g, in the principal frames (u_k = U^T e_k, row k of U, z = V^T wv),
    plus the viscous part."""
    S = t.scalar
    mls = transfer == "mls" and not kernel.gradient_affine
    node_gradient = make_node_gradient(t, kernel)
    per_particle_K = kernel.moment is None
    Wm = weight_matrix_type(t, kernel)
    Cache = make_stencil_cache(t, kernel)
    Args = make_walk_args(t)
    quadratic = make_tangent_quadratic(t)
    inv_G = 1.0 / kernel.n_grids
    half_inv_G = 0.5 / kernel.n_grids
    dim = t.dim

    @wp.func
    def args_at(p: int, cache: Cache, K: S, dx: S):
        args = Args()
        if wp.static(per_particle_K):
            args.Kp = cache.K[p]
        args.K = K
        args.inv_dx = S(1.0) / dx
        return args

    @wp.func
    def weight_gradient(a: int, b: int, c: int, W: Wm, dW: Wm, r: t.vec, w: S, args: Args):
        if wp.static(mls):
            if wp.static(per_particle_K):
                return w * (args.Kp * r)
            else:
                return (w * args.K) * r
        else:
            return node_gradient(a, b, c, W, dW, args.inv_dx)

    @wp.func
    def gather_node(D: t.mat, a: int, b: int, c: int, w: S, r: t.vec, i: int, W: Wm, dW: Wm, args: Args):
        return D + wp.outer(args.field[i], weight_gradient(a, b, c, W, dW, r, w, args))

    @wp.func
    def scatter_node(D: t.mat, a: int, b: int, c: int, w: S, r: t.vec, i: int, W: Wm, dW: Wm, args: Args):
        wp.atomic_add(args.field, i, args.M * weight_gradient(a, b, c, W, dW, r, w, args))
        return D

    @wp.func
    def evaluate_node(D: t.mat, a: int, b: int, c: int, w: S, r: t.vec, i: int, W: Wm, dW: Wm, args: Args):
        gi = weight_gradient(a, b, c, W, dW, r, w, args)
        dt = args.dt
        wp.atomic_add(args.field, i, dt * (args.M * gi))
        z = args.VF0T * gi
        y = args.FinvT * gi
        dg = t.vec()
        for k in range(wp.static(dim)):
            dg[k] = (dt * dt * S(inv_G) * args.V0) * quadratic(args.T, args.T.U[k], z)
            if wp.static(viscous):
                dg[k] += dt * args.k_visc * (wp.dot(y, y) + y[k] * y[k]) * S(half_inv_G)
        wp.atomic_add(args.diag, i, dg)
        return D

    gradients = not mls
    return (args_at, make_walk(t, kernel, gradients, gather_node, Args),
            make_walk(t, kernel, gradients, scatter_node, Args), make_walk(t, kernel, gradients, evaluate_node, Args))


@functools.cache
def make_evaluate(t: Types, kernel: Kernel, transfer: str, material, psd: bool):
    """Per particle of one material model at the iterate v: F_p(v), the
    energy, the tangent (stored), the viscous factor V^0 J 2 eta (stored),
    and the scatter of dt S_p g_ip into the residual and of the elastic and
    viscous parts of A's diagonal."""
    f64 = wp.float64
    S = t.scalar
    Cache = make_stencil_cache(t, kernel)
    Tangent = make_tangent_type(t)
    principal_stress = make_principal_stress(t, material, psd)
    viscous = material.viscosity_param is not None
    args_at, gather, _, scatter = make_walks(t, kernel, transfer, viscous)
    eta_index = material.viscosity_param or 0
    inv_G = 1.0 / kernel.n_grids
    n_grids = float(kernel.n_grids)
    mat = t.mat

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
        p = wp.tid() + start  # pyright: ignore[reportOperatorIssue]
        b = body[p]
        Fs = Fsn[p]
        F0 = F0s[p]
        V0 = volume[p]
        args = args_at(p, cache, K, dx)
        args.field = v
        D = S(inv_G) * gather(p, b, shape, cache, dx, mat(), args)
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
        args.field = residual
        args.diag = diag
        args.dt = dt
        args.M = stress
        args.T = T
        args.VF0T = wp.transpose(T.V) * wp.transpose(F0)  # pyright: ignore[reportOperatorIssue]
        args.FinvT = FinvT
        args.V0 = V0
        args.k_visc = k_visc
        scatter(p, b, shape, cache, dx, mat(), args)

    return evaluate


@functools.cache
def make_apply(t: Types, kernel: Kernel, transfer: str, viscous: bool):
    """Per particle: the scatter of dt dS_p g_ip for the direction dv (A's
    stress part; the mass part is added per node by :func:`make_node_kernels`)."""
    S = t.scalar
    Cache = make_stencil_cache(t, kernel)
    Tangent = make_tangent_type(t)
    action = make_tangent_action(t)
    args_at, gather, scatter, _ = make_walks(t, kernel, transfer)
    inv_G = 1.0 / kernel.n_grids
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
        args = args_at(p, cache, K, dx)  # pyright: ignore[reportArgumentType]
        args.field = dv
        D = S(inv_G) * gather(p, b, shape, cache, dx, mat(), args)  # pyright: ignore[reportArgumentType]
        dS = volume[p] * action(tangent[p], dt * D * F0) * wp.transpose(F0)
        if wp.static(viscous):
            Finv = wp.inverse(Fsn[p])
            L = D * Finv
            dS += visc[p] * S(0.5) * (L + wp.transpose(L)) * wp.transpose(Finv)
        args.field = out
        args.M = dt * dS
        scatter(p, b, shape, cache, dx, mat(), args)  # pyright: ignore[reportArgumentType]

    return apply


def make_node_kernels(t: Types):
    """The per-node halves of the solve (all float64 sums in ``acc``):
    Newton's (:func:`make_newton_node_kernels`) and conjugate gradients'
    (:func:`make_cg_node_kernels`)."""
    return (*make_newton_node_kernels(t), *make_cg_node_kernels(t))


@functools.cache
def make_newton_node_kernels(t: Types):
    """``finish_residual``, ``finish_apply``: the per-node halves of the
    residual and of A's action."""
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

    return finish_residual, finish_apply


@functools.cache
def make_cg_node_kernels(t: Types):
    """``cg_start``, ``cg_step``, ``cg_direction``, ``trial``: conjugate
    gradients' per-node passes and the line search's trial point."""
    f64 = wp.float64
    S = t.scalar
    vec = t.vec

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

    return cg_start, cg_step, cg_direction, trial


@functools.cache
def make_boundary_work(t: Types, rigid: bool = False):
    """Kernel: the impulse of the constraints on each node at the solution,
    J = m reaction (v - reaction: the velocity without it), into the step's
    ``status.boundary_impulse``, and its work, the positive part of J . v,
    into ``status.boundary_work`` (mpm.grid ``make_work``, mpm.stepping.detection),
    and that of a node a collider constrains (``contact_id``, mpm.grid
    ``make_constraints``; one entry without colliders) into its row of
    ``status.collider_impulse`` (a node stuck on a frictional collider:
    the whole reaction, normal and tangential; a sliding node's load adds
    its own, mpm.implicit.rough ``work``, and under the node rule the
    friction after the solve its own, :func:`make_friction`); with
    ``rigid``, its angular impulse about the collider's centre at ``time``
    into ``torque`` too (the node at ``q``, mpm.collider_device
    ``make_add_reaction``; mpm.rigid_coupling)."""
    S = t.scalar
    vec = t.vec
    work = make_work(t)
    add_reaction = make_add_reaction(t, rigid)
    Data = make_collider_data(t)

    @warp_kernel
    def boundary_work(m: wp.array(dtype=S), reaction: wp.array(dtype=vec), v: wp.array(dtype=vec),
                      contact_id: wp.array(dtype=wp.int32), q: wp.array(dtype=vec), time: S,
                      colliders: wp.array(dtype=Data), torque: wp.array(dtype=wp.float64), status: StepStatus):
        i = wp.tid()
        if m[i] > S(0.0):
            work(m[i], v[i] - reaction[i], v[i], status)
            if contact_id.shape[0] > i:
                if contact_id[i] >= 0:
                    add_reaction(status.collider_impulse, torque, colliders, contact_id[i], q[i], time,
                                 m[i] * reaction[i])

    return boundary_work


@functools.cache
def make_friction(t: Types, rigid: bool = False):
    """Kernel: Coulomb friction at the colliders after the solve, under the
    node rule (``Scene.boundary_rule`` "nodes", as earlier versions; the
    surface rule's is inside the solve, mpm.implicit.rough): the tangential
    velocity relative to the collider loses mu times the normal velocity
    the constraint removed (its reaction, while it pushes). Its impulse and
    work go into ``status`` as the constraints' do (:func:`make_boundary_work`,
    ``rigid`` its angular impulse too)."""
    S = t.scalar
    vec = t.vec
    work = make_work(t)
    add_reaction = make_add_reaction(t, rigid)
    Data = make_collider_data(t)

    @warp_kernel
    def friction(m: wp.array(dtype=S), free: wp.array(dtype=t.mat), reaction: wp.array(dtype=vec),
                 mu: wp.array(dtype=S), u: wp.array(dtype=vec), normal: wp.array(dtype=vec),
                 shift: wp.array(dtype=vec), contact_id: wp.array(dtype=wp.int32), v: wp.array(dtype=vec),
                 q: wp.array(dtype=vec), time: S, colliders: wp.array(dtype=Data),
                 torque: wp.array(dtype=wp.float64), status: StepStatus):
        i = wp.tid()
        if m[i] <= S(0.0) or mu[i] <= S(0.0):
            return
        push = wp.dot(reaction[i], normal[i])  # > 0: the constraint held the node out of the collider
        if push <= S(0.0):
            return
        vr = v[i] + shift[i] - u[i]  # the surface point's velocity relative to the collider (mpm.surface)
        vt = free[i] * vr
        lt = wp.length(vt)
        if lt > S(0.0):
            v_new = u[i] + (vr - vt) + vt * wp.max(S(0.0), S(1.0) - mu[i] * push / lt) - shift[i]
            work(m[i], v[i], v_new, status)
            if contact_id[i] >= 0:
                add_reaction(status.collider_impulse, torque, colliders, contact_id[i], q[i], time,
                             m[i] * (v_new - v[i]))
            v[i] = v_new

    return friction


@functools.cache
def make_side_kernels(t: Types):
    """Kernels of the one-sided constraints' rounds (mpm.implicit.solve
    ``ImplicitSolve._sides``): ``unconstrained`` turns the solution v into
    the velocity without the constraints' reaction, v - reaction, which the
    constraints then classify as they classify the predictor (a node held
    while its reaction pushes stays held; one the solution moves into a
    solid is held; one whose constraint pulls is let go); ``changed``
    counts the nodes whose projector Pi the classification changed."""
    S = t.scalar

    @warp_kernel
    def unconstrained(m: wp.array(dtype=S), reaction: wp.array(dtype=t.vec), v: wp.array(dtype=t.vec)):
        i = wp.tid()
        if m[i] > S(0.0):
            v[i] = v[i] - reaction[i]

    @warp_kernel
    def changed(free: wp.array(dtype=t.mat), before: wp.array(dtype=t.mat), count: wp.array(dtype=wp.int32)):
        i = wp.tid()
        d = free[i] - before[i]
        if wp.ddot(d, d) > S(0.0):
            wp.atomic_add(count, 0, 1)

    return unconstrained, changed
