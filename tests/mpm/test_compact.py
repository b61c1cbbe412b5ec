"""The compact kernel on its pair of grids: the Eulerian step against an
independent NumPy implementation, for the three transfers."""

import numpy as np
import pytest

import mpm
from reference_mpm import compact_step
from test_reference import assert_no_contact, assert_state_matches, particle_inputs, tiny_scene


@pytest.mark.parametrize("transfer", ["mls", "apic", "pic"])
@pytest.mark.parametrize("dim", [2, 3])
def test_compact_eulerian_step_matches_numpy_reference(dim, transfer, device):
    scene = tiny_scene(dim)
    model, state = mpm.build(scene, mpm.KERNELS["compact"], "float64", device)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(transfer=transfer))
    solver.prepare(state)
    _, models, prms, mass, vol = particle_inputs(scene, model)
    s = state.numpy()
    x, v, C, F = s["x"], s["v"], s["C"], s["F0s"]
    dt = 2e-4
    for k in range(6 if dim == 2 else 3):
        x, v, C, F = compact_step(x, v, C, F, mass, vol, models, prms, model.dx, model.domain,
                                  scene.gravity, scene.walls, dt, transfer)
        solver.advance(state, dt)
        assert_no_contact(solver)
        assert_state_matches(state, x, v, C, F, k, model.dx, C_factor=512)  # the per-particle K_p adds round-off
    assert np.abs(F - np.eye(dim)).max() > 1e-4
