"""Contact between bodies (mpm.contact) against a NumPy transcription of its
rule, evaluated bin by bin over the whole global lattice: the solver's
passes run over the body nodes only and must give every node the same
correction."""

import dataclasses

import numpy as np
import pytest

import mpm
from mpm.contact import passes as contact
from test_conservation import colliding_scene

DEVICE = "cpu"


def outward(M, b, g, present, cells, strides, rest_mass=None, normal="difference", rank=None):
    """Body b's unit outward normal at global node g (mpm.contact), grad M_c
    by central differences, one-sided at the lattice's edge: "difference",
    normalize(grad(M_others - M_b)); "max_gradient", +-grad M_c of the body c
    present with the largest |grad M_c| / rest_mass_c (the first of equals),
    pointing out of b (into c, or against grad M_b when c is b); "stiffer",
    the same among the bodies present of the highest ``rank``."""
    idx = np.unravel_index(g, tuple(c + 1 for c in cells))
    grad = np.zeros((M.shape[0], len(cells)))
    for d in range(len(cells)):
        minus = g if idx[d] == 0 else g - strides[d]
        plus = g if idx[d] == cells[d] else g + strides[d]
        grad[:, d] = M[:, plus] - M[:, minus]
    if normal == "difference":
        n = grad[present].sum(0) - 2.0 * grad[b]
    else:
        if normal == "stiffer":
            present = present[rank[present] == rank[present].max()]
        sizes = np.linalg.norm(grad[present], axis=1) / rest_mass[present]
        c = present[int(np.argmax(sizes))]
        n = -grad[c] if c == b else grad[c]
    length = np.linalg.norm(n)
    return n / length if length > 0 else n


def lattice_weights(q, inv_dx, cells, strides, gather):
    """Per node, its lattice nodes and weights: the nearest one with weight 1
    (wp.round: halves away from 0), or (``gather``) the 2^d corners of its
    cell with the linear weights prod_d (1 - |q_d / dx - g_d|), indices
    clamped to the lattice."""
    s = q * inv_dx
    if not gather:
        idx = np.clip(np.floor(s + 0.5).astype(np.int64), 0, cells)
        return (idx @ np.asarray(strides))[:, None], np.ones((len(q), 1))
    base = np.floor(s).astype(np.int64)
    frac = s - base
    flats, weights = [], []
    for k in range(2 ** q.shape[1]):
        bits = np.array([(k >> d) & 1 for d in range(q.shape[1])])
        flats.append(np.clip(base + bits, 0, cells) @ np.asarray(strides))
        weights.append(np.where(bits == 1, frac, 1.0 - frac).prod(axis=1))
    return np.stack(flats, 1), np.stack(weights, 1)


def reference_contact(m, v, q, body, n_grids, inv_dx, cells, strides, rest_mass, fill, gather=False, mu=None,
                      normal="difference", share=0.0, rank=None):
    """The corrected node velocities, the nodes taking a correction from a
    lattice node in contact and the number of lattice nodes in contact with
    three or more bodies: M_bg = sum w_ig m_i / G, P_bg = sum w_ig m_i v_i /
    G over each node's lattice nodes and weights (lattice_weights); where two
    or more bodies fill a node (sum M_bg / (rho_b dx^d) >= fill), dV_bg =
    -((v_b - v_cm) . n_b) n_b for a body approaching (> 0), less the
    mass-weighted mean correction with three or more; node i takes
    sum_g w_ig dV_bg. ``mu`` (a table per pair of bodies): Coulomb friction,
    dV_bg -= min(1, mu_b rel / |u_t|) u_t with u_t = (v_b - v_cm) - rel n_b
    and mu_b the pair's (two bodies) or the mass-weighted mean over the
    others present. A body is present at g where M_bg > ``share`` rest_mass_b;
    ``normal``: the rule of :func:`outward` (``rank``: per body, its place by
    stiffness). Also returns the kinetic energy the correction changed,
    sum_i (m_i / G) (|v_i'|^2 - |v_i|^2) / 2."""
    nb, n_global = len(rest_mass), int(np.prod(np.asarray(cells) + 1))
    live = m > 0
    g, w = lattice_weights(q, inv_dx, cells, strides, gather)
    M = np.zeros((nb, n_global))
    P = np.zeros((nb, n_global, q.shape[1]))
    for k in range(g.shape[1]):
        mw = w[live, k] * m[live] / n_grids
        np.add.at(M, (body[live], g[live, k]), mw)
        np.add.at(P, (body[live], g[live, k]), mw[:, None] * v[live])
    dV = np.zeros_like(P)
    hit = np.zeros(n_global, bool)
    crowded = 0
    for gg in np.unique(g[live]):
        present = np.flatnonzero(M[:, gg] > share * rest_mass)
        if len(present) < 2 or (M[present, gg] / rest_mass[present]).sum() < fill:
            continue
        hit[gg] = True
        v_cm = P[present, gg].sum(0) / M[present, gg].sum()
        for b in present:
            n = outward(M, b, gg, present, cells, strides, rest_mass, normal, rank)
            u = P[b, gg] / M[b, gg] - v_cm
            rel = u @ n
            if rel > 0:
                dV[b, gg] = -rel * n
                others = present[present != b]
                if mu is not None and np.linalg.norm(u - rel * n) > 0:
                    mu_b = (M[others, gg] * mu[b, others]).sum() / M[others, gg].sum()
                    ut = u - rel * n
                    dV[b, gg] -= min(1.0, mu_b * rel / np.linalg.norm(ut)) * ut
        if len(present) > 2:
            crowded += 1
            dV[present, gg] -= (M[present, gg, None] * dV[present, gg]).sum(0) / M[present, gg].sum()
    out = v.copy()
    for k in range(g.shape[1]):
        out[live] += w[live, k, None] * dV[body[live], g[live, k]]
    work = 0.5 * (m[live] / n_grids * ((out[live] ** 2).sum(1) - (v[live] ** 2).sum(1))).sum()
    # a node is in contact through a lattice node in contact where its body is present
    touching = hit[g] & (M[body[:, None], g] > share * rest_mass[body][:, None])
    return out, live & touching.any(axis=1), crowded, work


def test_bodies_of_equal_stiffness_share_a_place():
    """The normal "stiffer" ranks bodies by P-wave modulus rho c^2: equal
    materials share a place (their normals then by the largest gradient), a
    denser body of the same moduli is softer (c^2 = M / rho: the same rho c^2)."""
    box = mpm.Box((0.5, 0.5), (0.1, 0.1))
    bodies = [mpm.Body(box, mpm.FixedCorotated(E=2e5, nu=0.3)), mpm.Body(box, mpm.FixedCorotated(E=2e6, nu=0.3)),
              mpm.Body(box, mpm.FixedCorotated(E=2e5, nu=0.3, rho=3000.0)), mpm.Body(box, mpm.Fluid(K=1e4))]
    moduli = [b.material.rho * b.material.wave_speed() ** 2 for b in bodies]
    assert moduli[0] == pytest.approx(moduli[2], rel=1e-12)
    rank = contact.stiffness_rank(bodies)
    assert list(rank) == [1, 2, 1, 0]


FRICTION = dict(contact="friction", contact_friction=0.6, contact_pairs=[mpm.ContactPair(0, 1, 0.25)])
"""Coulomb friction between the three colliding bodies: 0.25 between the
first two, 0.6 for the other pairs (a pair's own mu and the mass-weighted
mean where three meet)."""


SETTINGS = [(False, "difference", 0.0), (True, "difference", 0.0), (True, "max_gradient", 0.1),
            (True, "stiffer", 0.1)]
"""(friction, Scene.contact_normal, Scene.contact_share)"""


@pytest.mark.parametrize("friction,normal,share", SETTINGS, ids=["frictionless", "friction", "max_gradient", "stiffer"])
@pytest.mark.parametrize("scheme,kernel", [(mpm.EMPM(), "quadratic"), (mpm.TLMPM(), "quadratic"),
                                           (mpm.EMPM(), "compact"), (mpm.TLMPM(), "compact")],
                         ids=lambda x: getattr(x, "name", x))
def test_contact_matches_the_lattice_rule(scheme, kernel, friction, normal, share):
    """Three bodies of three materials collide (2D, float64), frictionless
    or with Coulomb friction, with either rule of the normals (the largest
    volume gradient's with a presence share of 0.1): in every step,
    each node's corrected velocity equals the reference's (Eulerian nodes
    binned at their lattice node, Lagrangian ones spread, GATHER_PASSES
    times) to round-off, 16 eps
    of the largest (the two sum the bins in different orders; the old lattice-wide passes gave
    the solver's results bit for bit), the status counts the nodes of bins
    in contact and the kinetic energy the contact changed (the reference's
    to round-off of the energy's sum, never above it), and the lattice bins
    are all zero again after the step."""
    scene = colliding_scene(2)
    if friction:
        scene = dataclasses.replace(scene, **FRICTION)
    scene = dataclasses.replace(scene, contact_normal=normal, contact_share=share)
    model, state = mpm.build(scene, mpm.KERNELS[kernel], "float64", DEVICE)
    solver = mpm.Solver(model, scheme)
    solver.prepare(state)
    G = model.kernel.n_grids
    rest_mass = solver.contact.rest_mass.numpy()
    inv_dx, cells, strides = float(solver.contact.inv_dx), np.asarray(model.cells), np.asarray(model.strides)
    resolve = solver._resolve_contact
    seen, differs = [], []

    def checked():
        n = solver.layout.n_nodes
        m, v, q = (a.numpy()[:n].copy() for a in (solver.grid.m, solver.grid.v, solver.grid.q))
        read = solver.buffer.read()
        before, work_before = read["contact_nodes"][0], read["contact_work"][0]
        resolve()
        offset = solver.layout.offset
        body = (np.searchsorted(offset, np.arange(n), side="right") - 1) // G
        gather = scheme.name != "empm"
        args = (body, G, inv_dx, cells, strides, rest_mass, float(solver.contact.fill), gather,
                scene.friction_table() if friction else None, normal, share, solver.contact.rank.numpy())
        want, in_contact, crowded, work = reference_contact(m, v, q, *args)
        if normal == "stiffer":  # the rule matters: the largest gradient alone would give other normals
            other = reference_contact(m, v, q, *args[:-3], "max_gradient", share)[0]
            differs.append(not np.array_equal(other, want))
        for _ in range(contact.GATHER_PASSES - 1 if gather else 0):  # each from the last pass's velocities
            want, _, _, more = reference_contact(m, want, q, *args)
            work += more
        got = solver.grid.v.numpy()[:n]
        scale = np.abs(v).max()
        np.testing.assert_allclose(got, want, rtol=0, atol=16 * np.finfo(np.float64).eps * scale)  # measured 1 eps
        read = solver.buffer.read()
        assert read["contact_nodes"][0] - before == in_contact.sum()
        # the kinetic energy changed: sums of m |v|^2 over the nodes, round-off 64 eps of the energy's scale
        energy = 0.5 * (m / G * (v**2).sum(1)).sum()
        assert abs(read["contact_work"][0] - work_before - work) <= 64 * np.finfo(np.float64).eps * energy
        assert work <= 64 * np.finfo(np.float64).eps * energy  # the contact never gains energy
        assert not solver.contact.M.numpy().any() and not solver.contact.P.numpy().any()
        seen.append((int(in_contact.sum()), int((np.abs(want - v) > 0).any(axis=1).sum()), crowded))

    solver._resolve_contact = checked
    for _ in range(60):
        report = solver.advance(state, 5e-4)
        assert report.reason is None
    assert len(seen) == 60
    # the bodies did meet, and all three in some bins (the mean correction's rule; with a share
    # of 0.1 the third body's fringe is not present there)
    assert sum(n > 0 for n, _, _ in seen) >= 20 and sum(c for _, c, _ in seen) > 0, seen
    assert share > 0 or sum(k for _, _, k in seen) > 0, seen
    assert normal != "stiffer" or sum(differs) > 0
    # the places by P-wave modulus rho c^2 (6.7e4, 1.3e5 and 1.4e5 Pa here: no two equal)
    moduli = [b.material.rho * b.material.wave_speed() ** 2 for b in scene.bodies]
    assert list(solver.contact.rank.numpy()) == list(np.argsort(np.argsort(moduli)))
