"""Coulomb friction between bodies inside the implicit solve (mpm.implicit).

The frictionless constraint of a bin g where bodies a and c touch
(mpm.contact.constraint) asks for equal normal velocities,
n_a . (V_a - V_c) = 0, with V_b = sum_{i in (b, g)} w_i v_i the bin's mean
velocity of body b, w_i = m_i / (G M_bg). With friction every bin where
two bodies touch is a constraint, approaching on the predictor or not (a
block resting on a plate falls with it on the predictor, so the approach
test would leave out most of its contact), and each bin with mu_ac > 0 is
in one of two states, chosen by an active set:

* stick: the whole relative velocity vanishes, V_a - V_c = 0 (d rows per
  bin, c_i = s_i w_i I with s_i = +1 on a's nodes and -1 on c's). The rows
  of one bin share its nodes, so B W B^T is a d x d block per bin and the
  W-orthogonal projection is still one bin sum and one node pass:
  lambda_g = (sum s_i w_i Pi_i W_i x_i) solved against
  (sum w_i^2 Pi_i W_i Pi_i), x_i -= s_i w_i Pi_i lambda_g (W as in
  mpm.contact.constraint ``make_projection``; mode 0: W = M^-1). Where
  a wall or a collider holds every node of the bin along one direction,
  the block is singular there: it is solved on its range (its
  pseudo-inverse), so the bin still sticks, or slides, along the
  directions left free (earlier versions kept the normal row only: the
  bin stayed stuck with no tangential reaction, and never slid).
* slip: the normal row only, and a tangential impulse of magnitude
  mu lambda_n along the slip, applied as a known load: the predictor of a's
  nodes v*_i += s_i w_i Pi_i f_g / m_i (and c's with the opposite sign),
  f_g = -mu lambda_n u_t / |u_t|, u_t the tangential part of V_a - V_c
  (the impulse on a opposes a's slip).

With lambda_g a bin's reaction at the solution (the residual's projection
sums: R_i = s_i w_i Pi_i lambda_g is node i's share, so the impulse on a
is lambda_g and on c -lambda_g) the
normal reaction is lambda_n = -n_a . lambda_g (> 0 pressing the bodies
together) and its tangential part lambda_t. After a solve
(:func:`make_friction_constraint` ``classify``): a stick bin whose
|lambda_t| exceeds mu lambda_n slides, with f_g = mu lambda_n
lambda_t / |lambda_t|; a sliding bin whose slip the load turned round
(u_t . f_g > 0) sticks;
a sliding bin's f_g follows its new lambda_n and slip direction; a bin
whose lambda_n is not positive (the bodies pull at each other) lets go: no
row for the rest of the step (the explicit pass after the solve catches a
bin that then approaches). The solve is repeated
from its last solution until no bin changes and the loads have settled
(mpm.implicit.rounds FRICTION_TOL, mpm.implicit.solve ROUNDS). The two
bodies' impulses are equal and opposite in every state (momentum kept);
a stuck pair does no work, a sliding one the work of f_g against its slip
(``contact_work``).
"""

import functools

import warp as wp

from .constraint import make_remove
from .lattice import make_bins, make_occupancy, make_outward
from ..lattice import make_lattice
from ..launch import warp_kernel
from ..stepping.status import StepStatus
from ..types import Types

NONE, STICK, SLIP, FREE = 0, 1, 2, 3  # a bin's state: frictionless, stuck, sliding, let go (-1: no contact)
SINGULAR = 1.0e-8  # det / trace^d of a stick block below which it is solved on its range (pseudo-inverse)
RANK = 1.0e-6  # an eigenvalue of a singular stick block below this fraction of its largest: out of its range


@functools.cache
def make_coulomb_round(t: Types):
    """``coulomb_round(state, R_t, limit, u_t, L, tol) -> (state', L', moved)``:
    one round of Coulomb's rule for a pair stuck (STICK) or sliding (SLIP)
    after a solve, shared by the bins between bodies (here) and the nodes
    at a collider (mpm.implicit.rough). ``R_t``: the tangential reaction;
    ``limit``: mu times the normal reaction; ``u_t``: the slip; ``L``: the
    sliding load. A stuck pair whose |R_t| exceeds the limit slides with
    L' = limit R_t / |R_t|; a sliding pair whose slip the load turned round
    (u_t . L > 0) sticks (L' = 0); a sliding pair's load takes the limit
    against its slip (its old direction where it does not slip). ``moved``:
    1 where the state changed or the load moved by more than ``tol`` of the
    limit."""
    S, vec = t.scalar, t.vec

    @wp.func
    def coulomb_round(state: int, Rt: vec, limit: S, ut: vec, L: vec, tol: S):
        after = state
        L_new = L
        moved = int(0)
        if state == STICK:
            lt = wp.length(Rt)
            if lt > limit:
                after = SLIP
                L_new = Rt * (limit / lt)
                moved = 1
        elif wp.dot(ut, L) > S(0.0):  # the load turned the slip round: the pair sticks
            after = STICK
            L_new = vec()
            moved = 1
        else:
            lu = wp.length(ut)
            L_new = L * (limit / wp.max(wp.length(L), S(1.0e-30)))
            if lu > S(0.0):
                L_new = ut * (-limit / lu)
            if wp.length(L_new - L) > tol * limit:
                moved = 1
        return after, L_new, moved

    return coulomb_round


@functools.cache
def make_friction_constraint(t: Types, normal: str = "difference"):
    """``frame``, ``sums``, ``project``, ``classify``, ``load``, ``work``:
    the kernels of friction inside the implicit solve (module docstring)."""
    S = t.scalar
    f64 = wp.float64
    vec, mat = t.vec, t.mat
    Lattice = make_lattice(t)
    Bins = make_bins(t)
    outward = make_outward(t, normal)
    occupancy = make_occupancy(t)
    remove = make_remove(t)
    coulomb_round = make_coulomb_round(t)

    @wp.func
    def pseudo_solve(den: mat, num: vec):
        """den^+ num for a symmetric semi-definite block: the solve on the
        eigenvectors whose eigenvalues exceed RANK of the largest (a bin
        whose nodes a wall or collider holds along one direction has no
        row there; its other directions still stick)."""
        out = vec()
        if wp.static(t.dim == 2):
            a = den[0, 0]
            b = S(0.5) * (den[0, 1] + den[1, 0])
            c = den[1, 1]
            mean = S(0.5) * (a + c)
            r = wp.sqrt(S(0.25) * (a - c) * (a - c) + b * b)
            phi = S(0.5) * wp.atan2(S(2.0) * b, a - c)
            e1 = vec(wp.cos(phi), wp.sin(phi))  # eigenvector of mean + r
            e2 = vec(-e1[1], e1[0])
            top = mean + r
            if top > S(0.0):
                out = e1 * (wp.dot(e1, num) / top)
                if mean - r > S(RANK) * top:
                    out = out + e2 * (wp.dot(e2, num) / (mean - r))
        else:
            Q = mat()
            d = vec()
            wp.eig3(S(0.5) * (den + wp.transpose(den)), Q, d)
            top = wp.max(d[0], wp.max(d[1], d[2]))
            for k in range(3):
                if top > S(0.0) and d[k] > S(RANK) * top:
                    e = vec(Q[0, k], Q[1, k], Q[2, k])
                    out = out + e * (wp.dot(e, num) / d[k])
        return out

    @wp.func
    def reaction(state: int, n: vec, num: vec, den: mat):
        """lambda_g from the bin's sums: the d x d solve of a stuck bin (on
        the block's range where it is singular), none for a bin let go, the
        normal row's otherwise."""
        if state == FREE:
            return vec()
        if state == STICK:
            tr = wp.trace(den)
            if tr > S(0.0) and wp.determinant(den) > S(SINGULAR) * wp.pow(tr, S(wp.static(t.dim))):
                return wp.inverse(den) * num
            if tr > S(0.0):
                return pseudo_solve(den, num)
        s = wp.dot(n, den * n)
        if s > S(0.0):
            return n * (wp.dot(n, num) / s)
        return vec()

    @warp_kernel
    def frame(lat: Lattice, bins: Bins, cbin: wp.array(dtype=wp.int32), bnormal: wp.array(dtype=vec),
              state: wp.array(dtype=wp.int32), mu: wp.array(dtype=S), force: wp.array(dtype=vec)):
        """Per active bin (between mpm.contact ``bin`` and ``unbin``): n_a as
        ``couple`` found it, mu_ac, no load, and the start: stuck where mu_ac > 0."""
        i = wp.tid()
        g = cbin[i]
        if g < 0:
            return
        _present, _m, _p, _volume, a, c = occupancy(lat, bins, g)
        bnormal[g] = outward(lat, bins, a, g)  # (every node of the bin writes the same)
        mu_ac = bins.mu[a * lat.n_bodies + c]
        mu[g] = mu_ac
        force[g] = vec()
        if mu_ac > S(0.0):
            state[g] = STICK
        else:
            state[g] = NONE

    @warp_kernel
    def sums(mode: int, cbin: wp.array(dtype=wp.int32), coef: wp.array(dtype=vec),
             bnormal: wp.array(dtype=vec), free: wp.array(dtype=mat), m: wp.array(dtype=S),
             inv_diag: wp.array(dtype=vec), x: wp.array(dtype=vec),
             num: wp.array(dtype=vec),  # per bin: sum s w Pi W x (mode 0: sum s w x)
             den: wp.array(dtype=mat)):  # per bin: sum w^2 Pi W Pi
        i = wp.tid()
        g = cbin[i]
        if g < 0:
            return
        sw = wp.dot(coef[i], bnormal[g])  # s_i w_i
        Pi = free[i]
        if mode == 0:
            wp.atomic_add(num, g, sw * x[i])
            wp.atomic_add(den, g, (sw * sw / m[i]) * (Pi * wp.transpose(Pi)))
        else:
            W = wp.diag(inv_diag[i])
            wp.atomic_add(num, g, sw * (Pi * (W * x[i])))
            wp.atomic_add(den, g, (sw * sw) * (Pi * W * wp.transpose(Pi)))

    @warp_kernel
    def project(mode: int, cbin: wp.array(dtype=wp.int32), coef: wp.array(dtype=vec),
                bnormal: wp.array(dtype=vec), state: wp.array(dtype=wp.int32), free: wp.array(dtype=mat),
                m: wp.array(dtype=S), inv_diag: wp.array(dtype=vec), num: wp.array(dtype=vec),
                den: wp.array(dtype=mat), x: wp.array(dtype=vec), z: wp.array(dtype=vec),
                acc: wp.array(dtype=f64), r2: int, rz: int):
        """As mpm.contact.constraint ``project``, with a stuck bin's d rows."""
        i = wp.tid()
        g = cbin[i]
        if g < 0:
            return
        n = bnormal[g]
        Pi = free[i]
        ct = Pi * (wp.dot(coef[i], n) * reaction(state[g], n, num[g], den[g]))
        if mode == 0:
            x[i] = x[i] - ct / m[i]
            return
        remove(mode, i, ct, Pi, inv_diag, x, z, acc, r2, rz)  # pyright: ignore[reportArgumentType]

    @warp_kernel
    def classify(bnormal: wp.array(dtype=vec), state: wp.array(dtype=wp.int32), mu: wp.array(dtype=S),
                 num: wp.array(dtype=vec), den: wp.array(dtype=mat), rel: wp.array(dtype=vec),
                 force: wp.array(dtype=vec), tol: S, after: wp.array(dtype=vec),
                 changed: wp.array(dtype=wp.int32)):
        """Per bin, after a solve with the loads ``force``: its next state and
        load f_g into ``after`` (module docstring); ``num``, ``den`` the
        residual's sums at the solution, ``rel`` V_a - V_c (mode-0 sums of
        the solution), ``mu`` per bin. Counts the bins that changed state or
        whose f_g moved by more than ``tol`` of mu lambda_n (none: the solve
        stands with ``force`` and ``state`` as they were)."""
        g = wp.tid()
        st = state[g]
        f = force[g]
        after[g] = f
        if st < NONE or st == FREE:
            return
        n = bnormal[g]
        lam = reaction(st, n, num[g], den[g])
        lam_n = -wp.dot(lam, n)
        if not (lam_n > S(0.0)):  # the bodies pull at each other: no constraint
            state[g] = FREE
            after[g] = vec()
            wp.atomic_add(changed, 0, 1)
            return
        if st == NONE:
            return
        st_new, f_new, moved = coulomb_round(st, lam - wp.dot(lam, n) * n, mu[g] * lam_n,
                                             rel[g] - wp.dot(rel[g], n) * n, f, tol)
        state[g] = st_new
        after[g] = f_new
        if moved != 0:
            wp.atomic_add(changed, 0, 1)

    @warp_kernel
    def load(cbin: wp.array(dtype=wp.int32), coef: wp.array(dtype=vec), bnormal: wp.array(dtype=vec),
             state: wp.array(dtype=wp.int32), force: wp.array(dtype=vec), free: wp.array(dtype=mat),
             m: wp.array(dtype=S), v_star0: wp.array(dtype=vec), v_star: wp.array(dtype=vec)):
        """The predictor with the sliding bins' loads: v* = v*0 + s w Pi f / m."""
        i = wp.tid()
        v = v_star0[i]
        g = cbin[i]
        if g >= 0 and m[i] > S(0.0):
            if state[g] == SLIP:
                v = v + free[i] * (wp.dot(coef[i], bnormal[g]) * force[g]) / m[i]
        v_star[i] = v

    @warp_kernel
    def work(cbin: wp.array(dtype=wp.int32), coef: wp.array(dtype=vec), bnormal: wp.array(dtype=vec),
             state: wp.array(dtype=wp.int32), force: wp.array(dtype=vec), free: wp.array(dtype=mat),
             n_grids: int, v: wp.array(dtype=vec), status: StepStatus):
        """The sliding bins' work on the solution: sum_i J_i . v_i with
        J_i = s w Pi f / G the node's impulse [kg m/s] (each grid holds the full mass)."""
        i = wp.tid()
        g = cbin[i]
        if g < 0 or state[g] != SLIP:
            return
        J = (free[i] * (wp.dot(coef[i], bnormal[g]) * force[g])) / S(n_grids)
        wp.atomic_add(status.contact_work, 0, f64(wp.dot(J, v[i])))

    return frame, sums, project, classify, load, work
