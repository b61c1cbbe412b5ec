"""Particle volumes from geometry (mpm.sampling.shape_volume, Scene.particle_volume):
a body's particles share its shape's exact volume, so that its mass and
kinetic energy are the shape's, not its sampling cells'."""

import math

import numpy as np
import pytest

import mpm
from helpers import DEVICE, PAPER_SCENES, spec_for
from mpm.meshes import MeshShape
from mpm.sampling import shape_volume
from shapes import volume_and_area

SHAPES_3D = [
    mpm.Box((0.5, 0.5, 0.5), (0.1, 0.2, 0.05)),
    mpm.Sphere((0.5, 0.5, 0.5), 0.2),
    mpm.Sphere((0.5, 0.5, 0.5), 0.2, inner_radius=0.15),
    mpm.Cylinder((0.5, 0.5, 0.5), 0.1, 0.2, axis=2, inner_radius=0.04),
    mpm.scene.Bowl((0.5, 0.5, 0.5), 0.2, 0.03, 0.05),
    mpm.scene.Bowl((0.5, 0.5, 0.5), 0.2, 0.03, -0.1),
    mpm.scene.Rotated(mpm.Box((0.5, 0.5, 0.5), (0.1, 0.2, 0.05)), mpm.scene.rotation_matrix((10, 20, 30), 3)),
    MeshShape("warp:bunny", (0.5, 0.5, 0.5), 0.3),
    mpm.Compound((mpm.Sphere((0.3, 0.5, 0.5), 0.1), mpm.Box((0.7, 0.5, 0.5), (0.1, 0.1, 0.1)))),
]


@pytest.mark.parametrize("shape", SHAPES_3D, ids=lambda s: type(s).__name__)
def test_shape_volumes_are_the_closed_forms(shape):
    """Against tests/shapes.py (closed forms, the divergence theorem, and for a
    union a midpoint quadrature), written apart from mpm: to float64 round-off
    where the reference is exact, within the quadrature's bound for a union."""
    V, _, bound = volume_and_area(shape, 3, 1 / 256)
    assert shape_volume(shape, 3) == pytest.approx(V, rel=64 * np.finfo(float).eps, abs=bound)


def test_2d_volumes_against_a_quadrature():
    """Discs, rings, boxes and arcs (the 2D bowl: a ring below a chord) against
    the midpoint rule with each shape's own membership test on a lattice of
    spacing h, whose error is within sqrt(2)/2 h times the perimeter."""
    h = 1 / 2048
    g = np.stack(np.meshgrid(*([np.arange(h / 2, 1, h)] * 2), indexing="ij"), -1).reshape(-1, 2)
    for shape, perimeter in [(mpm.Sphere((0.5, 0.5), 0.3), 2 * math.pi * 0.3),
                             (mpm.Sphere((0.5, 0.5), 0.3, inner_radius=0.2), 2 * math.pi * 0.5),
                             (mpm.Box((0.5, 0.5), (0.2, 0.1)), 1.2),
                             (mpm.scene.Bowl((0.5, 0.5), 0.3, 0.05, 0.1), 2 * math.pi * 0.65 + 0.1),
                             (mpm.scene.Bowl((0.5, 0.5), 0.3, 0.05, -0.2), 2 * math.pi * 0.65 + 0.1)]:
        quadrature = shape.contains(g).sum() * h * h
        assert abs(shape_volume(shape, 2) - quadrature) <= 0.5 * math.sqrt(2) * perimeter * h, shape


def test_overlapping_union_has_no_closed_form():
    """A union whose parts overlap has no closed form: its particles keep their
    cells' volumes, and the model says so."""
    union = mpm.Compound((mpm.Sphere((0.45, 0.5), 0.1), mpm.Sphere((0.55, 0.5), 0.1)))
    assert shape_volume(union, 2) is None
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, bodies=[mpm.Body(union, mpm.NeoHookean())])
    model, _ = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", DEVICE)
    v = model.body_volumes[0]
    assert v["used"] == "cells" and v["shape"] is None and v["volume"] == v["cells"]


@pytest.mark.parametrize("scene", sorted(PAPER_SCENES))
def test_paper_scenes_shapes_have_their_volumes(scene):
    """Every body of the papers' scenes: its shape's volume is the closed form
    (tests/shapes.py), or None for a union of overlapping parts."""
    s = spec_for([f"scene={scene}"]).scene
    for b in s.bodies:
        got = shape_volume(b.shape, s.dim)
        V, _, bound = volume_and_area(b.shape, s.dim, s.particle_dx / 8)
        if got is None:
            assert isinstance(b.shape, mpm.Compound)
        else:
            assert got == pytest.approx(V, rel=64 * np.finfo(float).eps, abs=bound), b.name


def _two_disks(particle_volume: str):
    """Sulsky, Chen and Schreyer (1994), two elastic disks: radius 0.2 m,
    centres 0.5 sqrt(2) m apart on the diagonal, v = +-(0.1, 0.1) m/s,
    rho = 1000 kg/m^3, cells of 0.05 m (their 20 x 20 over the unit square),
    4 particles per cell; the domain is 1.5 m wide so that the walls' bands
    leave the disks free."""
    disk = dict(material=mpm.NeoHookean(E=1000.0, nu=0.3, rho=1000.0))
    bodies = [mpm.Body(mpm.Sphere((0.5, 0.5), 0.2), velocity=(0.1, 0.1), **disk),
              mpm.Body(mpm.Sphere((1.0, 1.0), 0.2), velocity=(-0.1, -0.1), **disk)]
    scene = mpm.Scene(dim=2, domain=(1.5, 1.5), resolution=30, ppc=4, bodies=bodies, gravity=(0.0, 0.0),
                      walls=("open",) * 4, particle_volume=particle_volume)
    return mpm.build(scene, mpm.KERNELS["quadratic"], "float64", DEVICE)


def test_two_disks_carry_the_disks_mass_and_kinetic_energy():
    """The disks' mass is rho pi r^2 each and the initial kinetic energy
    2 x 1/2 rho pi r^2 |v|^2 = 0.251 J, to float64 round-off, with the
    particles sharing the shape's volume; with each particle its cell's
    (dx^2 / ppc) both are off by the sampling's error (3.5 % here)."""
    rho, r, v2 = 1000.0, 0.2, 0.02
    mass = rho * math.pi * r * r
    for used in ("shape", "cells"):
        model, state = _two_disks(used)
        m = model.mass.numpy()
        body = model.body.numpy()
        ke = 0.5 * np.sum(m * np.sum(state.v.numpy() ** 2, axis=1))
        cells = model.body_volumes[0]["cells"]
        if used == "shape":
            for b in (0, 1):
                assert m[body == b].sum() == pytest.approx(mass, rel=1e-13)
            assert ke == pytest.approx(mass * v2, rel=1e-13)
        else:
            assert ke == pytest.approx(rho * cells * v2, rel=1e-13)
            assert abs(cells / (math.pi * r * r) - 1) > 0.005  # what the shape's volume corrects
        assert model.body_volumes[0]["used"] == used
