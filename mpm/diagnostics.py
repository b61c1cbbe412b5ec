"""Physical scalars of a state, accumulated in float64.

Measured quantities (names from :func:`diagnostic_names`):
  mass            sum m_p [kg]
  momentum        sum m_p v_p [kg m/s]
  angular_momentum  APIC angular momentum about the centre of mass c [kg m^2/s]
                  sum m_p (x_p - c) x v_p + m_p axial(A_p),  A_p = C_p D_p F^sn_p^T,
                  D_p = K_p^-1 the kernel's second moment (dx^2/4 I for the
                  quadratic B-spline; Jiang et al. 2015): the angular momentum
                  of the nodal field sum_i q_i x m_i v_i each particle
                  rasterises; in 2D the scalar m (x0 v1 - x1 v0) + m (A10 - A01).
                  The kernel sums it about the origin (L_0) with sum m_p x_p;
                  :func:`about_center_of_mass` turns it into L_0 - c x P. About
                  the centre of mass it is conserved under uniform gravity too,
                  and a body spinning far from the origin is not measured
                  against its orbital angular momentum.
  kinetic_energy  sum 1/2 m_p |v_p|^2 [J]
  elastic_energy  sum V_p^0 psi(F_p) [J]; evaluated by the P2G pass, which
                  decomposes F for the stress anyway (see mpm.transfer)
  potential_energy  -sum m_p g . x_p [J] (zero at the origin)
  momentum_scale  sum m_p |v_p|: the scale of relative momentum drifts
  angular_momentum_scale  sum m_p (|x_p - c'| |v_p| + |A_p|): same for angular,
                  about a given point c' (the centre of mass of the previous
                  measurement)
  center_of_mass  sum m_p x_p / sum m_p [m]

Relative drifts (:func:`relative_drift`) are |Q(t) - Q(0)| / |Q(0)| when Q(0)
is not near zero, else against the quantity's scale.
"""

import functools

import numpy as np
import warp as wp

from .launch import warp_kernel
from .stepping.status import StepControl, StepStatus
from .types import Types


def diagnostic_names(dim: int) -> list[str]:
    axes = "xyz"[:dim]
    L = ["angular_momentum"] if dim == 2 else [f"angular_momentum_{a}" for a in axes]
    return (["mass"] + [f"momentum_{a}" for a in axes] + L
            + ["kinetic_energy", "elastic_energy", "potential_energy",
               "momentum_scale", "angular_momentum_scale"]
            + [f"center_of_mass_{a}" for a in axes])


NEAR_ZERO = 1.0e-3  # |Q(0)| below this fraction of Q's scale counts as zero


def relative_drift(first: np.ndarray, current: np.ndarray, scale: float):
    """|Q - Q0| / |Q0|, or / ``scale`` when |Q0| < NEAR_ZERO scale (a
    quantity that starts at zero, such as the momentum of two bodies
    colliding head-on). ``current`` is one value of Q (a float comes back)
    or a series of them along its first axis (an array comes back)."""
    diff = np.linalg.norm(np.asarray(current) - np.asarray(first), axis=-1)
    norm0 = float(np.linalg.norm(first))
    denom = norm0 if norm0 >= NEAR_ZERO * scale else scale
    out = diff / denom if denom > 0 else diff
    return float(out) if np.ndim(out) == 0 else out


def about_center_of_mass(d: np.ndarray, dim: int) -> np.ndarray:
    """Diagnostics as summed by the kernel (L about the origin, sum m x) to
    the named ones (L about the centre of mass, the centre of mass)."""
    names = diagnostic_names(dim)
    out = d.copy()
    M = d[0]
    iP, iL, ic = 1, 1 + dim, names.index("center_of_mass_x")
    c = d[ic:ic + dim] / M if M > 0 else np.zeros(dim)
    P = d[iP:iP + dim]
    if dim == 2:
        out[iL] = d[iL] - (c[0] * P[1] - c[1] * P[0])
    else:
        out[iL:iL + 3] = d[iL:iL + 3] - np.cross(c, P)
    out[ic:ic + dim] = c
    return out


@functools.cache
def make_measure(t: Types, per_particle_K: bool, batched: bool = False):
    """Everything but the elastic energy, for all particles at once, into the
    step's ``status.diagnostics`` (the angular momentum scale about
    ``control.center``); ``per_particle_K``: the kernel's moment D_p = K_p^-1
    varies per particle; ``batched``: nothing in a step the driver skips or
    whose configuration update waits for the host (mpm.stepping.driver)."""
    S = t.scalar
    vec = t.vec
    dim = t.dim
    f64 = wp.float64
    nL = 1 if dim == 2 else 3
    iL = 1 + dim  # first angular momentum slot
    iE = iL + nL  # kinetic energy slot
    iC = iE + 5  # sum m x

    @warp_kernel
    def measure(
        mass: wp.array(dtype=S),
        x: wp.array(dtype=t.vec),
        v: wp.array(dtype=t.vec),
        C: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        D: S,
        cache_K: wp.array(dtype=t.mat),
        gravity: t.vec,
        status: StepStatus,
        control: StepControl,
    ):
        if wp.static(batched):
            if control.skip[0] != f64(0.0) or control.host_update[0] != f64(0.0):
                return
        out = status.diagnostics
        center = t.vec()
        for d in range(wp.static(dim)):
            center[d] = S(control.center[d])
        p = wp.tid()
        m = mass[p]
        xp = x[p]
        vp = v[p]
        Cp = C[p]
        A = D * Cp * wp.transpose(Fsn[p])  # C D_p F^sn,T with D_p = D I
        if wp.static(per_particle_K):
            A = Cp * wp.inverse(cache_K[p]) * wp.transpose(Fsn[p])
        wp.atomic_add(out, 0, f64(m))
        for d in range(wp.static(dim)):
            wp.atomic_add(out, 1 + d, f64(m * vp[d]))
        if wp.static(dim == 2):
            L = m * (xp[0] * vp[1] - xp[1] * vp[0]) + m * (A[1, 0] - A[0, 1])
            wp.atomic_add(out, iL, f64(L))
        else:
            L3 = m * wp.cross(xp, vp) + m * vec(
                A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1])
            for d in range(3):
                wp.atomic_add(out, iL + d, f64(L3[d]))
        wp.atomic_add(out, iE, f64(S(0.5) * m * wp.dot(vp, vp)))
        wp.atomic_add(out, iE + 2, f64(-m * wp.dot(gravity, xp)))
        speed = wp.length(vp)
        wp.atomic_add(out, iE + 3, f64(m * speed))
        wp.atomic_add(out, iE + 4, f64(m * (wp.length(xp - center) * speed + wp.sqrt(wp.ddot(A, A)))))
        for d in range(wp.static(dim)):
            wp.atomic_add(out, iC + d, f64(m * xp[d]))

    return measure


def nearest_points(queries: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Index into ``points`` (n, d) of the nearest point to each query (m, d)
    [m]. Points are hashed into cells of width r and each query's 3^d cells
    searched: a point found within r is the nearest (any nearer one lies in
    those cells). Queries with none within r are searched again with r
    doubled, from ``radius`` until r spans the points, and the few left (far
    from every point) against all points."""
    queries, points = np.asarray(queries, np.float64), np.asarray(points, np.float64)
    best = np.full(len(queries), -1, np.int64)
    if not len(points):
        return best
    best_d2 = np.full(len(queries), np.inf)
    lo, extent = points.min(0), float(np.ptp(points, 0).max())
    todo, r = np.arange(len(queries)), max(radius, 1e-12)
    while len(todo) and r <= 4.0 * extent:
        _cell_search(queries[todo], points, lo, r, todo, best, best_d2)
        todo = todo[best_d2[todo] > r * r]
        r *= 2.0
    for chunk in np.array_split(todo, max(1, len(todo) * len(points) // 4_000_000)):  # far from all: every point
        if len(chunk):
            best[chunk] = ((queries[chunk, None, :] - points[None, :, :]) ** 2).sum(-1).argmin(1)
    return best


def _cell_search(q: np.ndarray, points: np.ndarray, lo: np.ndarray, r: float, rows: np.ndarray,
                 best: np.ndarray, best_d2: np.ndarray) -> None:
    """Update ``best``/``best_d2`` at ``rows`` (the queries ``q``) with the
    points in the 3^d cells of width ``r`` around each query."""
    dim = points.shape[1]
    cell = np.floor((points - lo) / r).astype(np.int64)
    shape = cell.max(0) + 3  # one empty cell around every side
    key = np.asarray(np.ravel_multi_index((cell + 1).T, shape))
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    qcell = np.floor((q - lo) / r).astype(np.int64) + 1
    for offset in np.ndindex(*(3,) * dim):
        c = qcell + np.asarray(offset) - 1
        ok = np.all((c >= 0) & (c < shape), axis=1)
        qk = np.where(ok, np.ravel_multi_index(np.clip(c, 0, shape - 1).T, shape), -1)
        start = np.searchsorted(sorted_key, qk, "left")
        count = np.where(ok, np.searchsorted(sorted_key, qk, "right") - start, 0)
        for j in range(int(count.max(initial=0))):
            has = np.flatnonzero(count > j)
            idx = order[start[has] + j]
            d2 = ((points[idx] - q[has]) ** 2).sum(1)
            better = d2 < best_d2[rows[has]]
            best[rows[has[better]]], best_d2[rows[has[better]]] = idx[better], d2[better]


def spilled_fraction(x: np.ndarray, bowl, x_bowl: np.ndarray | None = None, X_bowl: np.ndarray | None = None,
                     spacing: float = 0.0) -> float:
    """Fraction of the points ``x`` [m] (a fluid's particles) that lie below
    the rim plane of ``bowl`` (an mpm.scene.Bowl, its initial geometry) and
    outside its outer sphere: fluid that has left the bowl and run down its
    outside (A-ULMPM paper, Fig. 11: the leaking EMPM bowl).
    With the bowl's particles now (``x_bowl``) and at the start (``X_bowl``),
    each point is first carried into the bowl's initial shape by its nearest
    bowl particle b, X = X_b + (x - x_b), so that a bowl which has moved,
    settled or squashed is judged in its own frame (the bowl in the scene
    starts above the floor and flattens under the water: judged against its
    initial place, water resting on its lowered floor counted as outside).
    ``spacing`` [m]: the bowl particles' spacing, the nearest-search cell."""
    if len(x) == 0:
        return 0.0
    x = np.asarray(x, np.float64)
    if x_bowl is not None and X_bowl is not None and len(x_bowl):
        b = nearest_points(x, x_bowl, radius=max(2.0 * spacing, 1e-9))
        x = np.asarray(X_bowl, np.float64)[b] + (x - np.asarray(x_bowl, np.float64)[b])
    d = x - np.asarray(bowl.center)
    below = d[:, bowl.axis] < bowl.rim
    outside = np.linalg.norm(d, axis=1) > bowl.radius + bowl.thickness
    return float(np.mean(below & outside))


class Diagnostics:
    """The scalars of :func:`diagnostic_names` for one model's states, but the
    elastic energy (P2G evaluates it: mpm.solver.Solver.measure), summed on
    the device into the step buffer (mpm.stepping.status); the centre of the angular
    momentum scale is the last measurement's centre of mass, kept in
    ``control.center``."""

    def __init__(self, model, launch, buffer, per_particle_K: bool, batched: bool = False):
        t = model.types
        self.model, self.launch, self.buffer = model, launch, buffer
        self.kernel = make_measure(t, per_particle_K=per_particle_K, batched=batched)
        self.names = diagnostic_names(t.dim)
        self.D = t.scalar(model.kernel.moment * model.dx**2 if model.kernel.moment is not None else 0.0)
        self.gravity = t.vec(*model.gravity)
        self.sums = buffer.view("diagnostics")

    def prepare(self, x: np.ndarray) -> None:
        """The centre of mass of the initial positions ``x`` [m]."""
        mass = self.model.mass.numpy().astype(np.float64)
        self.buffer.set(center=mass @ np.asarray(x, np.float64) / mass.sum())

    def launch_measure(self, state) -> None:
        """Sum the diagnostics of ``state`` on the device (nothing read back)."""
        b = self.buffer
        self.launch(self.kernel, self.model.n_particles, [
            self.model.mass, state.x, state.v, state.C, state.Fsn, self.D, state.stencils.K, self.gravity,
            b.status, b.control])

    def measure(self, state) -> np.ndarray:
        """Every scalar of ``state`` (float64) with the elastic energy NaN."""
        self.sums.zero_()
        self.launch_measure(state)
        out = self.named(self.sums.numpy())
        self.buffer.set(center=out[self.names.index("center_of_mass_x"):][:self.model.dim])
        return out

    def named(self, sums: np.ndarray) -> np.ndarray:
        """The named scalars (NaN elastic energy) of the sums of a measurement."""
        out = about_center_of_mass(np.asarray(sums, np.float64), self.model.dim)
        out[self.names.index("elastic_energy")] = np.nan
        return out
