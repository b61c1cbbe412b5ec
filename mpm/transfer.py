"""Particle-to-grid and grid-to-particle transfers (MLS-MPM with APIC), in
each body's reference configuration.

Notation (REFERENCE.md §1, A-ULMPM paper eq. 10-33): ``X_p`` reference
particle positions, ``X_i`` reference node positions, ``r = X_i - X_p``,
``W_ip`` kernel weights (cached at the last configuration update),
``K_p = I / (moment dx^2)`` the MLS moment inverse, ``F^{0s}`` the deformation
gradient at the last update, ``F^{sn}`` the deformation since then,
``F^{0n} = F^{sn} F^{0s}``.

P2G (eq. 10-12, 20, 23; force and momentum fused as in MLS-MPM):
    m_i      = sum_p W_ip m_p
    m_i v_i  = sum_p W_ip [m_p v_p + (m_p C_p - dt V_p^0 P(F^{0n}) F^{0s,T} K_p) r]
    m_i q_i  = sum_p W_ip m_p (x_p + F^{sn}_p r)     (current node positions)
after division by m_i the nodal velocity holds the internal-force impulse.
The stored energy sum_p V_p^0 psi(F^{0n}_p) of the state the step starts from
is accumulated on the way (one decomposition of F for stress and energy).

G2P (eq. 28, 30, 31; APIC form):
    v_p = sum_i W_ip v_i,   C_p = sum_i W_ip v_i r^T K_p,
    x_p += dt v_p,          F^{sn} += dt C_p,   dJ_p = |det F^{sn} - 1|.
"""

import functools

import warp as wp

from .kernels import Kernel
from .stencil import make_node, make_strides, weight_matrix_type
from .types import Types

# layout of the per-step status buffer (float64): see Solver.check
STATUS_MAX_V2, STATUS_NONFINITE, STATUS_OUTSIDE, STATUS_HEADER = 0, 1, 2, 3
STATUS_PER_BODY = 5  # marked count, largest dJ, smallest J, smallest stretch^2, largest |L|^2


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
            return S(2.0) * d * d / wp.max(f2 + wp.sqrt(wp.max(f2 * f2 - S(4.0) * d * d, S(0.0))),
                                           S(1.0e-30))
        else:
            G = wp.transpose(wp.inverse(F)) * d  # cofactor matrix
            return wp.min(S(3.0) * d * d / wp.max(wp.ddot(G, G), S(1.0e-30)), S(1.0))

    return min_stretch2


@functools.cache
def make_p2g(t: Types, kernel: Kernel, material, with_regions: bool):
    """P2G for the particles of one material model (``material`` is its class);
    ``with_regions``: also the mass each node draws from kinematic regions."""
    f64 = wp.float64
    S = t.scalar
    dim, Ks = t.dim, kernel.support
    node = make_node(t, kernel)
    strides = make_strides(t)
    stress_energy = material.stress_energy(t)
    Wm = weight_matrix_type(t, kernel)
    needs_L = material.needs_velocity_gradient

    @wp.kernel(module="unique")
    def p2g(
        # Model:
        mass: wp.array(dtype=S),
        volume: wp.array(dtype=S),
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        shape: wp.array(dtype=t.ivec),
        # State in:
        x: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        cache_base: wp.array(dtype=wp.int32),
        cache_fx: wp.array(dtype=t.vec),
        cache_W: wp.array(dtype=Wm),
        # Step:
        dx: S,
        K: S,
        dt: S,
        start: int,
        # Grid out:
        grid_m: wp.array(dtype=S),
        grid_mv: wp.array(dtype=t.vec),
        grid_mq: wp.array(dtype=t.vec),
        region: wp.array(dtype=wp.int32),
        grid_kin: wp.array(dtype=S),
        grid_kin_id: wp.array(dtype=wp.int32),
        # Diagnostics out:
        energy: wp.array(dtype=f64),
    ):
        p = wp.tid() + start
        b = body[p]
        st = strides(shape[b])
        flat = cache_base[p]
        fx = cache_fx[p]
        W = cache_W[p]
        m = mass[p]
        xp = x[p]
        Cp = C[p]
        Fs = Fsn[p]
        F0 = F0s[p]
        L = Cp  # velocity gradient in current coordinates: C (F^sn)^-1
        if wp.static(needs_L):
            L = Cp * wp.inverse(Fs)
        P, psi = stress_energy(Fs * F0, L, body_params[b])
        wp.atomic_add(energy, 0, f64(volume[p] * psi))
        affine = m * Cp - (dt * volume[p] * K) * P * wp.transpose(F0)
        mv = m * v[p]
        rid = int(0)
        if wp.static(with_regions):
            rid = region[p]
        for a in range(Ks):
            for bb in range(Ks):
                for c in range(wp.static(Ks if dim == 3 else 1)):
                    w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                    wp.atomic_add(grid_m, i, w * m)
                    wp.atomic_add(grid_mv, i, w * (mv + affine * r))
                    wp.atomic_add(grid_mq, i, (w * m) * (xp + Fs * r))
                    if wp.static(with_regions):
                        if rid > 0:
                            wp.atomic_add(grid_kin, i, w * m)
                            wp.atomic_max(grid_kin_id, i, rid)

    return p2g


@functools.cache
def make_g2p(t: Types, kernel: Kernel, record_dJ: bool, count_marked: bool, lagrangian: bool,
             track_compression: bool):
    """G2P for all particles.

    ``lagrangian``: the reference may lag behind (not EMPM), so track the
    narrowest current cell and take the velocity gradient as C (F^sn)^-1 (for
    EMPM F^sn = I at the start of every step: it is C);
    ``track_compression``: a material stiffens under compression (a fluid).

    ``status`` accumulates [max |v_p|^2, non-finite count, outside count],
    then per body the marked count (``count_marked``: dJ_p >= epsilon), the
    largest dJ_p, the smallest J = det F^{0n} (for the time step of materials
    that stiffen under compression), the smallest stretch of F^{sn} (a
    reference cell of width dx is sigma_min(F^sn) dx wide now, and the time
    step must shrink with it), and the bounding box of the new positions (min
    per axis, then max per axis).
    """
    S = t.scalar
    f64 = wp.float64
    vec, mat = t.vec, t.mat
    dim, Ks = t.dim, kernel.support
    node = make_node(t, kernel)
    strides = make_strides(t)
    Wm = weight_matrix_type(t, kernel)
    min_stretch2 = make_min_stretch2(t)

    @wp.kernel(module="unique")
    def g2p(
        # Model:
        body: wp.array(dtype=wp.int32),
        shape: wp.array(dtype=t.ivec),
        n_bodies: int,
        # Grid in:
        grid_v: wp.array(dtype=t.vec),
        # Stencil cache:
        cache_base: wp.array(dtype=wp.int32),
        cache_fx: wp.array(dtype=t.vec),
        cache_W: wp.array(dtype=Wm),
        # Step:
        dx: S,
        K: S,
        dt: S,
        epsilon: S,
        inside_lo: t.vec,
        inside_hi: t.vec,
        # State in/out:
        x: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        dJ: wp.array(dtype=S),
        status: wp.array(dtype=f64),
    ):
        p = wp.tid()
        b = body[p]
        st = strides(shape[b])
        flat = cache_base[p]
        fx = cache_fx[p]
        W = cache_W[p]
        vp = vec()
        B = mat()
        for a in range(Ks):
            for bb in range(Ks):
                for c in range(wp.static(Ks if dim == 3 else 1)):
                    w, r, i = node(a, bb, c, flat, fx, W, st, dx)
                    wv = w * grid_v[i]
                    vp += wv
                    B += wp.outer(wv, r)
        Cp = B * K
        xp = x[p] + dt * vp
        Fs = Fsn[p] + dt * Cp
        x[p] = xp
        v[p] = vp
        C[p] = Cp
        Fsn[p] = Fs
        dj = wp.abs(wp.determinant(Fs) - S(1.0))
        if wp.static(record_dJ):
            dJ[p] = dj
        if wp.static(count_marked):
            if dj >= epsilon:
                wp.atomic_add(status, STATUS_HEADER + b, f64(1.0))
            wp.atomic_max(status, STATUS_HEADER + n_bodies + b, f64(dj))
        if wp.static(track_compression):
            wp.atomic_min(status, STATUS_HEADER + 2 * n_bodies + b,
                          f64(wp.determinant(Fs) * wp.determinant(F0s[p])))
        # |L|^2 of the velocity gradient in current coordinates, L = C (F^sn)^-1;
        # for EMPM F^sn was I: L = C; otherwise bounded by |C|^2 / sigma_min^2
        rate2 = wp.ddot(Cp, Cp)
        if wp.static(lagrangian):
            s2 = min_stretch2(Fs)
            wp.atomic_min(status, STATUS_HEADER + 3 * n_bodies + b, f64(s2))
            rate2 = rate2 / wp.max(s2, S(1.0e-12))
        wp.atomic_max(status, STATUS_HEADER + 4 * n_bodies + b, f64(rate2))

        # stability monitor and bounding box of the new positions
        wp.atomic_max(status, STATUS_MAX_V2, f64(wp.dot(vp, vp)))
        if not (wp.isfinite(xp) and wp.isfinite(vp) and wp.isfinite(Fs)):
            wp.atomic_add(status, STATUS_NONFINITE, f64(1.0))
        else:
            outside = False
            box = STATUS_HEADER + STATUS_PER_BODY * n_bodies + b * dim
            for d in range(wp.static(dim)):
                if xp[d] < inside_lo[d] or xp[d] > inside_hi[d]:
                    outside = True
                wp.atomic_min(status, box + d, f64(xp[d]))
                wp.atomic_max(status, box + n_bodies * dim + d, f64(xp[d]))
            if outside:
                wp.atomic_add(status, STATUS_OUTSIDE, f64(1.0))

    return g2p
