"""The explicit step's linear stability bound per kernel, for comparison
with the stability maps (``python -m pipelines.cfl_bound``).

Symplectic Euler on the grid, M dv/dt = -K u, is stable for
dt <= 2 / omega_max, omega_max^2 the largest eigenvalue of M^-1 K. Here M
is the lumped node mass and K the linear-elastic stiffness the transfers
build: a particle's velocity gradient L_p = 1/G sum_i v_i g_ip^T, its
stress rate lambda tr(eps) I + 2 mu eps (eps = sym L_p), and the force
-V_p sigma_p g_ip on every node (each of the kernel's G grids receives the
full mass and force), with g_ip the MLS weight K_p r_ip w_ip or the
kernel's gradient. On a periodic lattice filled with n x n particles per
cell (a body's interior; no surface, no transfer dissipation) the bound is

    k* = dt_crit c / dx,   c = sqrt((lambda + 2 mu) / rho)

in the units of the maps' step multiple. Kernels in lattice units
(dx = 1): the B-splines of degree 1-3 and the CK-MPM compact kernel
K(x) = 1 - |x| + sin(2 pi |x|) / (2 pi) on two grids shifted by -1/4, +1/4.
"""

from __future__ import annotations


import numpy as np


def bspline(degree: int):
    """``w(r) -> (w, dw/dr)`` of the B-spline of ``degree`` at r = (x_i - x_p) / dx."""
    def w(r: float):
        a = abs(r)
        s = np.sign(r)
        if degree == 1:
            return (1 - a, -s) if a < 1 else (0.0, 0.0)
        if degree == 2:
            if a < 0.5:
                return 0.75 - a * a, -2 * r
            return (0.5 * (1.5 - a) ** 2, -(1.5 - a) * s) if a < 1.5 else (0.0, 0.0)
        if degree == 3:
            if a < 1:
                return 0.5 * a**3 - a * a + 2 / 3, (1.5 * a * a - 2 * a) * s
            return ((2 - a) ** 3 / 6, -0.5 * (2 - a) ** 2 * s) if a < 2 else (0.0, 0.0)
        raise ValueError(degree)
    return w


def compact(r: float):
    a = abs(r)
    if a >= 1:
        return 0.0, 0.0
    return 1 - a + np.sin(2 * np.pi * a) / (2 * np.pi), (np.cos(2 * np.pi * a) - 1) * np.sign(r)


KERNELS = {"linear": [(0.0, bspline(1))], "quadratic": [(0.0, bspline(2))], "cubic": [(0.0, bspline(3))],
           "compact": [(-0.25, compact), (0.25, compact)]}


def bound(kernel: str, mls: bool = True, dim: int = 2, per_axis: int = 2, nu: float = 0.3, cells: int = 12) -> float:
    """k* = dt_crit c / dx of ``kernel`` (MLS weights, or the kernel's
    gradient), ``per_axis`` particles per cell and axis, Poisson's ratio
    ``nu``, on a periodic lattice of ``cells`` per axis."""
    grids = KERNELS[kernel]
    G, N = len(grids), cells
    lam, mu = nu / ((1 + nu) * (1 - 2 * nu)), 1 / (2 * (1 + nu))  # E = 1, rho = 1
    c = np.sqrt(lam + 2 * mu)
    sub = (np.arange(per_axis) + 0.5) / per_axis
    axes = np.meshgrid(*([np.arange(N)] * dim), *([sub] * dim), indexing="ij")
    points = np.stack([axes[a] + axes[dim + a] for a in range(dim)], -1).reshape(-1, dim)
    nodes = np.stack(np.meshgrid(*([np.arange(N)] * dim), indexing="ij"), -1).reshape(-1, dim)
    n_nodes = G * len(nodes)
    volume = 1.0 / per_axis**dim
    mass = np.zeros(n_nodes)
    K = np.zeros((dim * n_nodes, dim * n_nodes))
    for p in points:
        w_all, r_all, g_all = np.zeros(n_nodes), np.zeros((n_nodes, dim)), np.zeros((n_nodes, dim))
        for k, (shift, fn) in enumerate(grids):
            r = (nodes + shift - p + N / 2) % N - N / 2  # periodic
            wd = np.array([[fn(x) for x in row] for row in r])  # (nodes, dim, 2)
            w = np.prod(wd[..., 0], axis=1)
            grad = np.stack([-wd[:, a, 1] * np.prod(np.delete(wd[..., 0], a, axis=1), axis=1)
                             for a in range(dim)], -1)
            sl = slice(k * len(nodes), (k + 1) * len(nodes))
            w_all[sl], r_all[sl], g_all[sl] = w, r, grad
        mass += volume * w_all
        if mls:
            D = np.einsum("k,ka,kb->ab", w_all, r_all, r_all) / G
            g_all = (w_all[:, None] * r_all) @ np.linalg.inv(D).T
        idx = np.nonzero(np.any(g_all != 0, axis=1))[0]
        g = g_all[idx] / G  # dL / dv_i = e_a (x) g_i / G
        B = np.zeros((len(idx) * dim, dim, dim))
        for t, gi in enumerate(g):
            for a in range(dim):
                B[t * dim + a, a] = gi
        eps = 0.5 * (B + B.transpose(0, 2, 1))
        sigma = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(dim) + 2 * mu * eps
        rows = (idx[:, None] * dim + np.arange(dim)).ravel()
        K[np.ix_(rows, rows)] += volume * G * np.einsum("iab,jab->ij", B, sigma)
    omega2 = np.max(np.real(np.linalg.eigvals(K / np.repeat(mass, dim)[:, None])))
    return float(2.0 / np.sqrt(omega2) * c)


def main(argv: list[str] | None = None) -> int:
    from .config.arguments import Parser

    parser = Parser(prog="python -m pipelines.cfl_bound", description=__doc__.split("\n")[0])
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3))
    parser.add_argument("--per-axis", type=int, default=2, help="particles per cell and axis")
    parser.add_argument("--nu", type=float, default=0.3)
    args = parser.parse_args(argv)
    if not 1 <= args.per_axis <= 8:
        parser.error(f"--per-axis: {args.per_axis}; accepted: an integer from 1 to 8")
    if not -1.0 < args.nu < 0.5:  # false for nan too
        parser.error(f"--nu: {args.nu}; accepted: -1 < nu < 0.5")
    print("| kernel | MLS | kernel gradient |")
    print("|---|---|---|")
    for kernel in KERNELS:
        print(f"| {kernel} | {bound(kernel, True, args.dim, args.per_axis, args.nu):.3f} | "
              f"{bound(kernel, False, args.dim, args.per_axis, args.nu):.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
