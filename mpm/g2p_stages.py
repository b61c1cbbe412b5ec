"""The stages of G2P (mpm.g2p), each a Warp function made by a factory
specialised with ``wp.static`` flags, so that a scene compiles only what it
uses: the stencil sums, the affine matrix C, the update of x and F^sn (plain
or compensated), the removal at open faces, the step's per-particle figures
and the commit of the reference configuration (EMPM).
"""

import functools
from typing import Any

import warp as wp

from .kernels import Kernel
from .reference_update import make_committed, make_moment_at
from .stepping.status import StepStatus
from .stencil import make_cached, make_node, make_node_gradient, make_stencil_cache
from .types import Types


def transfer_flags(kernel: Kernel, transfer: str):
    """``(mls, affine, flip)``: C from B K_p (MLS), C at all (not PIC or
    FLIP), FLIP's blend."""
    mls = transfer == "mls" and not kernel.gradient_affine
    return mls, transfer not in ("pic", "flip"), transfer == "flip"


@wp.func
def compensated_add(s: Any, inc: Any, c: Any):
    """``(s', c')``: s + inc as a compensated (Kahan) sum whose running error
    is c (mpm.g2p): y = inc - c, s' = s + y, c' = (s' - s) - y."""
    y = inc - c
    s_new = s + y
    return s_new, (s_new - s) - y


@functools.cache
def make_min_stretch2(t: Types):
    """``min_stretch2(F)``: the square of the smallest singular value of F,
    exact in 2D (the stable root 2 det^2 / (|F|^2 + sqrt(|F|^4 - 4 det^2)));
    in 3D the lower bound 3 det^2 / |cof F|^2, equal to 1 at F = I and never
    below a third of the true value."""
    S = t.scalar

    @wp.func
    def min_stretch2(F: t.mat):
        d = wp.determinant(F)
        if wp.static(t.dim == 2):
            f2 = wp.ddot(F, F)
            return S(2.0) * d * d / wp.max(f2 + wp.sqrt(wp.max(f2 * f2 - S(4.0) * d * d, S(0.0))),  # pyright: ignore[reportArgumentType]
                                           S(1.0e-30))
        else:
            G = wp.transpose(wp.inverse(F)) * d  # cofactor matrix
            return wp.min(S(3.0) * d * d / wp.max(wp.ddot(G, G), S(1.0e-30)), S(1.0))

    return min_stretch2


@functools.cache
def make_velocity_sums(t: Types, kernel: Kernel, transfer: str, fused: bool):
    """``sums(p, b, shape, cache, grid_v, grid_m, grid_p0, dx) -> (v, v0, B,
    grad v)``: over the G grids, not yet divided by G, the sums of W_ip v_i,
    of FLIP's W_ip p0_i / m_i, of B = W_ip v_i r^T (the affine transfers that
    take C from B) and of v_i grad_ip^T (not MLS)."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    dim, Ks, G = t.dim, kernel.support, kernel.n_grids
    mls, affine, flip = transfer_flags(kernel, transfer)
    with_B = affine and not kernel.gradient_affine  # B = sum w v r^T for C
    node = make_node(t, kernel)
    node_gradient = make_node_gradient(t, kernel)
    Cache = make_stencil_cache(t, kernel)
    reference, cached = make_cached(t, kernel, not mls, fused)

    @wp.func
    def slab(col: vec, r: S, v: vec):
        """A column of B / dx takes in a slab's weighted velocity v at offset
        r = index - fx; the next slab's offset."""
        col_next = col
        if wp.static(with_B):
            col_next = col + r * v
        return col_next, r + S(1.0)

    @wp.func
    def sums(p: int, b: int, shape: wp.array(dtype=t.ivec), cache: Cache, grid_v: wp.array(dtype=vec),
             grid_m: wp.array(dtype=S), grid_p0: wp.array(dtype=vec), dx: S):
        vp = vec()
        v_transferred = vec()  # FLIP: sum w p0_i / m_i
        B = mat()
        grad_v = mat()
        u0, ph = reference(p, cache)
        for g in range(G):
            st, flat, fx, W, dW = cached(p, g, b, shape, cache, u0, ph)
            # B = sum w v_i r^T with r = (index - fx) dx: per axis, the weighted velocities summed over
            # the stencil's slabs, times the slab's offset index - fx (no outer product per node)
            col0 = vec()
            col1 = vec()
            col2 = vec()
            ra = -fx[0]  # the slabs' offsets r / dx
            for a in range(Ks):
                va = vec()
                rb = -fx[1]
                for bb in range(Ks):
                    vb = vec()
                    rc = -fx[dim - 1]
                    for c in range(wp.static(Ks if dim == 3 else 1)):
                        w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                        vi = grid_v[i]
                        wv = w * vi
                        if wp.static(flip):
                            if w > S(0.0):
                                v_transferred += (w / grid_m[i]) * grid_p0[i]
                        vb += wv
                        if wp.static(dim == 3):
                            col2, rc = slab(col2, rc, wv)
                        if wp.static(not mls):
                            grad_v += wp.outer(vi, node_gradient(a, bb, c, W, dW, S(1.0) / dx))
                    va += vb
                    col1, rb = slab(col1, rb, vb)
                vp += va
                col0, ra = slab(col0, ra, va)
            if wp.static(with_B):
                if wp.static(dim == 3):
                    B += dx * wp.matrix_from_cols(col0, col1, col2)
                else:
                    B += dx * wp.matrix_from_cols(col0, col1)
        return vp, v_transferred, B, grad_v

    return sums


@functools.cache
def make_affine(t: Types, kernel: Kernel, transfer: str):
    """``affine(p, B, grad_v, K, cache) -> (C, grad v)`` from the sums of
    :func:`make_velocity_sums` (B and grad v summed over the G grids): C =
    1/G B K_p (MLS and APIC with a moment), 1/G grad v (a gradient-affine
    kernel), 0 (PIC, FLIP); grad v = C for MLS."""
    S = t.scalar
    mat = t.mat
    mls, affine, _ = transfer_flags(kernel, transfer)
    affine_from_gradient = affine and kernel.gradient_affine
    per_particle_K = kernel.moment is None
    inv_G = 1.0 / kernel.n_grids
    Cache = make_stencil_cache(t, kernel)

    @wp.func
    def from_B(p: int, B: mat, K: S, cache: Cache):
        """C = 1/G B K_p."""
        if wp.static(per_particle_K):
            return S(inv_G) * B * cache.K[p]
        else:
            return (S(inv_G) * K) * B

    @wp.func
    def affine_C(p: int, B: mat, grad_v: mat, K: S, cache: Cache):
        Cp = mat()
        L = grad_v
        if wp.static(mls):
            Cp = from_B(p, B, K, cache)
            L = Cp
        else:
            L = S(inv_G) * grad_v
            if wp.static(affine_from_gradient):
                Cp = L
            elif wp.static(affine):
                Cp = from_B(p, B, K, cache)
        return Cp, L

    return affine_C


@functools.cache
def make_advance(t: Types, compensate: bool, commit: bool):
    """``advance(p, dt, v, grad_v, x, xc, Fsn, Fc) -> (x', xc', F^sn, F^sn',
    Fc')``: x' = x + dt v, F^sn' = F^sn + dt grad v, each plain or (F^sn's
    unless ``commit``) a compensated sum with its running error (mpm.g2p);
    the errors are zero where not compensated. ``store(p, x', xc', v', C',
    F^sn', Fc', x, xc, v, C, Fsn, Fc)`` writes the new state (F^sn with
    ``commit`` is the commit's)."""
    vec, mat = t.vec, t.mat
    S = t.scalar
    compensate_x = compensate
    compensate_F = compensate and not commit

    @wp.func
    def advance(p: int, dt: S, vp: vec, grad_v: mat, x: wp.array(dtype=vec), xc: wp.array(dtype=vec),
                Fsn: wp.array(dtype=mat), Fc: wp.array(dtype=mat)):
        x_old = x[p]
        xp = x_old + dt * vp
        xc_new = vec()
        if wp.static(compensate_x):
            xp, xc_new = compensated_add(x_old, dt * vp, xc[p])
        Fsn_old = Fsn[p]
        Fs = Fsn_old + dt * grad_v
        Fc_new = mat()
        if wp.static(compensate_F):
            Fs, Fc_new = compensated_add(Fsn_old, dt * grad_v, Fc[p])
        return xp, xc_new, Fsn_old, Fs, Fc_new

    @wp.func
    def store(p: int, xp: vec, xc_new: vec, v_new: vec, Cp: mat, Fs: mat, Fc_new: mat, x: wp.array(dtype=vec),
              xc: wp.array(dtype=vec), v: wp.array(dtype=vec), C: wp.array(dtype=mat), Fsn: wp.array(dtype=mat),
              Fc: wp.array(dtype=mat)):
        x[p] = xp
        if wp.static(compensate_x):
            xc[p] = xc_new
        v[p] = v_new
        C[p] = Cp
        if wp.static(not commit):
            Fsn[p] = Fs
            if wp.static(compensate_F):
                Fc[p] = Fc_new

    return advance, store


@functools.cache
def make_commit(t: Types, kernel: Kernel, transfer: str, project):
    """``commit(p, X, F^sn, F^0s, params, F0s, Fsn, cache, dx)``: the
    reference configuration moves to X (mpm.reference_update): F^0s <-
    project(F^sn F^0s), F^sn <- I and K_p at X where the kernel's moment
    varies (the affine transfers read it); ``commit_compensated(p, X, D, F^0s,
    F0s, Fsn, Fc, cache, dx)``: the same with F^0s <- F^0s + D F^0s, D = dt
    grad v, a compensated sum whose running error is Fc."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    mls, affine, _ = transfer_flags(kernel, transfer)
    commit_K = kernel.moment is None and affine
    committed = make_committed(t, project)
    moment_at = make_moment_at(t, kernel, not mls)
    Cache = make_stencil_cache(t, kernel)
    dim = t.dim

    @wp.func
    def move_reference(p: int, Xp: vec, Fsn: wp.array(dtype=mat), cache: Cache, dx: S):
        cache.X[p] = Xp
        Fsn[p] = wp.identity(n=dim, dtype=S)
        if wp.static(commit_K):
            cache.K[p] = moment_at(Xp, S(1.0) / dx, cache.grid_offsets, dx)

    @wp.func
    def commit(p: int, Xp: vec, Fs: mat, F0: mat, params: t.params, F0s: wp.array(dtype=mat),
               Fsn: wp.array(dtype=mat), cache: Cache, dx: S):
        F0s[p] = committed(Fs, F0, params)
        move_reference(p, Xp, Fsn, cache, dx)

    @wp.func
    def commit_compensated(p: int, Xp: vec, D: mat, F0: mat, F0s: wp.array(dtype=mat),
                           Fsn: wp.array(dtype=mat), Fc: wp.array(dtype=mat), cache: Cache, dx: S):
        F0n, c = compensated_add(F0, D * F0, Fc[p])
        Fc[p] = c
        F0s[p] = F0n
        move_reference(p, Xp, Fsn, cache, dx)

    return commit, commit_compensated


@functools.cache
def make_grow_box(t: Types):
    """``grow_box(status, b, x)``: body b's bounding box of the new positions
    (the next reference grids) takes in x."""
    dim = t.dim

    @wp.func
    def grow_box(status: StepStatus, b: int, xp: t.vec):
        for d in range(wp.static(dim)):
            wp.atomic_min(status.box_lo, b * dim + d, wp.float64(xp[d]))
            wp.atomic_max(status.box_hi, b * dim + d, wp.float64(xp[d]))

    return grow_box


@functools.cache
def make_removal(t: Types, kernel: Kernel, transfer: str, project, commit: bool):
    """``parked(p, b, x, mass, ...) -> bool``: whether the particle was
    removed in an earlier step; ``remove(p, b, x', F^sn, bounds..., arrays...)
    -> bool``: whether the
    particle crossed the interior's bound on an open face; if so it is
    removed (mpm.g2p: massless, clamped inside, at rest, counted), with
    ``commit`` its reference moved there (F^sn was not advanced)."""
    S = t.scalar
    vec, mat = t.vec, t.mat
    dim = t.dim
    grow_box = make_grow_box(t)
    commit_reference = make_commit(t, kernel, transfer, project)[0]
    Cache = make_stencil_cache(t, kernel)

    @wp.func
    def remove(p: int, b: int, xp: vec, Fsn_old: mat, inside_lo: vec, inside_hi: vec, open_lo: vec,
               open_hi: vec, x: wp.array(dtype=vec), v: wp.array(dtype=vec), C: wp.array(dtype=mat),
               mass: wp.array(dtype=S), volume: wp.array(dtype=S), status: StepStatus,
               body_params: wp.array(dtype=t.params), F0s: wp.array(dtype=mat), Fsn: wp.array(dtype=mat),
               cache: Cache, dx: S):
        gone = False
        for d in range(wp.static(dim)):
            if (xp[d] < inside_lo[d] and open_lo[d] > S(0.0)) or (xp[d] > inside_hi[d] and open_hi[d] > S(0.0)):
                gone = True
        if gone and wp.isfinite(xp):
            xq = xp
            for d in range(wp.static(dim)):
                xq[d] = wp.clamp(xq[d], inside_lo[d], inside_hi[d])
            x[p] = xq
            v[p] = vec()
            C[p] = mat()
            mass[p] = S(0.0)
            volume[p] = S(0.0)
            wp.atomic_add(status.removed, b, wp.float64(1.0))
            grow_box(status, b, xq)
            if wp.static(commit):  # F^sn was not advanced for a removed particle
                commit_reference(p, xq, Fsn_old, F0s[p], body_params[b], F0s, Fsn, cache, dx)
            return True
        return False

    @wp.func
    def parked(p: int, b: int, x: wp.array(dtype=vec), mass: wp.array(dtype=S), status: StepStatus,
               body_params: wp.array(dtype=t.params), F0s: wp.array(dtype=mat), Fsn: wp.array(dtype=mat),
               cache: Cache, dx: S):
        """Whether the particle was removed before (massless): parked inside,
        still in its body's reference box (with ``commit`` committed in place)."""
        if mass[p] == S(0.0):
            grow_box(status, b, x[p])
            if wp.static(commit):
                commit_reference(p, x[p], Fsn[p], F0s[p], body_params[b], F0s, Fsn, cache, dx)
            return True
        return False

    return remove, parked


@functools.cache
def make_figures(t: Types, record_dJ: bool, count_marked: bool, lagrangian: bool, track_compression: bool,
                 track_energy: bool, track_inversion: bool, bound_reach: bool):
    """``figures(p, b, x', v', F^sn', F^sn, grad_v, ...)``: the particle's
    share of the step's figures in ``status`` (mpm.g2p: dJ_p and the marked
    count, the smallest J, stretches, the largest rate |L|^2 and speed, the
    energies, the non-finite and outside counts, the bounding box)."""
    S = t.scalar
    f64 = wp.float64
    vec, mat = t.vec, t.mat
    dim = t.dim
    min_stretch2 = make_min_stretch2(t)
    grow_box = make_grow_box(t)

    @wp.func
    def row_sum_norm(F: mat):
        """|F|_inf = max_d sum_k |F_dk|: |(F r)_d| <= |F|_inf max_k |r_k|."""
        n = S(0.0)
        for d in range(wp.static(dim)):
            row = S(0.0)
            for k in range(wp.static(dim)):
                row += wp.abs(F[d, k])
            n = wp.max(n, row)
        return n

    @wp.func
    def deformation(p: int, b: int, Fs: mat, Fsn_old: mat, grad_v: mat, epsilon: S, F0s: wp.array(dtype=mat),
                    dJ: wp.array(dtype=S), status: StepStatus):
        dj = wp.abs(wp.determinant(Fs) - S(1.0))
        if wp.static(record_dJ):
            dJ[p] = dj
        if wp.static(count_marked):
            if dj >= epsilon:
                wp.atomic_add(status.marked, b, f64(1.0))
            wp.atomic_max(status.max_dJ, b, f64(dj))  # pyright: ignore[reportArgumentType]
        if wp.static(track_compression or track_inversion):
            wp.atomic_min(status.min_J, b, f64(wp.determinant(Fs) * wp.determinant(F0s[p])))
        if wp.static(track_inversion):
            wp.atomic_min(status.min_F_stretch2, b, f64(min_stretch2(Fs * F0s[p])))  # pyright: ignore[reportArgumentType]
        # |L|^2 of the velocity gradient in current coordinates, L = grad_v (F^sn)^-1
        # (for EMPM F^sn was I: L = grad_v); a singular F^sn makes it non-finite
        rate2 = wp.ddot(grad_v, grad_v)
        if wp.static(lagrangian):
            s2 = min_stretch2(Fs)
            wp.atomic_min(status.min_stretch2, b, f64(s2))  # pyright: ignore[reportArgumentType]
            if wp.static(bound_reach):
                wp.atomic_max(status.max_F_norm, b, f64(row_sum_norm(Fs)))  # pyright: ignore[reportArgumentType]
            L = grad_v * wp.inverse(Fsn_old)
            rate2 = wp.ddot(L, L)
        wp.atomic_max(status.max_rate2, b, f64(rate2))

    @wp.func
    def motion(p: int, b: int, mass: wp.array(dtype=S), xp: vec, v_new: vec, Fs: mat, gravity: vec, inside_lo: vec,
               inside_hi: vec, status: StepStatus):
        """The stability monitor and the bounding box of the new positions."""
        v2 = f64(wp.dot(v_new, v_new))
        wp.atomic_max(status.max_v2, 0, v2)
        if wp.static(track_energy):
            wp.atomic_add(status.kinetic, 0, f64(0.5) * f64(mass[p]) * v2)
            wp.atomic_add(status.potential, 0, -f64(mass[p]) * f64(wp.dot(gravity, xp)))
            wp.atomic_max(status.max_speed2, b, v2)
        if not (wp.isfinite(xp) and wp.isfinite(v_new) and wp.isfinite(Fs)):
            wp.atomic_add(status.nonfinite, 0, f64(1.0))
        else:
            outside = False
            for d in range(wp.static(dim)):
                if xp[d] < inside_lo[d] or xp[d] > inside_hi[d]:
                    outside = True
            grow_box(status, b, xp)
            if outside:
                wp.atomic_add(status.outside, 0, f64(1.0))

    return deformation, motion
