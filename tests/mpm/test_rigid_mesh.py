"""Rigid bodies of a closed triangle mesh (mpm.rigid with a mesh shape):
the solid's volume and centroid against closed forms, Newton's mass and
inertia against closed forms and an independent computation (trimesh), a
mesh cube's distance the box's, and an off-centre mesh (a prism, whose
centroid is not its bounding box's centre) turning about its centroid and
keeping the momentum and angular momentum of body and material together."""

import numpy as np
import pytest

import mpm
from mpm.colliders import Collider
from mpm.materials import FixedCorotated
from mpm.meshes import MeshShape, solid_properties
from mpm.model import SceneError
from test_rigid import strike_3d

pytest.importorskip("newton")

CENTRE = (0.3, 0.56, 0.54)  # the shape's bounding-box centre [m]
SIZE = 0.1  # its largest side [m]


def _prism(path) -> str:
    """A right triangular prism, legs 1 along x and y, 1 deep along z (an OBJ file)."""
    v = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1)]
    f = [(0, 2, 1), (3, 4, 5), (0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (2, 0, 3), (2, 3, 5)]
    path.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v) + "".join(f"f {a + 1} {b + 1} {c + 1}\n"
                                                                           for a, b, c in f))
    return str(path)


def _cube(path) -> str:
    """A unit cube (an OBJ file, 12 triangles)."""
    import trimesh

    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(str(path))
    return str(path)


def test_a_closed_meshs_volume_and_centroid_are_the_closed_forms(tmp_path):
    """The prism of legs s and depth s: V = s^3 / 2, centroid at (s/3, s/3, s/2)
    from its right-angled corner; the cube: s^3 and its centre; either
    orientation of the triangles gives the same."""
    pts, tris = MeshShape(_prism(tmp_path / "p.obj"), CENTRE, SIZE).geometry
    corner = np.asarray(CENTRE) - SIZE / 2
    volume, centroid = solid_properties(pts, tris)
    assert volume == pytest.approx(SIZE**3 / 2, rel=1e-12)
    np.testing.assert_allclose(centroid, corner + SIZE * np.array([1 / 3, 1 / 3, 1 / 2]), atol=1e-14)
    assert solid_properties(pts, tris[:, ::-1])[0] == pytest.approx(volume, rel=1e-12)
    np.testing.assert_allclose(solid_properties(pts, tris[:, ::-1])[1], centroid, atol=1e-14)
    pts, tris = MeshShape(_cube(tmp_path / "c.obj"), CENTRE, SIZE).geometry
    volume, centroid = solid_properties(pts, tris)
    assert volume == pytest.approx(SIZE**3, rel=1e-12)
    np.testing.assert_allclose(centroid, CENTRE, atol=1e-14)


def test_a_mesh_cube_is_the_box_body_in_mass_inertia_and_distance(tmp_path):
    """A cube given as 12 triangles and the same cube as a box: Newton's
    mass rho s^3 and inertia m s^2 / 6 about every axis (closed form) for
    both, the mesh's centre of mass at the body's origin, and the solver's
    signed distance of the two colliders the same at points around the
    surface (to the mesh's float32 rounding). (A box body meets the
    material at its edges by its faces' rule, mpm.collider_device
    ``make_edge``, which a mesh body does not: the two differ there.)"""
    from collider_sdf import evaluate

    path = _cube(tmp_path / "c.obj")
    box = Collider.box(CENTRE, (SIZE / 2,) * 3, boundary="separate", friction=0.3)
    mesh = Collider.from_mesh(MeshShape(path, CENTRE, SIZE), boundary="separate", friction=0.3)
    block = mpm.Body(mpm.Box((0.72,) * 3, (0.04,) * 3), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))
    m = 2000.0 * SIZE**3
    for shape in (box, mesh):
        scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=16, bodies=[block], gravity=(0.0,) * 3,
                          walls=("slip",) * 6, rigid_bodies=[mpm.RigidBody(shape, density=2000.0)])
        model = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")[0]
        newton = mpm.Solver(model, mpm.EMPM()).conditions.rigid.newton
        assert float(newton.body_mass.numpy()[0]) == pytest.approx(m, rel=1e-6)
        inertia = np.eye(3) * m * SIZE**2 / 6.0
        np.testing.assert_allclose(newton.body_inertia.numpy()[0], inertia, atol=1e-6 * m * SIZE**2)
        assert np.abs(newton.body_com.numpy()[0]).max() < 1e-7 * SIZE
    q = np.asarray(CENTRE) + np.random.default_rng(3).uniform(-0.08, 0.08, (400, 3))
    phi_box, n_box = evaluate(box, q)
    phi_mesh, n_mesh = evaluate(mesh, q)
    np.testing.assert_allclose(phi_mesh, phi_box, atol=2e-6)
    assert np.abs(phi_box).min() < 0.005 and (phi_box < 0).any() and (phi_box > 0).any()


def test_an_off_centre_mesh_turns_about_its_centroid_and_keeps_angular_momentum(tmp_path):
    """The prism, whose centroid lies a sixth of its size from its bounding
    box's centre in x and y: Newton's mass and inertia about the centroid
    are trimesh's (an independent computation of the same solid), and
    striking the block it keeps the momentum of body and material to 1e-6
    (measured 6e-8) and their angular momentum to 5e-4 (measured 1.9e-4:
    the keep-out's lever, as for the ball of tests/mpm/test_rigid.py, at a
    sharp-edged body)."""
    import trimesh

    path = _prism(tmp_path / "p.obj")
    coupler, drift = strike_3d(Collider.from_mesh(MeshShape(path, CENTRE, SIZE), boundary="separate", friction=0.3))
    pts, tris = MeshShape(path, CENTRE, SIZE).geometry
    solid = trimesh.Trimesh(pts, tris, process=False)
    solid.density = 2000.0
    assert float(coupler.newton.body_mass.numpy()[0]) == pytest.approx(solid.mass, rel=1e-6)
    np.testing.assert_allclose(coupler.newton.body_inertia.numpy()[0], solid.moment_inertia,
                               atol=1e-5 * np.abs(solid.moment_inertia).max())
    assert np.linalg.norm(coupler.poses()["angular_velocity"][0]) > 1.0
    assert drift[0] < 1e-6 and drift[1] < 5e-4, drift


def test_the_material_meets_a_spinning_mesh_where_newton_has_it(tmp_path):
    """The prism spinning freely (omega = (1, 2, 5) rad/s, v = 0.3 m/s, no
    material near it) for 60 steps of 1 ms: the collider the solver places
    from Newton's state has the mesh's vertices, posed by Newton about the
    centroid (R (p - c) + x), on its surface (|phi| < 1e-5 m; turned about
    the bounding box's centre instead they would lie up to 0.3 x 0.024 m
    off it) and moves them at v + omega x (q - x)."""
    import warp as wp
    from collider_sdf import _place_kernel
    from mpm.collider_device import scene_kinds

    path = _prism(tmp_path / "p.obj")
    body = mpm.RigidBody(Collider.from_mesh(MeshShape(path, CENTRE, SIZE)), density=800.0, velocity=(0.3, 0.0, 0.0),
                         angular_velocity=(1.0, 2.0, 5.0))
    block = mpm.Body(mpm.Box((0.72,) * 3, (0.04,) * 3), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=16, bodies=[block], gravity=(0.0,) * 3,
                      walls=("slip",) * 6, rigid_bodies=[body])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64")
    solver = mpm.Solver(model, mpm.EMPM())
    solver.prepare(state)
    for _ in range(60):
        solver.advance(state, 1e-3)
    coupler = solver.conditions.rigid
    solver.schedule(1e-3)  # the next step's clock: it starts at solver.time
    coupler.place(solver.buffer.status)  # the record as the next step has it
    p = coupler.poses()
    x, w, v = p["position"][0], p["angular_velocity"][0], p["velocity"][0]
    R = np.array(wp.quat_to_matrix(wp.quat(*p["quaternion"][0])), np.float64).reshape(3, 3)
    pts = MeshShape(path, CENTRE, SIZE).geometry[0]
    q = (pts - body.center()) @ R.T + x
    assert np.linalg.norm(q - pts, axis=1).max() > 0.01  # it has moved and turned
    t = model.types
    records = solver.conditions.data.colliders
    out = [wp.zeros(len(q), dtype=t.scalar, device=model.device)] + [
        wp.zeros(len(q), dtype=t.vec, device=model.device) for _ in range(2)]
    wp.launch(_place_kernel(t, scene_kinds(scene)), len(q), device=model.device,
              inputs=[records, wp.array(q, dtype=t.vec, device=model.device), float(solver.time), *out])
    phi, _, u = (a.numpy() for a in out)
    assert np.abs(phi).max() < 1e-5, np.abs(phi).max()
    np.testing.assert_allclose(u, v + np.cross(w, q - x), atol=1e-5)


def test_bad_mesh_bodies_are_refused_in_one_line(tmp_path):
    """A mesh body in 2D, and one given a pivot (it turns about its centroid)."""
    shape = MeshShape(_cube(tmp_path / "c.obj"), (0.5, 0.5), SIZE)
    block = mpm.Body(mpm.Box((0.3, 0.3), (0.05, 0.05)), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))
    flat = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16, bodies=[block], walls=("slip",) * 4,
                     rigid_bodies=[mpm.RigidBody(Collider.from_mesh(shape), density=500.0)])
    with pytest.raises(SceneError, match=r"^rigid_bodies\[0\].shape: 'mesh'; accepted in 2D: box, sphere$"):
        mpm.build(flat, mpm.KERNELS["quadratic"])
    block3 = mpm.Body(mpm.Box((0.3,) * 3, (0.05,) * 3), FixedCorotated(E=1e4, nu=0.3, rho=1000.0))
    pivoted = Collider.from_mesh(MeshShape(_cube(tmp_path / "c.obj"), (0.5,) * 3, SIZE), pivot=(0.5,) * 3)
    scene = mpm.Scene(dim=3, domain=(1.0,) * 3, resolution=16, bodies=[block3], walls=("slip",) * 6, gravity=(0.0,) * 3,
                      rigid_bodies=[mpm.RigidBody(pivoted, density=500.0)])
    with pytest.raises(SceneError, match=r"^rigid_bodies\[0\].shape: a moving, turning or inside-out shape"):
        mpm.build(scene, mpm.KERNELS["quadratic"])
