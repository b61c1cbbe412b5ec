"""The signed distance of a rigid collider at given points, evaluated by the
solver's own Warp function (mpm.collider_shapes.make_sdf), for the tests."""

import numpy as np
import warp as wp

from helpers import DEVICE
from mpm.collider_shapes import make_sdf, pack
from mpm.colliders import Collider
from mpm.launch import warp_kernel
from mpm.types import make_types


def _sdf_kernel(t, kinds):
    sdf = make_sdf(t, kinds)
    from mpm.collider_shapes import make_collider_data
    Data = make_collider_data(t)

    @warp_kernel
    def evaluate(c: wp.array(dtype=Data), q: wp.array(dtype=t.vec), phi: wp.array(dtype=t.scalar),
                 n: wp.array(dtype=t.vec)):
        i = wp.tid()
        p, nn = sdf(c[0], q[i])
        phi[i] = p
        n[i] = nn

    return evaluate


def evaluate(collider: Collider, q: np.ndarray):
    """(phi, n) of ``collider`` at the points ``q`` (float64)."""
    dim = q.shape[1]
    t = make_types(dim, "float64")
    meshes = {}
    if collider.type == "mesh":
        from mpm.collider_device import build_meshes
        meshes = build_meshes([collider], DEVICE)
    data = pack([collider], t, meshes, DEVICE)
    qa = wp.array(q, dtype=t.vec, device=DEVICE)
    phi = wp.zeros(len(q), dtype=t.scalar, device=DEVICE)
    n = wp.zeros(len(q), dtype=t.vec, device=DEVICE)
    wp.launch(_sdf_kernel(t, (collider.type,)), len(q), inputs=[data, qa, phi, n], device=DEVICE)
    return phi.numpy(), n.numpy()


def _place_kernel(t, kinds):
    from mpm.collider_motion import make_place
    from mpm.collider_shapes import make_collider_data
    place = make_place(t, kinds)
    Data = make_collider_data(t)

    @warp_kernel
    def evaluate(c: wp.array(dtype=Data), q: wp.array(dtype=t.vec), time: t.scalar, phi: wp.array(dtype=t.scalar),
                 n: wp.array(dtype=t.vec), u: wp.array(dtype=t.vec)):
        i = wp.tid()
        p, nn, uu = place(c[0], q[i], time)
        phi[i] = p
        n[i] = nn
        u[i] = uu

    return evaluate


def evaluate_at(collider: Collider, q: np.ndarray, time: float):
    """(phi, n, u) of ``collider`` where it is at ``time`` [s], at the points
    ``q`` (float64): the solver's mpm.collider_motion.make_place."""
    from mpm.collider_device import build_meshes, kinds_of
    t = make_types(q.shape[1], "float64")
    meshes = build_meshes([collider], DEVICE)
    data = pack([collider], t, meshes, DEVICE)
    qa = wp.array(q, dtype=t.vec, device=DEVICE)
    phi = wp.zeros(len(q), dtype=t.scalar, device=DEVICE)
    n, u = (wp.zeros(len(q), dtype=t.vec, device=DEVICE) for _ in range(2))
    wp.launch(_place_kernel(t, kinds_of([collider])), len(q), inputs=[data, qa, time, phi, n, u], device=DEVICE)
    return phi.numpy(), n.numpy(), u.numpy()
