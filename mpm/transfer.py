"""Particle-to-grid and grid-to-particle transfers (MLS-MPM with APIC).

Notation (REFERENCE.md §1, A-ULMPM paper eq. 10-33): ``X_p`` reference
particle positions, ``X_i`` reference node positions, ``W_ip`` kernel weights
in the reference configuration, ``K_p = I / (moment dx^2)`` the MLS moment
inverse, ``F^{0s}`` the deformation gradient at the last configuration
update, ``F^{sn}`` the deformation since then (identity at the start of an
Eulerian step), ``F^{0n} = F^{sn} F^{0s}``.

P2G (eq. 10, 11, 20, 23, fused as in MLS-MPM):
    m_i      = sum_p W_ip m_p
    m_i v_i  = sum_p W_ip [m_p v_p + (m_p C_p - dt V_p^0 P(F^{0n}) F^{0s,T} K_p)(X_i - X_p)]
so that after division by m_i the nodal velocity already holds the internal
force impulse dt f_i / m_i. The stored energy sum_p V_p^0 psi(F^{0n}_p) of the
state the step starts from is accumulated on the way (the decomposition of F
is shared with the stress).

G2P (eq. 28, 31, APIC form):
    v_p = sum_i W_ip v_i,   C_p = sum_i W_ip v_i (X_i - X_p)^T K_p,
    x_p += dt v_p,          F^{sn} += dt C_p.
For the Eulerian scheme F^{sn} = I + dt C_p and the configuration update
(X <- x, F^{0s} <- F^{sn} F^{0s}, F^{sn} <- I) is fused into G2P.
"""

import functools

import warp as wp

from .kernels import Kernel
from .stencil import make_locate, make_node
from .types import Types


@functools.cache
def make_p2g(t: Types, kernel: Kernel, material):
    """P2G for the particles of one material model (``material`` is its class)."""
    f64 = wp.float64
    S = t.scalar
    dim, Ks = t.dim, kernel.support
    locate = make_locate(t, kernel)
    node = make_node(t, kernel)
    stress_energy = material.stress_energy(t)

    @wp.kernel(module="unique")
    def p2g(
        # Model:
        mass: wp.array(dtype=S),
        volume: wp.array(dtype=S),
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        # State in:
        X: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        # Grid geometry and step:
        inv_dx: S,
        cells: t.ivec,
        strides: t.ivec,
        K: S,
        dt: S,
        start: int,
        # Grid out:
        grid_m: wp.array(dtype=S),
        grid_mv: wp.array(dtype=t.vec),
        # Diagnostics out:
        energy: wp.array(dtype=f64),
    ):
        p = wp.tid() + start
        flat, fx, W = locate(X[p], inv_dx, cells, strides)
        m = mass[p]
        F = F0s[p]
        Cp = C[p]
        # Eulerian: F^{sn} = I at the start of the step, so F^{0n} = F^{0s}
        # and the velocity gradient in current coordinates is C_p.
        P, psi = stress_energy(F, Cp, body_params[body[p]])
        wp.atomic_add(energy, 0, f64(volume[p] * psi))
        affine = m * Cp - (dt * volume[p] * K) * P * wp.transpose(F)
        mv = m * v[p]
        dx = S(1.0) / inv_dx
        for a in range(Ks):
            for b in range(Ks):
                for c in range(wp.static(Ks if dim == 3 else 1)):
                    w, r, i = node(a, b, c, flat, fx, W, strides, dx)
                    wp.atomic_add(grid_m, i, w * m)
                    wp.atomic_add(grid_mv, i, w * (mv + affine * r))

    return p2g


@functools.cache
def make_g2p(t: Types, kernel: Kernel, project, record_dJ: bool):
    """G2P with the Eulerian configuration update fused in.

    ``project``: the material's projection factory or None; ``record_dJ``:
    write ``dJ_p = |det(I + dt C_p) - 1|`` (paper eq. 33 for s = n).
    ``monitor`` accumulates [max |v_p|^2, non-finite count, outside count].
    """
    S = t.scalar
    vec, mat = t.vec, t.mat
    dim, Ks = t.dim, kernel.support
    locate = make_locate(t, kernel)
    node = make_node(t, kernel)
    proj = project(t) if project is not None else None

    @wp.kernel(module="unique")
    def g2p(
        # Model:
        body: wp.array(dtype=wp.int32),
        body_params: wp.array(dtype=t.params),
        # Grid in:
        grid_v: wp.array(dtype=t.vec),
        inv_dx: S,
        cells: t.ivec,
        strides: t.ivec,
        K: S,
        dt: S,
        start: int,
        inside_lo: t.vec,
        inside_hi: t.vec,
        # State in/out:
        x: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        F0s: wp.array(dtype=t.mat),
        dJ: wp.array(dtype=S),
        monitor: wp.array(dtype=wp.float64),
    ):
        p = wp.tid() + start
        xp = x[p]
        flat, fx, W = locate(xp, inv_dx, cells, strides)
        dx = S(1.0) / inv_dx
        vp = vec()
        B = mat()
        for a in range(Ks):
            for b in range(Ks):
                for c in range(wp.static(Ks if dim == 3 else 1)):
                    w, r, i = node(a, b, c, flat, fx, W, strides, dx)
                    wv = w * grid_v[i]
                    vp += wv
                    B += wp.outer(wv, r)
        Cp = B * K
        xp = xp + dt * vp
        Fsn = wp.identity(n=dim, dtype=S) + dt * Cp
        F = Fsn * F0s[p]
        if wp.static(proj is not None):
            F = proj(F, body_params[body[p]])
        x[p] = xp
        v[p] = vp
        C[p] = Cp
        F0s[p] = F
        if wp.static(record_dJ):
            dJ[p] = wp.abs(wp.determinant(Fsn) - S(1.0))

        # stability monitor
        wp.atomic_max(monitor, 0, wp.float64(wp.dot(vp, vp)))
        if not (wp.isfinite(xp) and wp.isfinite(vp) and wp.isfinite(F)):
            wp.atomic_add(monitor, 1, wp.float64(1.0))
        else:
            outside = False
            for d in range(wp.static(dim)):
                if xp[d] < inside_lo[d] or xp[d] > inside_hi[d]:
                    outside = True
            if outside:
                wp.atomic_add(monitor, 2, wp.float64(1.0))

    return g2p
