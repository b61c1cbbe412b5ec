"""One implicit step of two bodies in contact (EMPM, quadratic: each body's
nodes are lattice nodes), with each body's system assembled independently
in NumPy (reference_mpm.ImplicitSystem): the quantities the tests of the
contact constraints (tests/mpm/test_implicit.py) and of friction
(tests/mpm/test_implicit_friction.py) check their conditions on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_mpm import ImplicitSystem


@dataclass
class ContactStep:
    """Per body b, by lattice node (i, j): mass ``M[b]``, predictor
    ``v_star[b]``, residual at the solver's velocities ``R[b]`` (the
    contact's impulse on the node) and those velocities ``v[b]``; each
    body's lattice nodes ``lattice[b]`` and their flat grid indices
    ``nodes[b]`` (ImplicitSystem's order),
    ``scale`` the larger residual at the predictor, the solve's ``report``."""

    M: list[dict]
    v_star: list[dict]
    R: list[dict]
    v: list[dict]
    lattice: list[list[tuple]]
    nodes: list[list[int]]
    scale: float
    report: object


def contact_step(solver, state, dt, scene) -> ContactStep:
    """The solver's implicit step without the explicit contact pass after
    it; the state is left at the step's start."""
    s = state.numpy()
    mat = scene.bodies[0].material
    body = solver.model.body.numpy()
    lay = solver.layout
    systems, nodes = [], []
    for b in range(2):
        sel = body == b
        sb = {k: v[sel] for k, v in s.items() if len(v) == len(sel)}
        system = ImplicitSystem(sb, solver.model.mass.numpy()[sel], solver.model.volume.numpy()[sel], mat.name,
                                mat.packed(), solver.model.dx, scene.gravity, dt)
        lo, shape, offset = lay.lo_d.numpy()[b], lay.shape_d.numpy()[b], lay.offset_d.numpy()[b]
        nodes.append([offset + int(np.dot(np.array(n) - lo, [shape[1], 1])) for n in system.nodes])
        systems.append(system)
    solver.contact.resolve = lambda *args: None  # the solve's velocities, without the explicit pass after it
    try:
        solver.schedule(dt)
        report = solver.attempt(state)
    finally:
        del solver.contact.resolve
    grid_v = solver.grid.v.numpy()
    return ContactStep(
        M=[dict(zip(sy.nodes, sy.m)) for sy in systems],
        v_star=[dict(zip(sy.nodes, sy.v_star)) for sy in systems],
        R=[dict(zip(sy.nodes, sy.residual(grid_v[f]))) for sy, f in zip(systems, nodes)],
        v=[dict(zip(sy.nodes, grid_v[f])) for sy, f in zip(systems, nodes)],
        lattice=[list(sy.nodes) for sy in systems], nodes=nodes, scale=max(np.linalg.norm(sy.residual(sy.v_star)) for sy in systems), report=report)


def touching(step: ContactStep, fill: float, rest_mass: float) -> dict:
    """The lattice nodes both bodies fill to ``fill`` of ``rest_mass``
    (rho dx^d) together, each with body 0's outward normal there,
    normalize(grad(M_1 - M_0)) by central differences (the contact's
    default rule, mpm.contact.lattice ``outward``)."""
    M = step.M
    out = {}
    for n in set(M[0]) & set(M[1]):
        if (M[0][n] + M[1][n]) / rest_mass < fill:
            continue
        grad = np.array([sum((M[1].get(n[:k] + (n[k] + e,) + n[k + 1:], 0.0)
                              - M[0].get(n[:k] + (n[k] + e,) + n[k + 1:], 0.0)) * e for e in (1, -1))
                         for k in range(len(n))])
        out[n] = grad / np.linalg.norm(grad)
    return out
