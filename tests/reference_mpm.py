"""A minimal, independent NumPy MLS-MPM (Hu et al. 2018, APIC transfers,
quadratic B-spline; the linear and cubic B-splines and the compact kernel
further down), written for the tests: plain loops, textbook formulas, no code
shared with the solver."""

import numpy as np


def polar_rotation(F):
    U, _, Vt = np.linalg.svd(F)
    R = U @ Vt
    if np.linalg.det(R) < 0:  # proper rotation
        U[:, -1] *= -1
        R = U @ Vt
    return R


def stress(model, F, L, prm):
    """First Piola-Kirchhoff stress P(F)."""
    d = F.shape[0]
    J = np.linalg.det(F)
    FinvT = np.linalg.inv(F).T
    if model == "fixed_corotated":
        mu, lam = prm
        return 2 * mu * (F - polar_rotation(F)) + lam * (J - 1) * J * FinvT
    if model == "neo_hookean":
        mu, lam = prm
        return mu * (F - FinvT) + lam * np.log(J) * FinvT
    if model == "fluid":
        K, gamma, visc = prm
        p = K * (J**-gamma - 1)
        sigma = -p * np.eye(d) + visc * (L + L.T)
        return J * sigma @ FinvT
    raise ValueError(model)


def quadratic_weights(fx):
    """Per-axis weights of the 3 stencil nodes, fx = x/dx - base in [0.5, 1.5)."""
    return np.array([0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2])


def quadratic_cdf(x):
    """The share of a quadratic B-spline node's weight below x cells from it:
    the integral of N(d) = 3/4 - d^2 (|d| < 1/2), (3/2 - |d|)^2 / 2 (|d| < 3/2)."""
    if x <= -1.5:
        return 0.0
    if x < -0.5:
        return (x + 1.5) ** 3 / 6.0
    if x < 0.5:
        return 0.5 + 0.75 * x - x**3 / 3.0
    if x < 1.5:
        return 1.0 - (1.5 - x) ** 3 / 6.0
    return 1.0


def wall_contacts(q, V, domain, walls, wall_cells, dx):
    """The surface rule (mpm.surface) for the walls of a node at q with the
    body volume fraction V: per closed face it touches, (axis, side, kind).
    A wall is the solid behind the plane wall_cells dx inside the domain's
    face; the node touches it where phi / dx < 1/2 (phi the node's distance
    from the plane), V >= 0.1 and V + A(-phi / dx) >= 0.9, or lies half a
    cell or more behind the plane with any mass."""
    out = []
    for a in range(len(q)):
        for side, kind in ((0, walls[2 * a]), (1, walls[2 * a + 1])):
            if kind == "open":
                continue
            phi = q[a] - wall_cells * dx if side == 0 else domain[a] - wall_cells * dx - q[a]
            if (phi / dx < 0.5 and V >= 0.1 and V + quadratic_cdf(-phi / dx) >= 0.9) or (phi / dx <= -0.5 and V > 0):
                out.append((a, side, kind))
    return out


def keep_out(x, v, domain, walls, wall_cells, dx):
    """A particle behind a closed wall's plane put back on it, its velocity
    into the wall removed (mpm.keep_out)."""
    x, v = x.copy(), v.copy()
    for a in range(len(x)):
        for side, kind in ((0, walls[2 * a]), (1, walls[2 * a + 1])):
            face = wall_cells * dx if side == 0 else domain[a] - wall_cells * dx
            if kind != "open" and ((side == 0 and x[a] < face) or (side == 1 and x[a] > face)):
                x[a] = face
                v[a] = max(v[a], 0.0) if side == 0 else min(v[a], 0.0)
    return x, v


def step(x, v, C, F, mass, vol, models, prms, dx, cells, gravity, walls, dt, wall_cells=3,
         body=None, elastic_state=None, rho=None):
    """One MLS-MPM step; returns new (x, v, C, F). ``models``/``prms`` per particle.

    walls: per face (x_lo, x_hi, y_lo, ...) "sticky" | "slip" | "open".
    body: per-particle body index; each body is rasterised to a grid of its own
    (no contact between bodies).
    elastic_state: ``(p, F_p) -> (F_E, P)`` replaces the stored F by its
    elastic part and gives its stress at the start of P2G (plasticity).
    rho: per particle its body's rest density [kg/m^d]: the walls act by the
    surface rule (:func:`wall_contacts`, :func:`keep_out`); None: on the
    first ``wall_cells`` node rows (the node rule).
    """
    if body is not None and len(np.unique(body)) > 1:
        out = [a.copy() for a in (x, v, C, F)]
        for b in np.unique(body):
            sel = body == b
            res = step(x[sel], v[sel], C[sel], F[sel], mass[sel], vol[sel],
                       [mo for mo, s in zip(models, sel) if s], [pr for pr, s in zip(prms, sel) if s],
                       dx, cells, gravity, walls, dt, wall_cells, rho=None if rho is None else rho[sel])
            for o, r in zip(out, res):
                o[sel] = r
        return tuple(out)
    n, d = x.shape
    F = F.copy()
    shape = tuple(c + 1 for c in cells)
    gm = np.zeros(shape)
    gmv = np.zeros(shape + (d,))
    offsets = np.stack(np.meshgrid(*([np.arange(3)] * d), indexing="ij"), -1).reshape(-1, d)
    Dinv = 4.0 / dx**2
    for p in range(n):
        base = np.floor(x[p] / dx - 0.5).astype(int)
        fx = x[p] / dx - base
        w = quadratic_weights(fx)  # (3, d)
        if elastic_state is not None:
            F[p], P = elastic_state(p, F[p])
        else:
            P = stress(models[p], F[p], C[p], prms[p])
        affine = mass[p] * C[p] - dt * vol[p] * Dinv * P @ F[p].T
        for off in offsets:
            weight = np.prod([w[off[a], a] for a in range(d)])
            dpos = (off - fx) * dx
            node = tuple(base + off)
            gm[node] += weight * mass[p]
            gmv[node] += weight * (mass[p] * v[p] + affine @ dpos)
    gv = np.zeros_like(gmv)
    has = gm > 0
    gv[has] = gmv[has] / gm[has][:, None] + dt * np.asarray(gravity)
    idx = np.indices(shape)
    if rho is not None:
        domain = np.asarray(cells) * dx
        for node in zip(*np.nonzero(has)):
            for a, side, kind in wall_contacts(np.array(node) * dx, gm[node] / (rho[0] * dx**d), domain, walls,
                                               wall_cells, dx):
                if kind == "sticky":
                    gv[node] = 0.0
                elif (side == 0 and gv[node][a] < 0) or (side == 1 and gv[node][a] > 0):
                    gv[node][a] = 0.0
    for a in range(d if rho is None else 0):
        for side, kind in ((0, walls[2 * a]), (1, walls[2 * a + 1])):
            near = idx[a] < wall_cells if side == 0 else idx[a] > cells[a] - wall_cells
            if kind == "sticky":
                gv[near] = 0.0
            elif kind == "slip":
                comp = gv[..., a]
                into = near & ((comp < 0) if side == 0 else (comp > 0))
                comp[into] = 0.0
    xn, vn, Cn, Fn = x.copy(), np.zeros_like(v), np.zeros_like(C), F.copy()
    for p in range(n):
        base = np.floor(x[p] / dx - 0.5).astype(int)
        fx = x[p] / dx - base
        w = quadratic_weights(fx)
        for off in offsets:
            weight = np.prod([w[off[a], a] for a in range(d)])
            dpos = (off - fx) * dx
            g = gv[tuple(base + off)]
            vn[p] += weight * g
            Cn[p] += Dinv * weight * np.outer(g, dpos)
        xn[p] = x[p] + dt * vn[p]
        if rho is not None:
            xn[p], vn[p] = keep_out(xn[p], vn[p], np.asarray(cells) * dx, walls, wall_cells, dx)
        Fn[p] = (np.eye(d) + dt * Cn[p]) @ F[p]
        if models[p] == "fluid":
            Fn[p] = np.linalg.det(Fn[p]) ** (1.0 / d) * np.eye(d)
    return xn, vn, Cn, Fn


def energy(model, F, prm):
    """Stored energy per unit rest volume psi(F)."""
    d = F.shape[0]
    J = np.linalg.det(F)
    if model == "fixed_corotated":
        mu, lam = prm
        D = F - polar_rotation(F)
        return mu * np.sum(D * D) + 0.5 * lam * (J - 1) ** 2
    if model == "neo_hookean":
        mu, lam = prm
        return 0.5 * mu * (np.sum(F * F) - d) - mu * np.log(J) + 0.5 * lam * np.log(J) ** 2
    if model == "fluid":
        K, gamma, _ = prm
        return K * (J ** (1 - gamma) / (gamma - 1) + J - gamma / (gamma - 1))
    raise ValueError(model)


def apply_walls(vel, q, domain, walls, band):
    """Wall conditions on one node velocity at its current position q."""
    d = len(vel)
    for a in range(d):
        for side, kind in ((0, walls[2 * a]), (1, walls[2 * a + 1])):
            near = q[a] < band if side == 0 else q[a] > domain[a] - band
            if not near or kind == "open":
                continue
            if kind == "sticky":
                vel = np.zeros(d)
            elif (side == 0 and vel[a] < 0) or (side == 1 and vel[a] > 0):
                vel[a] = 0.0
    return vel


def lagrangian_step(s, mass, vol, models, prms, body, dx, cells, domain, gravity, walls, dt,
                    wall_cells=3):
    """One step of the reference-configuration formulation (A-ULMPM paper,
    eq. 10-31), each body on a grid of its own in its reference configuration.

    ``s``: dict of arrays x, v, C, F0s, Fsn, X (updated in place). Walls act on
    nodes whose current position q_i = sum W m (x_p + Fsn r) / m_i is within
    (wall_cells - 1/2) dx of a face.
    """
    n, d = s["x"].shape
    offsets = np.stack(np.meshgrid(*([np.arange(3)] * d), indexing="ij"), -1).reshape(-1, d)
    K = 4.0 / dx**2
    band = (wall_cells - 0.5) * dx
    new_v = np.zeros_like(s["v"])
    new_C = np.zeros_like(s["C"])
    for b in np.unique(body):
        nodes = {}  # (node index tuple) -> [m, mv, mq]
        ps = np.flatnonzero(body == b)
        for p in ps:
            base = np.floor(s["X"][p] / dx - 0.5).astype(int)
            fx = s["X"][p] / dx - base
            w = quadratic_weights(fx)
            Fs, F0 = s["Fsn"][p], s["F0s"][p]
            L = s["C"][p] @ np.linalg.inv(Fs)
            P = stress(models[p], Fs @ F0, L, prms[p])
            affine = mass[p] * s["C"][p] - dt * vol[p] * K * P @ F0.T
            for off in offsets:
                weight = np.prod([w[off[a], a] for a in range(d)])
                r = (off - fx) * dx
                acc = nodes.setdefault(tuple(base + off), [0.0, np.zeros(d), np.zeros(d)])
                acc[0] += weight * mass[p]
                acc[1] += weight * (mass[p] * s["v"][p] + affine @ r)
                acc[2] += weight * mass[p] * (s["x"][p] + Fs @ r)
        vel = {}
        for key, (m, mv, mq) in nodes.items():
            if m <= 0:
                continue
            vel[key] = apply_walls(mv / m + dt * np.asarray(gravity), mq / m, domain, walls, band)
        for p in ps:
            base = np.floor(s["X"][p] / dx - 0.5).astype(int)
            fx = s["X"][p] / dx - base
            w = quadratic_weights(fx)
            for off in offsets:
                weight = np.prod([w[off[a], a] for a in range(d)])
                r = (off - fx) * dx
                g = vel.get(tuple(base + off), np.zeros(d))
                new_v[p] += weight * g
                new_C[p] += K * weight * np.outer(g, r)
    s["v"] = new_v
    s["C"] = new_C
    s["x"] = s["x"] + dt * new_v
    s["Fsn"] = s["Fsn"] + dt * new_C
    return s


def update_configuration(s, sel, models, affine="keep"):
    """X <- x, F0s <- project(Fsn F0s), Fsn <- I (and C <- C Fsn^-1 if
    ``affine == "transform"``) for the particles selected by ``sel``."""
    d = s["x"].shape[1]
    for p in np.flatnonzero(sel):
        F = s["Fsn"][p] @ s["F0s"][p]
        if models[p] == "fluid":
            F = np.linalg.det(F) ** (1.0 / d) * np.eye(d)
        if affine == "transform":
            s["C"][p] = s["C"][p] @ np.linalg.inv(s["Fsn"][p])
        s["X"][p] = s["x"][p]
        s["F0s"][p] = F
        s["Fsn"][p] = np.eye(d)
    return s


# ---------------------------------------------------------------------------
# B-spline kernels of order 1 (linear), 2 (quadratic) and 3 (cubic) from their
# textbook definitions (centred B-splines N(d) of the distance d in cells,
# support |d| < (order + 1) / 2), with the three transfers written from their
# papers: MLS (Hu et al. 2018), APIC (Jiang et al. 2015) and PIC. The moment
# matrix D_p = sum_i w_ip r r^T is computed and inverted per particle.

ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}


def bspline(order, d):
    """N(d) and dN/dd of the centred B-spline of the given order."""
    a, s = abs(d), np.sign(d)
    if order == 1:
        return (1.0 - a, -s) if a < 1.0 else (0.0, 0.0)
    if order == 2:
        if a < 0.5:
            return 0.75 - a * a, -2.0 * d
        return (0.5 * (1.5 - a) ** 2, -s * (1.5 - a)) if a < 1.5 else (0.0, 0.0)
    if order == 3:
        if a < 1.0:
            return 0.5 * a**3 - a * a + 2.0 / 3.0, s * (1.5 * a * a - 2.0 * a)
        return ((2.0 - a) ** 3 / 6.0, -s * 0.5 * (2.0 - a) ** 2) if a < 2.0 else (0.0, 0.0)
    raise ValueError(order)


def bspline_stencil(order, xp, dx):
    """[(node index tuple, w, grad w [1/m], r = x_i - x_p [m])] over the order + 1
    nodes per axis whose support can hold xp."""
    d = len(xp)
    u = xp / dx
    first = np.floor(u - 0.5 * (order + 1)).astype(int) + 1  # the lowest i with |u - i| < (order + 1) / 2
    out = []
    for off in np.ndindex(*([order + 1] * d)):
        node = first + np.array(off)
        N, dN = zip(*(bspline(order, u[a] - node[a]) for a in range(d)))
        w = np.prod(N)
        grad = np.array([dN[a] * np.prod([N[b] for b in range(d) if b != a]) for a in range(d)]) / dx
        out.append((tuple(node), w, grad, node * dx - xp))
    return out


def node_momentum(transfer, w, m, v, C, S, Kp, r, grad):
    """A particle's momentum contribution to one node (P2G): weight w, node
    offset r = x_i - x_p, weight gradient grad, S = dt V P F^T, Kp the
    moment's inverse (MLS); PIC carries no affine part."""
    if transfer == "mls":
        return w * (m * v + (m * C - S @ Kp) @ r)
    if transfer == "apic":
        return w * (m * v + m * C @ r) - S @ grad
    return w * m * v - S @ grad


def bspline_step(x, v, C, F, mass, vol, models, prms, kernel, dx, domain, gravity, walls, dt,
                 transfer="mls", wall_cells=3, body=None, flip=0.95):
    """One Eulerian step with a B-spline kernel (``kernel``: linear, quadratic,
    cubic) and a transfer (mls, apic, pic); returns new (x, v, C, F). Each
    body on a grid of its own (``body``: per-particle body index).

        mls:  m_i v_i += w (m v + (m C - dt V P F^T K_p) r),  C <- B K_p,  F <- (I + dt C) F
        apic: m_i v_i += w (m v + m C r) - dt V P F^T grad w,  C <- B K_p,
              F <- (I + dt sum v_i grad w^T) F
        pic:  m_i v_i += w m v - dt V P F^T grad w,  C <- 0,  F as apic
        flip: as pic, then v_p <- v_pic + flip (v_p - sum w p0_i / m_i),
              p0_i = sum w m v (the momentum transferred alone); x moves with v_pic
    with B = sum w v_i r^T and K_p = D_p^-1. Walls act on nodes within
    (wall_cells - 1/2) dx of a face (:func:`apply_walls`)."""
    if body is not None and len(np.unique(body)) > 1:
        out = [a.copy() for a in (x, v, C, F)]
        for b in np.unique(body):
            sel = body == b
            res = bspline_step(x[sel], v[sel], C[sel], F[sel], mass[sel], vol[sel],
                               [mo for mo, s in zip(models, sel) if s], [pr for pr, s in zip(prms, sel) if s],
                               kernel, dx, domain, gravity, walls, dt, transfer, wall_cells, flip=flip)
            for o, r in zip(out, res):
                o[sel] = r
        return tuple(out)
    n, d = x.shape
    order = ORDER[kernel]
    band = (wall_cells - 0.5) * dx
    stencils = [bspline_stencil(order, x[p], dx) for p in range(n)]
    Kp = [np.linalg.inv(sum(w * np.outer(r, r) for _, w, _, r in st)) for st in stencils]
    m_i, mv_i, p0_i = {}, {}, {}
    for p in range(n):
        S = dt * vol[p] * stress(models[p], F[p], C[p], prms[p]) @ F[p].T
        for key, w, grad, r in stencils[p]:
            m_i[key] = m_i.get(key, 0.0) + w * mass[p]
            mv_i[key] = mv_i.get(key, 0.0) + node_momentum(transfer, w, mass[p], v[p], C[p], S, Kp[p], r, grad)
            p0_i[key] = p0_i.get(key, 0.0) + w * mass[p] * v[p]
    v_i = {key: (apply_walls(mv_i[key] / m + dt * np.asarray(gravity), np.array(key) * dx, domain, walls, band)
                 if m > 0 else np.zeros(d)) for key, m in m_i.items()}
    xn, vn, Cn, Fn = x.copy(), np.zeros_like(v), np.zeros_like(C), F.copy()
    for p in range(n):
        B = np.zeros((d, d))
        G = np.zeros((d, d))
        transferred = np.zeros(d)
        for key, w, grad, r in stencils[p]:
            vn[p] += w * v_i[key]
            B += w * np.outer(v_i[key], r)
            G += np.outer(v_i[key], grad)
            if w > 0:
                transferred += w * p0_i[key] / m_i[key]
        Cn[p] = B @ Kp[p] if transfer not in ("pic", "flip") else 0.0
        grad_v = Cn[p] if transfer == "mls" else G
        xn[p] = x[p] + dt * vn[p]
        if transfer == "flip":
            vn[p] = vn[p] + flip * (v[p] - transferred)
        Fn[p] = (np.eye(d) + dt * grad_v) @ F[p]
        if models[p] == "fluid":
            Fn[p] = np.linalg.det(Fn[p]) ** (1.0 / d) * np.eye(d)
    return xn, vn, Cn, Fn


# ---------------------------------------------------------------------------
# The compact kernel of CK-MPM on two staggered grids, written independently:
# nodes of grid g at (i + o_g) dx, o = -1/4, +1/4, two nodes per axis with
# weights K(t), 1 - K(t), K(t) = 1 - t + sin(2 pi t) / (2 pi).

def compact_1d(u):
    """(nodes offsets, weights, d weights / d u) of the 2 stencil nodes, t = u - floor(u)."""
    base = np.floor(u)
    t = u - base
    K = 1 - t + np.sin(2 * np.pi * t) / (2 * np.pi)
    dK = np.cos(2 * np.pi * t) - 1
    return base, np.array([K, 1 - K]), np.array([dK, -dK])


def compact_step(x, v, C, F, mass, vol, models, prms, dx, domain, gravity, walls, dt,
                 transfer="mls", wall_cells=3):
    """One Eulerian step with the compact kernel; returns new (x, v, C, F).
    Every grid receives the full mass; G2P averages the two grids."""
    n, d = x.shape
    grids = (-0.25, 0.25)
    band = (wall_cells - 0.5) * dx
    corners = np.stack(np.meshgrid(*([np.arange(2)] * d), indexing="ij"), -1).reshape(-1, d)

    def stencil(p, o):
        """[(node key, weight, r = X_i - X_p, grad w)] on grid o."""
        out = []
        b, w, dw = zip(*(compact_1d(x[p, a] / dx - o) for a in range(d)))
        b = np.array(b)
        for c in corners:
            weight = np.prod([w[a][c[a]] for a in range(d)])
            grad = np.array([dw[a][c[a]] * np.prod([w[e][c[e]] for e in range(d) if e != a])
                             for a in range(d)]) / dx
            node = b + c
            r = (node + o) * dx - x[p]
            out.append(((o, tuple(node)), weight, r, grad))
        return out

    # per-particle moment matrix D_p = 1/2 sum_g sum_i w r r^T
    Kp = []
    for p in range(n):
        D = sum(w * np.outer(r, r) for o in grids for _, w, r, _ in stencil(p, o)) / len(grids)
        Kp.append(np.linalg.inv(D + 1e-6 * dx * dx * np.eye(d)))
    m_i, mv_i = {}, {}
    for p in range(n):
        P = stress(models[p], F[p], C[p], prms[p])
        S = dt * vol[p] * P @ F[p].T
        for o in grids:
            for key, w, r, grad in stencil(p, o):
                m_i[key] = m_i.get(key, 0.0) + w * mass[p]
                mv_i[key] = mv_i.get(key, 0.0) + node_momentum(transfer, w, mass[p], v[p], C[p], S, Kp[p], r, grad)
    v_i = {}
    for key, m in m_i.items():
        if m <= 0:  # a node the particles reach with zero weight
            v_i[key] = np.zeros(d)
            continue
        q = (np.array(key[1]) + key[0]) * dx  # Eulerian: the node's own position
        v_i[key] = apply_walls(mv_i[key] / m + dt * np.asarray(gravity), q, domain, walls, band)
    xn, vn, Cn, Fn = x.copy(), np.zeros_like(v), np.zeros_like(C), F.copy()
    for p in range(n):
        B = np.zeros((d, d))
        G = np.zeros((d, d))
        for o in grids:
            for key, w, r, grad in stencil(p, o):
                vn[p] += w * v_i[key] / len(grids)
                B += w * np.outer(v_i[key], r) / len(grids)
                G += np.outer(v_i[key], grad) / len(grids)
        Cn[p] = B @ Kp[p] if transfer != "pic" else 0.0
        grad_v = Cn[p] if transfer == "mls" else G
        xn[p] = x[p] + dt * vn[p]
        Fn[p] = (np.eye(d) + dt * grad_v) @ F[p]
        if models[p] == "fluid":
            Fn[p] = np.linalg.det(Fn[p]) ** (1.0 / d) * np.eye(d)
    return xn, vn, Cn, Fn


# ---------------------------------------------------------------------------
# Plastic models, written from the papers' formulas with NumPy (one particle
# at a time), for the classic MLS-MPM step with plasticity: the return
# mapping acts on the stored trial F_E at the start of P2G (as mpm99 does).

def _lame(E, nu):
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


def _svd(F):
    """F = U diag(s) V^T with proper rotations (sign on the last value)."""
    U, s, Vt = np.linalg.svd(F)
    if np.linalg.det(U) < 0:
        U[:, -1] *= -1
        s[-1] *= -1
    if np.linalg.det(Vt) < 0:
        Vt[-1] *= -1
        s[-1] *= -1
    return U, s, Vt.T


def plastic_return(mat, F, hist, dt):
    """(F_E, hist) after the return mapping of ``mat`` (a dataclass of
    mpm.materials) on the trial elastic deformation F; hist = [volumetric
    variable, equivalent plastic strain]."""
    d = F.shape[0]
    mu, lam = _lame(mat.E, mat.nu)
    U, s, V = _svd(F)
    h = np.array(hist, float)
    e = np.log(np.maximum(np.abs(s), 1e-6))
    if mat.name == "snow":
        se = np.clip(s, 1 - mat.theta_c, 1 + mat.theta_s)
        h[0] += np.sum(e) - np.sum(np.log(se))
    elif mat.name == "sand":
        q = h[1] / np.sqrt(2 / 3)
        phi = np.radians(mat.friction_angle + (mat.h1 * q - mat.h3) * np.exp(-mat.h2 * q))
        if d == 3:
            alpha = np.sqrt(2 / 3) * 2 * np.sin(phi) / (3 - np.sin(phi))
        else:
            alpha = np.sin(phi) / np.sqrt(2)
        apex = d * mat.cohesion / np.tan(phi) / (d * lam + 2 * mu)
        ec = e + h[0] / d
        tr = ec.sum()
        if tr >= apex:
            h[0] = tr - apex
            se = np.exp(np.full(d, apex / d))
        else:
            h[0] = 0.0
            dev = ec - tr / d
            dg = np.linalg.norm(dev) + (d * lam + 2 * mu) / (2 * mu) * (tr - apex) * alpha
            se = np.exp(ec - dg * dev / np.linalg.norm(dev) if dg > 0 else ec)
    elif mat.name == "von_mises":
        dev = e - e.mean()
        sy = mat.yield_stress + mat.hardening * h[1]
        delta = (2 * mu * np.linalg.norm(dev) - np.sqrt(2 / 3) * sy) / (2 * mu + 2 * mat.hardening / 3)
        se = np.exp(e - delta * dev / np.linalg.norm(dev) if delta > 0 else e)
    elif mat.name == "nacc":
        kappa = lam + 2 * mu / 3
        p0 = kappa * (1e-5 + np.sinh(mat.xi * max(-h[0], 0.0)))
        pmin = -mat.beta * p0
        a = np.abs(s)
        J = np.prod(a)
        b = a * a
        shat = mu * J ** (-2 / d) * (b - b.mean())
        p = -kappa / 2 * (J * J - 1)
        M2 = mat.slope() ** 2
        if p > p0 or p < pmin:
            pn = min(max(p, pmin), p0)
            JE = np.sqrt(max(1 - 2 * pn / kappa, 1e-4))
            se = np.full(d, JE ** (1 / d))
            if mat.hardening:
                h[0] += np.log(J / JE)
        else:
            yq = 1.5 * (1 + 2 * mat.beta)
            yp = M2 * (p - pmin) * (p - p0)
            s2 = shat @ shat
            if yq * s2 + yp <= 0 or s2 == 0:
                se = a
            else:
                c = np.sqrt(-yp / yq / s2)
                se = np.sqrt(np.maximum(c * shat * J ** (2 / d) / mu + b.mean(), 0.0))
                se = se * (J / np.prod(se)) ** (1 / d)
                if mat.hardening and p0 > 1e-12 * kappa:
                    pc = (1 - mat.beta) * p0 / 2
                    dvec = np.array([pc - p, -np.sqrt(1.5 * s2)])
                    dvec /= np.linalg.norm(dvec)
                    A = M2 * dvec[0] ** 2 + (1 + 2 * mat.beta) * dvec[1] ** 2
                    B = M2 * dvec[0] * (2 * pc - p0 - pmin)
                    C = M2 * (pc - pmin) * (pc - p0)
                    roots = np.roots([A, B, C]).real
                    ps = pc + dvec[0] * roots
                    px = ps[0] if (p - pc) * (ps[0] - pc) > 0 else ps[1]
                    Jx2 = abs(1 - 2 * px / kappa)
                    if Jx2 > 1e-4:
                        h[0] += np.log(J / np.sqrt(Jx2))
    elif mat.name == "viscoplastic":
        a = np.abs(s)
        J = np.prod(a)
        bb = J ** (-2 / d) * a * a
        dev = bb - bb.mean()
        s_tr = mu * np.linalg.norm(dev)
        k = np.sqrt(2) * mat.yield_stress
        se = a
        if s_tr > k and dt > 0:
            assert mat.flow_index == 1.0
            # |s_tr| - |s| = 2 mu_hat dt |D_p|, |s| = k + 2 K |D_p| (Bingham)
            mu_hat = mu * bb.mean()
            s_new = k + (s_tr - k) / (1 + mu_hat * dt / mat.viscosity)
            bn = bb.mean() + dev * s_new / s_tr
            se = np.sqrt(bn)
            se *= (J / np.prod(se)) ** (1 / d)
    else:
        raise ValueError(mat.name)
    h[1] += np.sqrt(2 / 3) * np.linalg.norm(e - np.log(se))
    return U @ np.diag(se) @ V.T, h


def plastic_stress(mat, FE, hist):
    """First Piola-Kirchhoff stress of the elastic deformation F_E."""
    d = FE.shape[0]
    mu, lam = _lame(mat.E, mat.nu)
    J = np.linalg.det(FE)
    FinvT = np.linalg.inv(FE).T
    if mat.name == "snow":
        harden = np.exp(mat.xi * (1 - np.exp(hist[0])))
        return harden * (2 * mu * (FE - polar_rotation(FE)) + lam * (J - 1) * J * FinvT)
    if mat.name in ("sand", "von_mises"):
        U, s, V = _svd(FE)
        eps = np.log(s)
        tau = U @ np.diag(2 * mu * eps + lam * eps.sum()) @ U.T  # Kirchhoff
        return tau @ FinvT
    if mat.name in ("nacc", "viscoplastic"):
        kappa = lam + 2 * mu / 3
        b = FE @ FE.T
        tau = mu * J ** (-2 / d) * (b - np.trace(b) / d * np.eye(d)) + kappa / 2 * (J * J - 1) * np.eye(d)
        return tau @ FinvT
    raise ValueError(mat.name)


def plastic_step(x, v, C, F, hist, mass, vol, mats, dx, cells, gravity, walls, dt, wall_cells=3):
    """One classic MLS-MPM step (quadratic B-spline, one grid for all
    particles) with plasticity, as mpm99 does it: the return mapping of the
    stored trial F_E at the start of P2G. Returns (x, v, C, F_trial, hist),
    F the trial elastic deformation that the next step returns."""
    hist = hist.copy()

    def elastic_state(p, Fp):
        FE, hist[p] = plastic_return(mats[p], Fp, hist[p], dt)
        return FE, plastic_stress(mats[p], FE, hist[p])

    x, v, C, F = step(x, v, C, F, mass, vol, [m.name for m in mats], [None] * len(x), dx, cells,
                      gravity, walls, dt, wall_cells, elastic_state=elastic_state)
    return x, v, C, F, hist


class ImplicitSystem:
    """Backward Euler on the grid of one body in its reference configuration
    (quadratic B-spline, MLS, no boundary condition acting), assembled
    densely: the unknowns are the velocities of the stencil nodes, in the
    order of ``nodes``. ``s``: dict x, v, C, F0s, Fsn, X of the step's start.

        R(v) = M (v - v*) + dt sum_p V_p P(F_p(v)) F0s_p^T g_ip,
        F_p(v) = (Fsn_p + dt sum_i v_i g_ip^T) F0s_p,   g_ip = K r_ip w_ip,
        A = dR/dv = M + dt^2 sum_p V_p dP/dF : (e_a w_jp^T) . w_ip,  w_ip = F0s^T g_ip,
    with dP/dF by centred differences of :func:`stress`."""

    def __init__(self, s, mass, vol, model, prm, dx, gravity, dt):
        n, d = s["x"].shape
        self.d, self.dt, self.model, self.prm, self.vol = d, dt, model, prm, vol
        self.F0s, self.Fsn = s["F0s"], s["Fsn"]
        offsets = np.stack(np.meshgrid(*([np.arange(3)] * d), indexing="ij"), -1).reshape(-1, d)
        K = 4.0 / dx**2
        index = {}
        self.stencil = []  # per particle: (node numbers, weights, gradients g_ip)
        for p in range(n):
            base = np.floor(s["X"][p] / dx - 0.5).astype(int)
            fx = s["X"][p] / dx - base
            w = quadratic_weights(fx)
            ids, ws, gs, rs = [], [], [], []
            for off in offsets:
                ids.append(index.setdefault(tuple(base + off), len(index)))
                ws.append(np.prod([w[off[a], a] for a in range(d)]))
                rs.append((off - fx) * dx)
                gs.append(K * ws[-1] * rs[-1])
            self.stencil.append((np.array(ids), np.array(ws), np.array(gs), np.array(rs)))
        self.nodes = list(index)
        N = len(index)
        m = np.zeros(N)
        mv = np.zeros((N, d))
        for p, (ids, ws, gs, rs) in enumerate(self.stencil):
            for i, w, r in zip(ids, ws, rs):
                m[i] += w * mass[p]
                mv[i] += w * mass[p] * (s["v"][p] + s["C"][p] @ r)
        self.m = m
        self.v_star = mv / m[:, None] + dt * np.asarray(gravity)

    def F(self, v):
        """Per particle F_p(v) for node velocities v (N, d)."""
        return np.array([(Fs + self.dt * sum(np.outer(v[i], g) for i, g in zip(ids, gs))) @ F0
                         for (ids, _, gs, _), Fs, F0 in zip(self.stencil, self.Fsn, self.F0s)])

    def residual(self, v):
        R = self.m[:, None] * (v - self.v_star)
        for p, ((ids, _, gs, _), F) in enumerate(zip(self.stencil, self.F(v))):
            S = self.vol[p] * stress(self.model, F, np.zeros((self.d, self.d)), self.prm) @ self.F0s[p].T
            for i, g in zip(ids, gs):
                R[i] += self.dt * S @ g
        return R

    def matrix(self, v, h=1e-6):
        d = self.d
        A = np.diag(np.repeat(self.m, d))
        for p, ((ids, _, gs, _), F) in enumerate(zip(self.stencil, self.F(v))):
            T = np.zeros((d, d, d, d))  # dP_ac / dF_be
            for b in range(d):
                for e in range(d):
                    E = np.zeros((d, d))
                    E[b, e] = h
                    T[:, :, b, e] = (stress(self.model, F + E, 0 * E, self.prm)
                                     - stress(self.model, F - E, 0 * E, self.prm)) / (2 * h)
            W = np.array([self.F0s[p].T @ g for g in gs])  # w_ip
            block = self.dt**2 * self.vol[p] * np.einsum("acbe,ic,je->iajb", T, W, W)
            rows = (ids[:, None] * d + np.arange(d)).ravel()
            A[np.ix_(rows, rows)] += block.reshape(len(ids) * d, len(ids) * d)
        return A

    def particle_velocities(self, v):
        return np.array([ws @ v[ids] for ids, ws, _, _ in self.stencil])
