"""The explicit step's linear stability bound per kernel, for comparison
with the stability maps (``python -m pipelines.cfl_bound``; with a 2D
scene's overrides, ``python -m pipelines.cfl_bound scene=stability_ball_2d``,
the bound of that body's own particles, :func:`body_bound`).

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

import sys

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


def lame(nu: float) -> tuple[float, float, float]:
    """lambda, mu and the P-wave speed c of a material with E = 1, rho = 1."""
    lam, mu = nu / ((1 + nu) * (1 - 2 * nu)), 1 / (2 * (1 + nu))
    return lam, mu, float(np.sqrt(lam + 2 * mu))


def weights(fn, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The weights (n,) and their gradients with respect to the particle's
    position (n, d) of the 1-D kernel ``fn`` at offsets ``r`` (n, d) = node -
    particle, lattice units."""
    wd = np.array([[fn(x) for x in row] for row in r])  # (n, d, 2): w and dw/dr per axis
    w = np.prod(wd[..., 0], axis=1)
    grad = np.stack([-wd[:, a, 1] * np.prod(np.delete(wd[..., 0], a, axis=1), axis=1)
                     for a in range(r.shape[1])], -1)
    return w, grad


def particle_stiffness(g: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """A particle's linear-elastic stiffness per unit volume on its nodes,
    (n d, n d) in :func:`dofs` order: with dL/dv_i = e_a (x) g_i (``g``
    (n, d)), the stress rate lambda tr(eps) I + 2 mu eps of eps = sym L."""
    dim = g.shape[1]
    B = np.zeros((len(g) * dim, dim, dim))
    for t, gi in enumerate(g):
        for a in range(dim):
            B[t * dim + a, a] = gi
    eps = 0.5 * (B + B.transpose(0, 2, 1))
    sigma = lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(dim) + 2 * mu * eps
    return np.einsum("iab,jab->ij", B, sigma)


def dofs(nodes: np.ndarray, dim: int) -> np.ndarray:
    """The rows of the nodes' velocity components (node-major)."""
    return (np.asarray(nodes)[:, None] * dim + np.arange(dim)).ravel()


def bound(kernel: str, mls: bool = True, dim: int = 2, per_axis: int = 2, nu: float = 0.3, cells: int = 12) -> float:
    """k* = dt_crit c / dx of ``kernel`` (MLS weights, or the kernel's
    gradient), ``per_axis`` particles per cell and axis, Poisson's ratio
    ``nu``, on a periodic lattice of ``cells`` per axis."""
    grids = KERNELS[kernel]
    G, N = len(grids), cells
    lam, mu, c = lame(nu)
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
            w, grad = weights(fn, r)
            sl = slice(k * len(nodes), (k + 1) * len(nodes))
            w_all[sl], r_all[sl], g_all[sl] = w, r, grad
        mass += volume * w_all
        if mls:
            D = np.einsum("k,ka,kb->ab", w_all, r_all, r_all) / G
            g_all = (w_all[:, None] * r_all) @ np.linalg.inv(D).T
        idx = np.nonzero(np.any(g_all != 0, axis=1))[0]
        g = g_all[idx] / G  # dL / dv_i = e_a (x) g_i / G
        rows = dofs(idx, dim)
        K[np.ix_(rows, rows)] += volume * G * particle_stiffness(g, lam, mu)
    omega2 = np.max(np.real(np.linalg.eigvals(K / np.repeat(mass, dim)[:, None])))
    return float(2.0 / np.sqrt(omega2) * c)


def body_bound(x: np.ndarray, volume: np.ndarray, kernel: str, dx: float, nu: float = 0.3,
               walls: tuple = (), lo: float = 0.0, hi: float | np.ndarray = 1.0) -> tuple[float, float]:
    """The step bound of a 2D body's own particles ``x`` (n, 2) [m] with
    volumes ``volume`` [m^2] under the explicit MLS step (B-spline
    ``kernel``, grid spacing ``dx`` [m], nodes at integer multiples of dx):
    returns ``(k*, |lambda|_max at k = 1.2)``. Unlike :func:`bound` the body
    has a surface, whose nodes carry a fraction of a cell's mass, and the
    step includes the transfer: with g the grid velocities and f the
    nodes' elastic forces (linear elasticity, E = 1, rho = 1),
        g' = P (T g + dt M^-1 f),   f' = f - dt K g',
    T the APIC round trip (T_ij = sum_p m_p w_ip (w_jp + r_ip . g_jp) / m_i,
    C_p = sum_j v_j g_jp^T), K the stiffness, with g_ip the MLS weight
    D_p^-1 w_ip r_ip (the linear kernel: its gradient, as mpm's), P the slip
    walls (``walls``: axes whose nodes below ``lo`` or beyond ``hi`` [m],
    per axis or one for all, keep no normal velocity). k* = dt_crit c / dx where the spectral radius
    of the one-step map first exceeds 1 + 1e-6 (bisection on [0.1, 3]; the
    rigid and zero-stress modes sit at 1 to round-off)."""
    degree = {"linear": 1, "quadratic": 2, "cubic": 3}[kernel]
    w = bspline(degree)
    dim = 2
    lam, mu, c = lame(nu)
    node_of: dict = {}
    per_particle = []
    reach = (degree + 1) / 2
    for p in np.asarray(x, float) / dx:  # lattice units
        base = np.floor(p - reach).astype(int)
        ij = np.stack(np.meshgrid(*[np.arange(b, b + degree + 3) for b in base], indexing="ij"), -1).reshape(-1, dim)
        r = ij - p
        wt, grad = weights(w, r)
        keep = wt > 0
        ij, r, wt, grad = ij[keep], r[keep], wt[keep], grad[keep]
        ks = np.array([node_of.setdefault(tuple(n), len(node_of)) for n in ij])
        per_particle.append((ks, wt, r, grad))
    n = len(node_of)
    mass, T, K = np.zeros(n), np.zeros((n, n)), np.zeros((dim * n, dim * n))
    for (ks, wt, r, grad), V in zip(per_particle, volume / dx**dim):
        mass[ks] += V * wt
        # dL / dv_i = e_a (x) g_i: the MLS weight, or the linear kernel's gradient (mpm.kernels gradient_affine)
        g = grad if degree == 1 else (wt[:, None] * r) @ np.linalg.inv(np.einsum("k,ka,kb->ab", wt, r, r)).T
        T[np.ix_(ks, ks)] += V * wt[:, None] * (wt[None, :] + r @ g.T)  # C_p = sum_j v_j g_j^T
        rows = dofs(ks, dim)
        K[np.ix_(rows, rows)] += V * particle_stiffness(g, lam, mu)
    T2 = np.kron(T / mass[:, None], np.eye(dim))
    free = np.ones(dim * n)
    top = np.broadcast_to(np.asarray(hi, float), (dim,))
    for ij, k in node_of.items():
        for a in walls:
            if not lo / dx <= ij[a] <= top[a] / dx:
                free[k * dim + a] = 0.0
    A = free[:, None] * T2  # P T
    PMinv = np.diag(free / np.repeat(mass, dim))  # P M^-1
    keep_f = np.hstack([np.zeros_like(K), np.eye(len(K))])

    def radius(k: float) -> float:
        dt = k / c  # lattice units: dx = 1
        g_row = np.hstack([A, dt * PMinv])  # g' from (g, f)
        return float(np.abs(np.linalg.eigvals(np.vstack([g_row, keep_f - dt * K @ g_row]))).max())

    a, b = 0.1, 3.0
    for _ in range(24):  # the rigid and zero-stress modes sit at |lambda| = 1 (to ~1e-8: defective)
        mid = 0.5 * (a + b)
        a, b = (a, mid) if radius(mid) > 1.0 + 1e-6 else (mid, b)
    return a, radius(1.2)


def scene_bounds(overrides: list[str]) -> list[tuple[str, float, float]]:
    """:func:`body_bound` of the first body of the scene the config
    ``overrides`` compose (2D), for each B-spline: (kernel, k*, |lambda|
    at k = 1.2), its slip walls' bands fixing the normal velocity."""
    import mpm

    from .config.validate import compose_spec

    spec = compose_spec(overrides)
    scene = spec.scene
    if scene.dim != 2:
        raise ValueError(f"scene.dim: {scene.dim}; accepted: 2 (the body bound is 2D)")
    model, state = mpm.build(scene, spec.kernel, "float64", "cpu", spec.seed, samples=spec.take_samples())
    first = model.body.numpy() == 0
    x, volume = state.x.numpy()[first], model.volume.numpy().astype(float)[first]
    band = scene.wall_cells * model.dx
    walls = tuple(a for a in range(2) if "slip" in tuple(scene.walls)[2 * a:2 * a + 2])
    return [(k, *body_bound(x, volume, k, model.dx, walls=walls, lo=band, hi=np.asarray(scene.domain, float) - band))
            for k in ("linear", "quadratic", "cubic")]


def main(argv: list[str] | None = None) -> int:
    from .config.arguments import Parser

    parser = Parser(prog="python -m pipelines.cfl_bound", description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3))
    parser.add_argument("--per-axis", type=int, default=2, help="particles per cell and axis")
    parser.add_argument("--nu", type=float, default=0.3)
    parser.add_argument("overrides", nargs="*",
                        help="a 2D scene (scene=stability_ball_2d scene.resolution=32 ...): the bound of its first "
                             "body's particles with their surface and walls, for each B-spline (body_bound)")
    args = parser.parse_args(argv)
    if not 1 <= args.per_axis <= 8:
        parser.error(f"--per-axis: {args.per_axis}; accepted: an integer from 1 to 8")
    if not -1.0 < args.nu < 0.5:  # false for nan too
        parser.error(f"--nu: {args.nu}; accepted: -1 < nu < 0.5")
    if args.overrides:
        from .config.errors import describe
        from .run.warp_setup import init_warp

        init_warp()
        try:
            rows = scene_bounds(args.overrides)
        except Exception as e:
            message = describe(e) or (str(e) if isinstance(e, ValueError) else None)
            if message is None:
                raise
            print(f"error: {message}", file=sys.stderr)
            return 2
        print("| kernel | k* (this body, MLS) | abs(lambda) at k = 1.2 |")
        print("|---|---|---|")
        for kernel, k, lam in rows:
            print(f"| {kernel} | {k:.4f} | {lam:.4f} |")
        return 0
    print("| kernel | MLS | kernel gradient |")
    print("|---|---|---|")
    for kernel in KERNELS:
        print(f"| {kernel} | {bound(kernel, True, args.dim, args.per_axis, args.nu):.3f} | "
              f"{bound(kernel, False, args.dim, args.per_axis, args.nu):.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
