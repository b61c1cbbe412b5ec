"""The colliders' drawable surfaces (pipelines.recording.surfaces) lie on
their signed distance's zero level set."""

import numpy as np
import pytest

from collider_sdf import evaluate
from mpm.colliders import Collider
from mpm.meshes import MeshShape


DRAWN = [Collider("half_space", point=(0.5, 0.3, 0.5), normal=(0.2, 1.0, 0.1)),
         Collider("wedge", point=(0.5, 0.4, 0.5), normals=((-1.0, 1.0, 0.0), (1.0, 1.0, 0.0))),
         Collider("box", center=(0.5, 0.5, 0.5), half_size=(0.1, 0.2, 0.3)),
         Collider("sphere", center=(0.5, 0.5, 0.5), radius=0.4, inside=True),
         Collider("cylinder", center=(0.5, 0.5, 0.5), radius=0.2, half_height=0.3, axis=(1.0, 1.0, 0.0)),
         Collider("cup", center=(0.5, 0.1, 0.5), radius=0.2, depth=0.3, thickness=0.05),
         Collider("bowl", center=(0.5, 0.5, 0.5), radius=0.3, thickness=0.05, rim=0.1),
         Collider("mesh", mesh=MeshShape("warp:bunny", (0.5, 0.5, 0.5), 0.4))]


@pytest.mark.parametrize("collider", DRAWN, ids=lambda c: c.type)
def test_drawn_surfaces_lie_on_the_collider(collider):
    """Every vertex of the recording's surface is on the zero level set of
    the collider's signed distance; in 2D the unbounded shapes are drawn as
    the outline of their solid within the domain (on or inside the solid)."""
    from pipelines.recording.surfaces import outline_2d, surface_3d

    v, f = surface_3d(collider, np.zeros(3), np.ones(3))
    assert len(v) >= 4 and len(f) >= 2 and f.max() < len(v)
    phi, _ = evaluate(collider, v)
    assert np.abs(phi).max() < 1e-6
    if collider.type != "mesh":
        flat = Collider(**{**collider.__dict__, **_to_2d(collider)})
        for line in outline_2d(flat, np.zeros(2), np.ones(2)):
            phi2, _ = evaluate(flat, line)
            if collider.type in ("half_space", "wedge"):
                assert phi2.max() < 1e-9 and np.sum(np.abs(phi2) < 1e-9) >= 2
            else:
                assert np.abs(phi2).max() < 1e-9


def _to_2d(c: Collider) -> dict:
    """The same collider in the x-y plane."""
    out = {}
    for k in ("point", "center", "half_size", "normal"):
        if getattr(c, k) is not None:
            out[k] = tuple(getattr(c, k))[:2]
    if c.normals is not None:
        out["normals"] = tuple(tuple(n)[:2] for n in c.normals)
    if not isinstance(c.axis, int):
        out["axis"] = tuple(c.axis)[:2]
    return out
