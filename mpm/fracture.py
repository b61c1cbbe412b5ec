"""A measure of numerical fracture: broken neighbour pairs.

Pairs (p, q) of particles of one body that were neighbours in the initial
sampling (closer than 1.5 particle spacings) are tracked. The continuum
predicts their current separation from their deformation gradients,
    x_q - x_p  ~  1/2 (F_p + F_q) (x_q^0 - x_p^0),
so genuine stretching, bending and rotation are explained by F. A pair is
*broken* when the actual separation departs from the prediction by more than
a cell width dx: the particles came apart without the material having
deformed that much - numerical fracture. Two figures follow: the fraction of
broken pairs (0: intact), and the number of fragments, the connected pieces
of each body's graph of intact pairs (1: whole). For fluids (F keeps only its
volume change) and plastic materials (F^sn F^0s is the elastic part F_E) they
count rearrangement and plastic flow, not fracture.
"""

import functools

import numpy as np
import warp as wp

from .launch import warp_kernel
from .types import Types


def fragments(n: int, p: np.ndarray, q: np.ndarray, intact: np.ndarray) -> np.ndarray:
    """Component label per particle of the graph on ``n`` nodes whose edges are
    the intact pairs (label propagation with pointer jumping)."""
    label = np.arange(n)
    p, q = p[intact], q[intact]
    while True:
        low = np.minimum(label[p], label[q])
        new = label.copy()
        np.minimum.at(new, p, low)
        np.minimum.at(new, q, low)
        new = new[new]  # pointer jumping
        if np.array_equal(new, label):
            return label
        label = new


def neighbour_pairs(x: np.ndarray, body: np.ndarray, radius: np.ndarray | float):
    """Index pairs (p < q) of particles of the same body closer than
    ``radius`` (per body or one value) [m], by binning into cells of that size."""
    radius = np.broadcast_to(np.asarray(radius, float), (body.max() + 1,))
    ps, qs = [], []
    for b in np.unique(body):
        idx = np.flatnonzero(body == b)
        r = radius[b]
        xb = x[idx]
        cell = np.floor((xb - xb.min(axis=0)) / r).astype(np.int64) + 1
        dims = cell.max(axis=0) + 2
        key = np.ravel_multi_index(cell.T, dims)
        order = np.argsort(key, kind="stable")
        skey = key[order]
        d = x.shape[1]
        for off in np.stack(np.meshgrid(*([[-1, 0, 1]] * d), indexing="ij"), -1).reshape(-1, d):
            nkey = np.ravel_multi_index((cell + off).T, dims)
            lo = np.searchsorted(skey, nkey, "left")
            hi = np.searchsorted(skey, nkey, "right")
            counts = hi - lo
            total = int(counts.sum())
            if total == 0:
                continue
            p = np.repeat(np.arange(len(xb)), counts)
            start = np.repeat(lo - (np.cumsum(counts) - counts), counts)
            q = order[np.arange(total) + start]
            keep = (q > p) & (np.sum((xb[q] - xb[p]) ** 2, axis=1) < r * r)
            ps.append(idx[p[keep]])
            qs.append(idx[q[keep]])
    if not ps:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    return np.concatenate(ps).astype(np.int32), np.concatenate(qs).astype(np.int32)


@functools.cache
def make_fracture(t: Types):
    S = t.scalar
    f64 = wp.float64

    @warp_kernel
    def broken_pairs(
        pair_p: wp.array(dtype=wp.int32),
        pair_q: wp.array(dtype=wp.int32),
        offset0: wp.array(dtype=t.vec),  # x_q^0 - x_p^0
        body: wp.array(dtype=wp.int32),
        x: wp.array(dtype=t.vec),
        F0s: wp.array(dtype=t.mat),
        Fsn: wp.array(dtype=t.mat),
        dx: S,
        out: wp.array(dtype=f64),  # broken pairs per body
        broken: wp.array(dtype=wp.uint8),  # per pair
    ):
        k = wp.tid()
        p = pair_p[k]
        q = pair_q[k]
        F = S(0.5) * (Fsn[p] * F0s[p] + Fsn[q] * F0s[q])
        gap = (x[q] - x[p]) - F * offset0[k]
        if not (wp.length(gap) <= dx):  # NaN counts as broken
            wp.atomic_add(out, body[p], f64(1.0))
            broken[k] = wp.uint8(1)
        else:
            broken[k] = wp.uint8(0)

    return broken_pairs


class FractureMeasure:
    """The measure for one model: the initial neighbour pairs (the positions
    given to :meth:`prepare`; the pairs are found at the first use, so that a
    run that never measures never pays for them), the fraction broken per
    body (:meth:`measure`), the pieces per body (:meth:`fragments`)."""

    def __init__(self, model):
        self.model = model
        self.kernel = make_fracture(model.types)
        self._x0 = None
        self._counts = np.zeros(len(model.scene.bodies), np.int64)

    def prepare(self, x: np.ndarray) -> None:
        """Take the positions ``x`` [m] whose pairs closer than 1.5 particle
        spacings are tracked."""
        self._x0 = np.array(x, copy=True)  # (on the CPU a Warp array's numpy() is a view of it)

    @property
    def pair_counts(self) -> np.ndarray:
        """The tracked pairs per body."""
        self._pairs()
        return self._counts

    def _pairs(self) -> None:
        """Find the pairs of the prepared positions, once."""
        if self._x0 is None:
            return
        x, self._x0 = self._x0, None
        m = self.model
        scene = m.scene
        n_bodies = len(scene.bodies)
        spacing = np.array([scene.particle_dx / (b.ppc or scene.ppc) ** (1.0 / m.dim) for b in scene.bodies])
        body = m.body.numpy()
        p, q = neighbour_pairs(x, body, 1.5 * spacing)
        self._counts = np.bincount(body[p], minlength=n_bodies)
        dtype = np.float32 if m.types.precision == "float32" else np.float64
        with wp.ScopedDevice(m.device):
            self._p = wp.array(p, dtype=wp.int32)
            self._q = wp.array(q, dtype=wp.int32)
            self._offset = wp.array((x[q] - x[p]).astype(dtype), dtype=m.types.vec)
            self._broken = wp.zeros(n_bodies, dtype=wp.float64)
            self._pair_broken = wp.zeros(len(p), dtype=wp.uint8)

    def measure(self, state) -> np.ndarray:
        """Fraction of the initial pairs broken in ``state``, per body."""
        m = self.model
        self._pairs()
        self._broken.zero_()
        if len(self._p):
            wp.launch(self.kernel, len(self._p), device=m.device, inputs=[
                self._p, self._q, self._offset, m.body, state.x, state.F0s, state.Fsn, m.types.scalar(m.dx),
                self._broken, self._pair_broken])
        return self._broken.numpy() / np.maximum(self._counts, 1)

    def fragments(self) -> np.ndarray:
        """Pieces per body (connected components of its intact pairs) at the
        last :meth:`measure`."""
        m = self.model
        self._pairs()
        intact = self._pair_broken.numpy() == 0
        label = fragments(m.n_particles, self._p.numpy(), self._q.numpy(), intact)
        body = m.body.numpy()
        return np.array([len(np.unique(label[body == b])) for b in range(len(m.scene.bodies))])
