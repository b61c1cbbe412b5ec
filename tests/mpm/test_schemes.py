"""The three schemes of one formulation: against an independent NumPy
reference of the reference-configuration step, the identities between them,
and the update criterion."""

import dataclasses

import numpy as np
import pytest

import mpm
from helpers import DEVICE
from reference_mpm import lagrangian_step, update_configuration
from test_reference import assert_no_contact, particle_inputs, round_off, tiny_scene


def run_reference(scene, model, state, scheme, steps, dt):
    """The NumPy reference with the scheme's update rule; yields after each step."""
    body, models, prms, mass, vol = particle_inputs(scene, model)
    s = {k: v.copy() for k, v in state.numpy().items()}
    counts = np.bincount(body)
    for _ in range(steps):
        lagrangian_step(s, mass, vol, models, prms, body, model.dx, model.cells, model.domain,
                        scene.gravity, scene.walls, dt)
        dJ = np.abs(np.linalg.det(s["Fsn"]) - 1.0)
        updated = []
        for b in range(len(counts)):
            if scheme.name == "aulmpm":  # paper eq. 33
                marked = int(np.sum(dJ[body == b] >= scheme.epsilon))
                update = marked >= scheme.eta * counts[b]
            else:
                update = scheme.name == "empm"
            if update:
                updated.append(b)
                update_configuration(s, body == b, models, scheme.affine)
        yield s, updated


SCHEMES = [mpm.EMPM(), mpm.TLMPM(), mpm.AULMPM(affine="transform"), mpm.AULMPM(affine="keep")]
# thresholds at which the tiny scenes update at some steps and not at others
# (dJ grows by about 1e-4 per step in 2D, 1e-6 in 3D)
EPSILON = {2: 2e-4, 3: 2e-6}


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("scheme", SCHEMES, ids=lambda s: f"{s.name}-{s.affine}")
def test_schemes_match_numpy_reference(scheme, dim, device):
    """Particle by particle, float64, with walls, gravity, several bodies and
    materials, to round-off (test_reference.round_off); A-ULMPM thresholds
    chosen so that some steps update and others do not."""
    scene = tiny_scene(dim)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", device)
    if scheme.name == "aulmpm":
        scheme = mpm.AULMPM(epsilon=EPSILON[dim], eta=0.3, affine=scheme.affine)
    solver = mpm.Solver(model, scheme)
    solver.prepare(state)
    steps, dt = (10, 2e-4) if dim == 2 else (5, 2e-4)
    updates_seen = set()
    for k, (ref, updated) in enumerate(run_reference(scene, model, state, solver.scheme, steps, dt)):
        report = solver.advance(state, dt)
        assert_no_contact(solver)
        assert report.updated == updated, f"step {k}"
        updates_seen.add(len(updated) > 0)
        got = state.numpy()
        tol = round_off(ref["x"], ref["v"], ref["Fsn"] @ ref["F0s"], model.dx)
        for key, name in (("x", "x"), ("v", "v"), ("C", "C"), ("F0s", "F"), ("Fsn", "F"), ("X", "x")):
            np.testing.assert_allclose(got[key], ref[key], rtol=0, atol=tol[name], err_msg=f"{key}, step {k}")
    if scheme.name == "aulmpm":
        assert updates_seen == {True, False}  # the criterion did switch


def run(scene, scheme, steps, dt, precision="float64"):
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], precision, DEVICE)
    solver = mpm.Solver(model, scheme)
    solver.prepare(state)
    reports = [solver.advance(state, dt) for _ in range(steps)]
    return state.numpy(), reports


CRITERIA = {"paper": {"criterion": "paper"},
            # bounds tight enough to fire on the tiny scenes if they were consulted
            "distortion": {"criterion": "distortion", "dJ_max": 1e-6, "stretch_min": 0.99999}}


@pytest.mark.bitwise
@pytest.mark.parametrize("criterion", list(CRITERIA))
@pytest.mark.parametrize("dim", [2, 3])
def test_aulmpm_limits_are_empm_and_tlmpm(dim, criterion):
    """epsilon = 0 (affine kept): every particle is marked, every step updates
    - the Eulerian scheme; epsilon = inf: never - the total Lagrangian scheme,
    with either criterion. Same floating-point operations, so equal bit for bit."""
    scene = tiny_scene(dim)
    steps = 30 if dim == 2 else 8
    ref_e, _ = run(scene, mpm.EMPM(), steps, 2e-4)
    got_e, rep = run(scene, mpm.AULMPM(epsilon=0.0, eta=1.0, affine="keep", **CRITERIA[criterion]),
                     steps, 2e-4)
    assert all(len(r.updated) == len(scene.bodies) for r in rep)
    ref_t, _ = run(scene, mpm.TLMPM(), steps, 2e-4)
    got_t, rep = run(scene, mpm.AULMPM(epsilon=float("inf"), eta=0.0, **CRITERIA[criterion]), steps, 2e-4)
    assert not any(r.updated for r in rep)
    for key in ("x", "v", "C", "F"):
        np.testing.assert_array_equal(got_e[key], ref_e[key], err_msg=key)
        np.testing.assert_array_equal(got_t[key], ref_t[key], err_msg=key)
    # and the two limits do differ
    assert np.abs(ref_e["x"] - ref_t["x"]).max() > 1e-9


def test_aulmpm_criteria():
    """paper: eq. 33 only (marked >= eta n); distortion: also any dJ >= dJ_max
    or a reference cell squeezed below stretch_min; the paper's criterion
    ignores the bounds even on a fluid, and refuses them when given."""
    paper = mpm.AULMPM(criterion="paper").resolved("fluid")
    dist = mpm.AULMPM().resolved("plastic")
    assert (paper.dJ_max, paper.stretch_min, dist.criterion) == (float("inf"), 0.0, "distortion")
    n = 1000
    assert paper.updates(10, n, 0.0, 1.0) and dist.updates(10, n, 0.0, 1.0)  # 10 >= 0.01 n
    assert not paper.updates(9, n, 0.9, 0.1)  # one particle squeezed or compressed: not eq. 33
    assert dist.updates(9, n, 0.5, 1.0) and dist.updates(9, n, 0.0, 0.49)
    assert not dist.updates(9, n, 0.49, 0.5)
    assert mpm.AULMPM(criterion="paper", stretch_min=0.5).problems()
    assert not mpm.AULMPM(criterion="distortion", stretch_min=0.5).problems()


def test_aulmpm_defaults_follow_the_materials():
    solid = mpm.AULMPM().resolved("solid")
    fluid = mpm.AULMPM().resolved("fluid")
    assert (solid.epsilon, solid.eta, solid.dJ_max, solid.stretch_min) == (0.5, 0.1, float("inf"), 0.05)
    plastic = mpm.AULMPM().resolved("plastic")
    assert (fluid.epsilon, fluid.eta, fluid.dJ_max, fluid.stretch_min) == (0.01, 0.01, float("inf"), 0.9)
    assert (plastic.epsilon, plastic.eta, plastic.dJ_max, plastic.stretch_min) == (0.01, 0.01, 0.5, 0.5)
    assert (solid.criterion, fluid.criterion, plastic.criterion) == ("distortion",) * 3
    assert mpm.AULMPM(criterion="paper").resolved("solid").stretch_min == 0.0  # eq. 33 alone: no bounds
    kind, M = mpm.schemes.scene_kind, mpm.MATERIALS
    assert kind([M["fixed_corotated"]()]) == "solid"
    assert kind([M["fixed_corotated"](), M["sand"]()]) == kind([M["viscoplastic"]()]) == "plastic"
    assert kind([M["sand"](), M["fluid"]()]) == kind([M["viscous"]()]) == "fluid"
    assert mpm.AULMPM(epsilon=0.2).resolved("fluid").epsilon == 0.2


def scene_of(dim: int, bodies: str) -> mpm.Scene:
    """The tiny scene (a solid, a fluid and in 2D another solid) or part of
    it: ``mixed`` all bodies (two projections), ``solids``, ``fluid`` (its
    projection), ``open`` the fluid alone thrown at an open left wall."""
    scene = tiny_scene(dim)
    fluid = [b for b in scene.bodies if isinstance(b.material, mpm.Fluid)]
    if bodies == "solids":
        return dataclasses.replace(scene, bodies=[b for b in scene.bodies if b not in fluid])
    if bodies == "fluid":
        return dataclasses.replace(scene, bodies=fluid)
    if bodies == "open":
        thrown = dataclasses.replace(fluid[0], velocity=(-8.0,) + (0.0,) * (dim - 1))
        return dataclasses.replace(scene, bodies=[thrown], walls=("open",) + scene.walls[1:])
    return scene


@pytest.mark.bitwise
@pytest.mark.parametrize("dim,kernel,transfer,bodies,resolution", [
    (2, "quadratic", "mls", "mixed", None), (2, "compact", "pic", "mixed", None),  # fused, an update pass
    (2, "quadratic", "mls", "solids", None), (2, "compact", "mls", "solids", None),  # G2P updates, K_p too
    (2, "compact", "apic", "fluid", None), (3, "compact", "mls", "fluid", None),  # with the projection
    (2, "quadratic", "pic", "open", None), (2, "compact", "mls", "open", None),  # removed particles
    # 1/dx rounds differently from float64 in float32 here: the fused path must divide as the kernels do
    (2, "quadratic", "mls", "solids", 30), (2, "compact", "mls", "solids", 28)])
def test_fused_eulerian_path_equals_the_cached_one(dim, kernel, transfer, bodies, resolution):
    """EMPM with the stencils located in P2G and G2P (SolverOptions.fuse),
    and G2P doing the configuration update where the bodies share one
    projection, is the same arithmetic as through the cache and the update
    kernel: equal bit for bit after every completed step (K_p and the
    reference positions too, removed particles included)."""
    scene = scene_of(dim, bodies)
    if resolution is not None:
        scene = dataclasses.replace(scene, resolution=resolution)
    steps, dt = (4, 2e-4) if dim == 3 else (40, 2e-3) if bodies == "open" else (12, 2e-4)
    out = []
    for fuse in (False, True):
        model, state = mpm.build(scene, mpm.KERNELS[kernel], "float32", DEVICE)
        solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(transfer=transfer, fuse=fuse))
        assert solver.fused == fuse
        assert solver.g2p_commits == (fuse and bodies != "mixed")
        solver.prepare(state)
        for _ in range(steps):
            solver.advance(state, dt)
        out.append({**state.numpy(), "K": state.stencils.K.numpy(), "removed": solver.removals.removed.sum()})
    for key in ("x", "v", "C", "F0s", "Fsn", "X", "K"):
        np.testing.assert_array_equal(out[1][key], out[0][key], err_msg=key)
    assert np.abs(out[0]["x"] - out[0]["X"]).max() == 0  # EMPM: the reference is where the particles are
    assert np.abs(out[0]["v"]).max() > 0
    assert (out[0]["removed"] > 0) == (bodies == "open") and out[1]["removed"] == out[0]["removed"]


def test_fused_by_default_where_it_pays():
    """SolverOptions.fuse None: EMPM fuses with the quadratic and cubic
    B-splines when the bodies share a projection, keeps the cache for the
    compact kernel (its sines) and the linear one,
    and never fuses the Lagrangian schemes or the implicit integrator."""
    def fused(bodies, kernel="quadratic", scheme=mpm.EMPM(), **options):
        model, _ = mpm.build(scene_of(2, bodies), mpm.KERNELS[kernel], "float32", DEVICE)
        return mpm.Solver(model, scheme, mpm.SolverOptions(**options)).fused

    assert fused("solids") and fused("fluid") and fused("solids", "cubic")
    # the kernels whose moment varies per particle keep the cache
    assert not fused("mixed") and not fused("solids", "compact") and not fused("solids", "linear")
    assert not fused("solids", scheme=mpm.AULMPM(epsilon=0.0)) and not fused("solids", scheme=mpm.TLMPM())
    assert not fused("solids", integrator=mpm.Implicit())


@pytest.mark.parametrize("dim", [2, 3])
def test_affine_matrix_over_an_update(dim):
    """At a configuration update (mpm.reference_update.make_update) C becomes
    C (F^sn)^-1 (transform), C R^T with F^sn = R U its polar decomposition
    (rotate: |C R^T| = |C|, never amplified), or stays (keep); checked
    against NumPy's polar decomposition (via the SVD) on a random stretched
    and turned F^sn per particle, to float64 round-off."""
    rng = np.random.default_rng(3)
    scene = mpm.Scene(dim=dim, domain=(1.0,) * dim, resolution=16, ppc=1, gravity=(0.0,) * dim,
                      walls=("slip",) * (2 * dim), bodies=[mpm.Body(mpm.Sphere((0.5,) * dim, 0.15), mpm.NeoHookean())])
    for affine in mpm.schemes.AFFINE:
        model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", DEVICE)
        solver = mpm.Solver(model, mpm.AULMPM(affine=affine))
        solver.prepare(state)
        n = model.n_particles
        C = rng.normal(size=(n, dim, dim))
        U, _, Vt = np.linalg.svd(rng.normal(size=(n, dim, dim)))
        U[np.linalg.det(U @ Vt) < 0, :, 0] *= -1.0
        R = U @ Vt  # proper rotations
        stretch = np.stack([np.diag(rng.uniform(0.2, 2.0, dim)) for _ in range(n)])
        Fsn = R @ stretch  # F = R U with U symmetric positive definite (diagonal here)
        state.C.assign(C)
        state.Fsn.assign(Fsn)
        solver.references.move(state, [0], solver.const)
        got = state.C.numpy()
        u, _, vt = np.linalg.svd(Fsn)
        polar = u @ vt  # the polar rotation of F^sn (det > 0 here)
        expected = {"keep": C, "transform": C @ np.linalg.inv(Fsn),
                    "rotate": C @ np.swapaxes(polar, 1, 2)}[affine]
        np.testing.assert_allclose(got, expected, rtol=0, atol=64 * np.finfo(float).eps * np.abs(expected).max())
        if affine == "rotate":
            np.testing.assert_allclose(np.linalg.norm(got, axis=(1, 2)), np.linalg.norm(C, axis=(1, 2)), rtol=1e-13)
        np.testing.assert_allclose(state.Fsn.numpy(), np.broadcast_to(np.eye(dim), (n, dim, dim)), atol=0)
