"""A minimal, independent NumPy MLS-MPM (Hu et al. 2018, APIC transfers,
quadratic B-spline), written for the tests: plain loops, textbook formulas,
no code shared with the solver."""

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


def step(x, v, C, F, mass, vol, models, prms, dx, cells, gravity, walls, dt, wall_cells=3,
         body=None):
    """One MLS-MPM step; returns new (x, v, C, F). ``models``/``prms`` per particle.

    walls: per face (x_lo, x_hi, y_lo, ...) "sticky" | "slip" | "open".
    body: per-particle body index; each body is rasterised to a grid of its own
    (no contact between bodies).
    """
    if body is not None and len(np.unique(body)) > 1:
        out = [a.copy() for a in (x, v, C, F)]
        for b in np.unique(body):
            sel = body == b
            res = step(x[sel], v[sel], C[sel], F[sel], mass[sel], vol[sel],
                       [mo for mo, s in zip(models, sel) if s], [pr for pr, s in zip(prms, sel) if s],
                       dx, cells, gravity, walls, dt, wall_cells)
            for o, r in zip(out, res):
                o[sel] = r
        return tuple(out)
    n, d = x.shape
    shape = tuple(c + 1 for c in cells)
    gm = np.zeros(shape)
    gmv = np.zeros(shape + (d,))
    offsets = np.stack(np.meshgrid(*([np.arange(3)] * d), indexing="ij"), -1).reshape(-1, d)
    Dinv = 4.0 / dx**2
    for p in range(n):
        base = np.floor(x[p] / dx - 0.5).astype(int)
        fx = x[p] / dx - base
        w = quadratic_weights(fx)  # (3, d)
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
    for a in range(d):
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
