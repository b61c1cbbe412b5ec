"""Where bodies touch: the contact benchmarks of examples/ (rolling.py,
plane_shift.py, resting.py, hertz.py, piston.py) at small sizes, and the
Hertz closed forms (mpm.hertz) against an independent integration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import load_example as load
from mpm.hertz import (contact_modulus, cylinder_approach, cylinder_half_width, plates_load, sphere_approach,
                       sphere_load)


# ------------------------------------------------------------ closed forms
@pytest.mark.parametrize("load_factor", [1.0e-4, 1.0e-3])
def test_the_cylinders_shortening_is_the_strain_integrated_on_its_loaded_diameter(load_factor):
    """Integrate, on a fine grid along the loaded diameter of a cylinder
    between two line contacts, the plane-strain strain
    eps_y = (1 - nu^2) / E (sigma_y - nu / (1 - nu) sigma_x) of the two
    Hertz pressures' half-plane stresses (exact in z, with asinh, not its
    logarithm) plus the disk's uniform tension P / (pi R): the shortening is
    twice mpm.hertz.cylinder_approach, to the terms in (b / R)^2 the
    closed form drops."""
    E, nu, R = 1.0e5, 0.3, 0.08
    Es = contact_modulus(E, nu)
    P = load_factor * E * R  # [N/m]
    b = cylinder_half_width(P, R, Es)
    p0 = 2 * P / (math.pi * b)
    y = np.linspace(-R, R, 2_000_001)

    def under(z):  # a contact's stresses at depth z on its axis
        root = np.sqrt(b * b + z * z)
        return -p0 * b / root, -(p0 / b) * ((b * b + 2 * z * z) / root - 2 * z)
    (sy1, sx1), (sy2, sx2) = under(R - y), under(R + y)
    tension = P / (math.pi * R)
    sy, sx = sy1 + sy2 + tension, sx1 + sx2 + tension
    strain = (1 - nu * nu) / E * (sy - nu / (1 - nu) * sx)
    shortening = -np.trapezoid(strain, y)
    assert shortening == pytest.approx(2 * cylinder_approach(P, R, Es), rel=5 * (b / R) ** 2 + 1e-6)


def test_the_hertz_laws_invert_and_the_plates_share_the_approach():
    """F(delta) and delta(F) invert each other; plates_load finds the load
    whose two approaches add up to the plates' (a rigid and a softer
    contact, 2D and 3D), and a softer contact takes more of it."""
    R, E, nu = 0.08, 1.0e5, 0.3
    rigid, soft = contact_modulus(E, nu), contact_modulus(E, nu, 2.0e5, nu)
    for F in (1e-3, 1.0, 30.0):
        assert sphere_load(sphere_approach(F, R, rigid), R, rigid) == pytest.approx(F, rel=1e-12)
    for dim, each in ((3, sphere_approach), (2, cylinder_approach)):
        F = plates_load(0.004, R, dim, rigid, soft)
        assert each(F, R, rigid) + each(F, R, soft) == pytest.approx(0.004, rel=1e-9)
        assert each(F, R, soft) > each(F, R, rigid)


# ------------------------------------------------------------ the benchmarks
def test_a_block_slides_alike_wherever_the_plane_lies_between_nodes(device):
    """A block on a rough collider plane whose surface lies on a node row or
    a quarter or half a cell above it (64 cells, EMPM): sliding at 30 deg,
    mu = 0.3, its acceleration is within 1 % of g (sin - mu cos) at every
    shift (measured within 0.3 %); held at 20 deg, mu = 0.5, it moves less
    than 0.2 cell while its weight comes onto the plane (it starts without
    it; measured 0.08-0.16) and less than 0.01 cell after 0.1 s. The node
    rule of earlier versions, with the plane on a node row, lets it creep
    on (its nodes act one row late)."""
    ex = load("plane_shift")
    closed = ex.sliding(30.0, ex.G, 0.3)
    for shift in (0.0, 0.25, 0.5):
        a = ex.acceleration(ex.run(shift, 30.0, 0.3, duration=0.2, device=device))
        assert abs(a / closed - 1) < 0.01, (shift, a, closed)
        held = ex.run(shift, 20.0, 0.5, duration=0.2, device=device)
        t, x = np.array(held.t), np.array(held.x)[:, 0] * 64
        assert abs(x[-1] - x[0]) < 0.2, shift
        assert np.ptp(x[t >= ex.LOADED]) < 0.01, shift
    old = ex.run(0.0, 20.0, 0.5, duration=0.2, rule="nodes", device=device)
    t, x = np.array(old.t), np.array(old.x)[:, 0] * 64
    assert np.ptp(x[t >= ex.LOADED]) > 0.1


def test_a_block_loaded_slowly_is_held_on_a_rough_plane_wherever_it_lies_between_nodes(device):
    """The held block of the test above (20 deg, mu = 0.5 > tan 20 deg =
    0.36, 64 cells, EMPM) with its weight rising from 0 over 0.2 s: friction
    can hold it at every instant, so it must not slip. Its travel along the
    plane is its elastic shear plus its slip; the same block on a sticky
    plane (its base held) travels by the shear alone, so the slip is the
    difference: under 0.05 cell at every shift (measured 0.007-0.012;
    the shear itself 0.033-0.040). The node rule with the plane on a node
    row slips (measured 0.13 cell): its nodes act one row late."""
    ex = load("plane_shift")

    def slip(shift, rule="surface"):
        held, sticky = (ex.run(shift, 20.0, mu, duration=0.3, ramp=0.2, rule=rule, device=device)
                        for mu in (0.5, None))
        return 64 * ((held.x[-1][0] - held.x[0][0]) - (sticky.x[-1][0] - sticky.x[0][0]))

    for shift in (0.0, 0.25, 0.5):
        assert abs(slip(shift)) < 0.05, shift
    assert slip(0.0, rule="nodes") > 0.05


@pytest.mark.parametrize("scheme", ["empm", "tlmpm"])
def test_a_block_rests_on_a_wall_a_collider_and_a_stiffer_body(scheme, device):
    """A block under its weight (32 cells) on the floor wall, on a collider
    plane on a node row and half a cell above one, and on a slab ten times
    stiffer: its lowest particles settle within 0.1 cell of their elastic
    rest position (measured within 0.04; the node rule sank 0.31 and 0.53
    cell on the wall)."""
    ex = load("resting")
    for on, shift in (("wall", 0.0), ("collider", 0.0), ("collider", 0.5), ("body", 0.0)):
        change, elastic = ex.rest(on, scheme, 32, shift, duration=0.3, device=device)
        assert abs(change - elastic) * 32 < 0.1, (on, shift, change * 32)


def test_a_piston_at_2_m_per_s_leaves_no_water_inside_it(device):
    """Water pushed by a box collider at 2 m/s (64 cells, K = 1e6 Pa): after
    every step no particle lies behind the moving face (the node rule
    leaves up to 34, a quarter of a cell deep), and the piston pushes
    the water forward."""
    driver, inside = load("piston").push(duration=0.08, device=device)
    assert driver.outcome.status == "completed"
    assert max(inside.count) == 0 and max(inside.depth) < 1e-4 / 64
    assert inside.impulse > 0.0


def test_a_disk_rolls_near_the_closed_form_on_a_collider_and_on_a_body(device):
    """A disk rolling from rest at 20 deg, mu = 0.5 (64 cells, EMPM):
    within 4 % of (2/3) g sin theta on the collider (measured -3.3 %) and
    5 % on the slab (-4.6 %), slipping less than 0.2 cell once its weight
    is on the plane. (The targets are 3 % and 0.1 cell: RESULTS says where
    each case stands.)"""
    ex = load("rolling")
    for on, bound in (("collider", 0.04), ("body", 0.05)):
        r = ex.roll(2, on, "empm", 64, device=device)
        assert abs(r.error) < bound, (on, r.error)
        assert abs(r.slip) * 64 < 0.2, (on, r.slip * 64)


def test_a_disk_rolls_without_slipping_on_a_collider_under_the_implicit_integrator(device):
    """The disk of rolling.py on the collider under the implicit integrator
    (64 cells, EMPM, 1 ms steps, 0.3 s): with Coulomb friction inside the
    solve (mpm.implicit.rough; the deep nodes held at the surface point)
    it slips 0.035 cells from 0.1 s on (bound 0.07); friction applied after
    the solve with the solve's normal reaction, as earlier versions did,
    let it slip 0.104 cells."""
    r = load("rolling").roll(2, "collider", "empm", 64, duration=0.3, integrator="implicit", device=device)
    assert abs(r.slip) * 64 < 0.07, r.slip * 64


def test_a_cylinder_pressed_between_plates_follows_the_line_contact_law(device):
    """A cylinder (R = 20 cells, EMPM) pressed slowly between two collider
    plates by 8 mm (2 cells): over the second half of the loading its force
    is within 7 % of the line contact law (measured 0.948 to 1.045; 0.955 to
    1.003 at twice the resolution)."""
    p = load("hertz").press(2, "collider", "empm", 64, device=device)
    assert np.all(np.abs(p.loaded() - 1.0) < 0.07), p.ratio



def test_plates_pressing_a_body_under_the_implicit_integrator_give_it_no_energy_beyond_their_work(device):
    """The cylinder of hertz.py (R = 15 cells) pressed between frictionless
    separating plates under the implicit integrator at 2 ms (15 times the
    explicit step), 0.16 s: the body's elastic plus kinetic energy never
    exceeds the plates' work W = sum J . v (backward Euler only dissipates;
    1 % for the work's split between steps), and most of W is stored
    (measured 0.175 J of 0.182 J). Decided once from the predictor, the
    one-sided plates left free the nodes the solution moved into them
    (mpm.implicit.solve): the body then stored 0.263 J of 0.153 J, and rang."""
    import mpm
    hertz = load("hertz")
    model, state = mpm.build(hertz.scene(2, "collider", 48, 0.02), mpm.QUADRATIC, "float64", device)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=mpm.INTEGRATORS["implicit"]()))
    rows = []  # per step: the work before it, the elastic energy at its start, the kinetic energy after it

    class Energy(mpm.Observer):
        work = 0.0

        def on_step(self, driver, report):
            rows.append((self.work, report.elastic, report.kinetic))
            self.work += report.boundary_work

    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=0.16, dt=2e-3), observers=[Energy()])
    assert driver.run().status == "completed"
    work, elastic, kinetic = np.array(rows).T
    stored = elastic[1:] + kinetic[:-1]  # at the start of each step after the first
    assert np.all(stored <= 1.01 * work[1:] + 1e-9), np.c_[work[1:], stored][::10]
    assert elastic[-1] > 0.8 * work[-1], (elastic[-1], work[-1])
