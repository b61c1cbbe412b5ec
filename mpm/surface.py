"""Where a body meets a rigid surface: a collider's solid or a domain wall.

A surface acts on a grid node by volume, not by where the node sits. The
node's kernel overlaps the solid by the fraction

    alpha = A(-phi / dx),

phi the node's signed distance to the surface [m] (negative inside the
solid) and A the kernel's cumulative 1-D profile (the share of a node's
kernel on one side of a plane through its centre shifted by x cells,
:func:`cumulative_profile`), and the body by its own volume fraction
V = m_i / (rho dx^d) (rho its rest density). A node no more than half a
cell outside the solid (phi < dx / 2) is in contact (CONTACT) where the
body takes a share of it (V >= SHARE) and the two fill it together,

    alpha + V >= FILL.

For a flat face on a plane, smoothed by the same kernel, alpha + V = 1
when they touch, less across a gap and more where they overlap, wherever
the plane lies between the nodes: the surface acts where it is (the node
rule, a node inside the solid, phi < 0, acted one node row late when the
plane lay on a row and early just above it). FILL is below 1 because
particles sample a face unevenly: a face turned to the lattice is a
staircase of particles half a particle spacing deep, which fills some
nodes less than its plane would (at FILL = 1 a block on a 25 degree slope,
20 cells across the domain, touched at 6 of the 34 nodes under it, and
its weight sank its particles onto the slope: 0.9 carries it on the grid).
SHARE leaves out a node that only the far fringe of a kernel reaches; the
half cell keeps the nodes in contact to the row nearest the surface (a
second row further in the body carries the body's own weight and the
shear of its interior, and took normal and friction load unevenly). A
node more than half a cell inside the solid where the body has any mass
is DEEP: the walls act on it as on a node in contact (mpm.walls; the
fringe of the kernels reaching through the face would otherwise pull the
particles in), the colliders leave it alone (their friction acts on the
nodes in contact only; mpm.keep_out catches a particle the grid misses).

The rule then acts on the body's velocity at the surface point
s = q - phi n below the node, extrapolated by the body's velocity gradient
G at the node (summed in P2G, mpm.p2g): v_s = v + G (s - q); the change
the rule makes to v_s is the node's. A node above or below the surface
thus sticks or slides where the surface is, not where it sits (a disk
rolling on nodes a quarter cell below a collider's plane rolled with a
radius a quarter cell too large). Without G (frictionless colliders and
the walls) v_s = v. The rules themselves are mpm.colliders' (sticky,
slip, separate, and Coulomb friction) and mpm.walls'.
"""


import functools

import numpy as np
import warp as wp

from .kernels import Kernel
from .types import Types, make_types

SHARE = 0.1
"""the volume fraction a body takes at least of a node in contact"""
FILL = 0.9
"""the volume fraction they fill together at a node in contact (module docstring)"""
STEPS = 64
"""intervals of the cumulative profile's table (linear between them: within 3e-4 of A)"""
APART, CONTACT, DEEP = 0, 1, 2
"""a node's state against a solid (:func:`make_surface`'s ``touching``)"""
SAMPLES = 4096
"""samples of the kernel's 1-D weights per cell, integrated for the table"""


def reach(kernel: Kernel) -> float:
    """[cells] how far from a node its kernel reaches: the 1-D profile vanishes beyond."""
    return float(max(abs(kernel.offset - (kernel.support - 1)), kernel.offset + 1.0))


@functools.cache
def _profile_kernel(kernel: Kernel):
    t = make_types(2, "float64")
    S = t.scalar
    assert kernel.weights is not None, "kernel_problem() checks"
    weights = kernel.weights(t)
    support = kernel.support

    @wp.kernel(enable_backward=False, module="unique")
    def sample(offset: S, n: int, out: wp.array2d(dtype=S)):
        k = wp.tid()
        u = offset + (S(k) + S(0.5)) / S(n)
        w = weights(u)
        for s in range(wp.static(support)):
            out[k, s] = w[s]

    return sample


@functools.cache
def cumulative_profile(kernel: Kernel) -> np.ndarray:
    """The kernel's cumulative 1-D profile A at STEPS + 1 equally spaced
    points x in [-reach, reach] cells (:func:`reach`): A(x) is the integral
    of the node's 1-D weight N(d) over d < x (N(d) the weight of a node d
    cells from a point, from the kernel's ``weights`` at midpoints of
    SAMPLES intervals per cell); A(-reach) = 0, A(reach) = 1."""
    r = reach(kernel)
    sample = _profile_kernel(kernel)
    out = wp.zeros((SAMPLES, kernel.support), dtype=wp.float64, device="cpu")
    wp.launch(sample, SAMPLES, inputs=[wp.float64(kernel.offset), SAMPLES, out], device="cpu")
    w = out.numpy()  # w[k, s]: the weight of stencil node s for a point at t_k = offset + (k + 1/2) / SAMPLES
    t = kernel.offset + (np.arange(SAMPLES) + 0.5) / SAMPLES
    d = (t[:, None] - np.arange(kernel.support)[None, :]).ravel()  # the point's distance from node s
    order = np.argsort(d)
    d, n = d[order], w.ravel()[order]
    x = np.linspace(-r, r, STEPS + 1)
    # A(x) = sum of N over the samples below x, each standing for 1 / SAMPLES of a cell
    cum = np.concatenate([[0.0], np.cumsum(n)]) / SAMPLES
    A = cum[np.searchsorted(d, x, side="left")]
    return A / cum[-1]


@functools.cache
def make_profile_type(t: Types):
    """The struct type ``Profile``: the table of :func:`cumulative_profile`
    as the kernels read it."""

    @wp.struct
    class Profile:
        table: wp.array(dtype=t.scalar)  # A at STEPS + 1 points over [-reach, reach] cells
        reach: t.scalar  # [cells]
        inv_dx: t.scalar  # [1/m]

    return Profile


def pack_profile(t: Types, kernel: Kernel, dx: float, device):
    """The ``Profile`` of ``kernel`` on a grid of spacing ``dx`` [m]."""
    p = make_profile_type(t)()
    dtype = np.float32 if t.precision == "float32" else np.float64
    p.table = wp.array(cumulative_profile(kernel).astype(dtype), dtype=t.scalar, device=device)
    p.reach = t.scalar(reach(kernel))
    p.inv_dx = t.scalar(1.0 / dx)
    return p


@functools.cache
def make_surface(t: Types):
    """``solid_share(phi, profile) -> alpha``: the fraction of a node's
    kernel inside a solid whose surface is ``phi`` [m] away (negative
    inside); ``touching(phi, V, alpha, profile) -> state``: APART, CONTACT
    or DEEP (the module docstring); ``surface_velocity(v, G, phi, n) ->
    v_s``: the velocity extrapolated from the node to the surface point
    (s - q = -phi n)."""
    S = t.scalar
    Profile = make_profile_type(t)
    steps, last = float(STEPS), float(STEPS - 1)

    @wp.func
    def solid_share(phi: S, profile: Profile):
        x = -phi * profile.inv_dx
        if x <= -profile.reach:
            return S(0.0)
        if x >= profile.reach:
            return S(1.0)
        u = (x + profile.reach) / (S(2.0) * profile.reach) * S(steps)
        kf = wp.min(wp.floor(u), S(last))
        f = u - kf
        k = wp.int32(kf)  # pyright: ignore[reportArgumentType]
        return (S(1.0) - f) * profile.table[k] + f * profile.table[k + 1]

    @wp.func
    def touching(phi: S, V: S, alpha: S, profile: Profile):
        x = phi * profile.inv_dx
        if x < S(0.5) and V >= S(SHARE) and alpha + V >= S(FILL):
            return CONTACT
        if x <= S(-0.5) and V > S(0.0):
            return DEEP
        return APART

    @wp.func
    def surface_velocity(v: t.vec, G: t.mat, phi: S, n: t.vec):
        return v - phi * (G * n)

    return solid_share, touching, surface_velocity
