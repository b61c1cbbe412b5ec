"""External loads (mpm.loads): what a load resolves to on the particles, the
impulse it gives in every scheme and both integrators, its profiles, the
work the blow-up detection counts, and a wave that a suddenly applied end
traction sends along a bar (mpm.beams.bar_wave)."""

import math

import numpy as np
import pytest

import mpm
from mpm.beams import bar_wave
from mpm.loads import POINT_REACH, Load

QUADRATIC = mpm.KERNELS["quadratic"]
STEEL_LIKE = dict(E=1.0e4, nu=0.0, rho=100.0)  # c = 10 m/s


def bar_scene(loads, dim=2, resolution=32, gravity=None, ppc=None, regions=()):
    """A bar 0.5 m long and 0.1 m high (0.1 m deep in 3D), free in the middle of the domain."""
    centre = (0.5, 0.25, 0.25)[:dim]
    half = (0.25, 0.05, 0.05)[:dim]
    return mpm.Scene(dim=dim, domain=(1.0, 0.5, 0.5)[:dim], resolution=resolution, ppc=ppc or 2**dim,
                     gravity=gravity or (0.0,) * dim,
                     bodies=[mpm.Body(mpm.Box(centre, half), mpm.FixedCorotated(**STEEL_LIKE), name="bar")],
                     walls=("slip",) * (2 * dim), loads=list(loads), regions=list(regions))


def tip_face(dim=2):
    """A box holding the bar's right end (x = 0.75 m)."""
    return mpm.Box((0.75, 0.25, 0.25)[:dim], (0.03, 0.1, 0.1)[:dim])


# ------------------------------------------------------------------ resolution on the particles
@pytest.mark.parametrize("dim", [2, 3])
def test_traction_is_carried_by_the_face_with_its_area(dim):
    """A traction t on the end face of a lattice-sampled box: one layer of
    particles, sum A_p = the face's area (H in 2D, H W in 3D) to round-off
    (H = 3.2 sampling spacings: 4 rows of particles whose volumes share
    the box's), total force t times the area; the normal picks the face.
    The top face, 16 spacings long, gets 0.8 of its area (the rows'
    volumes scaled by 3.2 / 4 across it): the documented limit of sum V_p / s,
    which the load's ``area`` mends."""
    t = (0.0, -3.0, 0.0)[:dim]
    top = mpm.Box((0.5, 0.25, 0.25)[:dim], (0.3, 0.1, 0.1)[:dim])
    up = (0.0, 1.0, 0.0)[:dim]
    scene = bar_scene([Load("traction", t, select=tip_face(dim), normal=(1.0,) + (0.0,) * (dim - 1)),
                       Load("traction", t, select=top, normal=up),
                       Load("traction", t, select=top, normal=up, area=0.5 if dim == 2 else 0.05)],
                      dim=dim, resolution=16)
    model, state = mpm.build(scene, QUADRATIC, "float64")
    end, top, stated = model.loads.summary
    area = 0.1 if dim == 2 else 0.1 * 0.1
    assert end["area"] == pytest.approx(area, rel=1e-12)
    assert np.allclose(end["total_force"], np.asarray(t) * area, rtol=1e-12, atol=0.0)
    x = state.x.numpy()
    members = model.loads.members(0)
    assert np.allclose(x[members, 0], x[:, 0].max())  # the outermost layer only
    top_area = 0.5 if dim == 2 else 0.5 * 0.1
    assert top["area"] == pytest.approx(0.8 * top_area, rel=1e-12)
    assert stated["area"] == pytest.approx(top_area, rel=1e-12)
    assert np.allclose(stated["total_force"], np.asarray(t) * top_area, rtol=1e-12, atol=0.0)


def test_point_and_body_loads_share_their_totals():
    """A point load on the n particles nearest a point shares F in proportion
    to their volumes (sum = F); a body force b on a region gives b times
    the volume of its particles, the whole body's volume without a region."""
    F = (0.0, -2.0)
    scene = bar_scene([Load("point", F, at=(0.75, 0.25), count=3),
                       Load("body", (0.0, -10.0)), Load("body", (5.0, 0.0), select=mpm.Box((0.375, 0.25), (0.125, 0.1)))])
    model, state = mpm.build(scene, QUADRATIC, "float64")
    point, whole, half = model.loads.summary
    assert point["particles"] == 3
    assert np.allclose(point["total_force"], F, rtol=1e-12)
    assert whole["volume"] == pytest.approx(0.5 * 0.1, rel=1e-12)
    assert np.allclose(whole["total_force"], (0.0, -10.0 * 0.05), rtol=1e-12)
    assert half["volume"] == pytest.approx(0.25 * 0.1, rel=1e-12)  # the lattice rows inside x < 0.5


def test_a_point_load_near_its_body_is_taken_and_one_off_it_refused():
    """``at`` within POINT_REACH cells of the body's nearest particle loads the
    nearest particles; farther it is refused naming ``at``, the distance and
    the reach (it would load whatever particles are nearest)."""
    dx = 1.0 / 32
    edge = 0.75 - 0.25 * dx  # the bar's last particles (ppc 4: a quarter cell in)
    near = mpm.build(bar_scene([Load.point((1.0, 0.0), at=(edge + 1.9 * dx, 0.25), count=2)]), QUADRATIC)[0]
    assert near.loads.summary[0]["particles"] == 2
    with pytest.raises(mpm.SceneError) as e:
        mpm.build(bar_scene([Load.point((1.0, 0.0), at=(edge + 2.1 * dx, 0.25), count=2)]), QUADRATIC)
    assert e.value.key == "loads[0].at" and "from the nearest particle of any body" in str(e.value)
    assert f"within {POINT_REACH:g} cells" in str(e.value)


def test_profiles():
    """Constant, ramp and table profiles inside their window, 0 outside."""
    f = (1.0, 0.0)
    assert Load("point", f, at=(0, 0), start=0.5).factor(0.4) == 0.0
    assert Load("point", f, at=(0, 0), start=0.5).factor(0.5) == 1.0
    assert Load("point", f, at=(0, 0), end=1.0).factor(1.0) == 0.0
    assert Load("point", f, at=(0, 0), ramp=2.0, start=1.0).factor(2.0) == pytest.approx(0.5)
    assert Load("point", f, at=(0, 0), ramp=2.0).factor(5.0) == 1.0
    table = Load("point", f, at=(0, 0), table=((0.0, 0.0), (1.0, 2.0), (1.0, -1.0), (3.0, 0.0)))
    assert [table.factor(t) for t in (0.5, 0.999, 1.0, 2.0, 9.0)] == pytest.approx([1.0, 1.998, -1.0, -0.5, 0.0])


@pytest.mark.parametrize("load, key", [
    (Load("pull", (1.0, 0.0), at=(0.5, 0.25)), "loads[0].kind"),
    (Load("point", (1.0, 0.0, 0.0), at=(0.5, 0.25)), "loads[0].force"),
    (Load("point", (1.0, math.nan), at=(0.5, 0.25)), "loads[0].force"),
    (Load("point", (1.0, 0.0)), "loads[0].at"),
    (Load("point", (1.0, 0.0), at=(0.5, 0.25), count=0), "loads[0].count"),
    (Load("traction", (1.0, 0.0), select=tip_face()), "loads[0].normal"),
    (Load("traction", (1.0, 0.0), normal=(1.0, 0.0)), "loads[0].select"),
    (Load("traction", (1.0, 0.0), select=tip_face(), normal=(0.0, 0.0)), "loads[0].normal"),
    (Load("body", (1.0, 0.0), table=((1.0, 0.0), (0.5, 1.0))), "loads[0].table"),
    (Load("body", (1.0, 0.0), start=1.0, end=1.0), "loads[0].end"),
    (Load("body", (1.0, 0.0), body=3), "loads[0].body"),
    (Load("body", (1.0, 0.0), select=mpm.Box((0.1, 0.1), (0.01, 0.01))), "loads[0].select"),
    (Load("point", (1.0, 0.0), at=(1.5, 0.25)), "loads[0].at"),  # outside the domain
    (Load("point", (1.0, 0.0), at=(0.95, 0.25)), "loads[0].at"),  # 0.2 m (6.4 cells) off the bar's end
    (Load("point", (1.0, 0.0), at=(0.5, 0.4), body=0), "loads[0].at"),  # 0.1 m above it
])
def test_a_bad_load_is_refused_naming_its_field(load, key):
    with pytest.raises(mpm.SceneError) as e:
        mpm.build(bar_scene([load]), QUADRATIC)
    assert e.value.key == key, str(e.value)


# ------------------------------------------------------------------ the impulse, every scheme and integrator
@pytest.mark.parametrize("scheme, integrator, transfer", [
    ("empm", "explicit", "mls"), ("tlmpm", "explicit", "mls"), ("aulmpm", "explicit", "mls"),
    ("empm", "implicit", "mls"), ("tlmpm", "implicit", "apic"), ("empm", "explicit", "flip"),
    ("tlmpm", "explicit", "flip"), ("tlmpm", "explicit", "pic")])
def test_momentum_gained_is_the_loads_impulse(scheme, integrator, transfer):
    """A free body (no gravity, no wall reached): every transfer conserves
    momentum, so after n steps sum_p m_p v_p = sum_n dt F(t_n), the loads'
    total force at each step's start (the profiles evaluated on the device
    against Load.factor on the host), to float64 round-off."""
    loads = [Load("traction", (0.0, -40.0), select=tip_face(), normal=(1.0, 0.0),
                  table=((0.0, 0.0), (0.002, 1.0), (0.004, -0.5))),
             Load("point", (3.0, 1.0), at=(0.3, 0.25), count=2, start=0.001, end=0.003),
             Load("body", (0.0, 20.0), ramp=0.003)]
    model, state = mpm.build(bar_scene(loads, resolution=32), QUADRATIC, "float64")  # (the walls out of reach)
    implicit = integrator == "implicit"
    opts = mpm.SolverOptions(integrator=mpm.Implicit(newton_tol=1e-10) if implicit else mpm.Explicit(),
                             transfer=transfer)
    solver = mpm.Solver(model, {"empm": mpm.EMPM, "tlmpm": mpm.TLMPM, "aulmpm": mpm.AULMPM}[scheme](), opts)
    solver.prepare(state)
    impulse = np.zeros(2)
    dt = 2.5e-4
    for n in range(24):
        impulse += dt * model.loads.force(solver.time)
        report = solver.advance(state, dt)
        assert report.reason is None
    momentum = (model.mass.numpy()[:, None] * state.v.numpy()).sum(axis=0)
    scale = np.abs(model.loads.entry_force).sum() * dt * 24
    assert np.allclose(momentum, impulse, rtol=0.0, atol=1e-10 * scale), (momentum, impulse)
    assert np.abs(impulse).max() > 0.1 * scale  # (the loads did push)


def test_detection_counts_the_loads_work():
    """A constant force on a free body puts in kinetic energy F^2 t^2 / 2M;
    the blow-up detection counts the loads' work (mpm.stepping.detection), so a
    run gaining many times its initial energy is not stopped, and the work
    it counted matches the kinetic energy F^2 t^2 / 2M to 1e-3."""
    scene = bar_scene([Load("body", (200.0, 0.0))])
    model, state = mpm.build(scene, QUADRATIC, "float64")
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(track_energy=True))
    driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=200, dt=1e-4), mpm.Detection(action="stop"))
    outcome = driver.run()
    assert outcome.status == "completed", outcome.reason
    M = float(model.mass.numpy().sum())
    F = 200.0 * 0.05
    t = driver.time
    kinetic = 0.5 * F**2 * t**2 / M
    # each step's work dt f . (v + v') / 2 is exact for a body moving rigidly; the stress waves the
    # force excites move energy between kinetic and elastic
    assert driver.detector.work == pytest.approx(kinetic, rel=1e-3)


# ------------------------------------------------------------------ a wave along a bar
@pytest.mark.parametrize("scheme", ["empm", "tlmpm"])
def test_sudden_end_traction_sends_a_wave(scheme):
    """A traction sigma applied suddenly at t = 0 on the right end of a bar
    at rest (nu = 0: a 1D bar): the front travels at c = sqrt(E / rho) and
    the particles behind it move at sigma / (rho c) (mpm.beams.bar_wave).
    At t = 0.6 L / c: the particles more than 3 cells behind the front
    move at that speed within 5 % (measured: 1.7 % fast; the MPM front
    spreads over a few cells and overshoots by 11 %), the particles within
    half a cell of the front at 25-75 % of it (the front arrives at c t;
    measured 41 %), those more than 3 cells ahead are at rest within 5 %
    of it (3.4 %), and the loaded end moved sigma t / (rho c) within 3 %
    (0.6 % short)."""
    sigma = 20.0
    ref = bar_wave(sigma, **STEEL_LIKE)
    c, L = ref["wave_speed"], 0.5
    scene = bar_scene([Load("traction", (sigma, 0.0), select=tip_face(), normal=(1.0, 0.0))], resolution=64)
    model, state = mpm.build(scene, QUADRATIC, "float64")
    X = state.x.numpy().copy()
    solver = mpm.Solver(model, {"empm": mpm.EMPM, "tlmpm": mpm.TLMPM}[scheme](), mpm.SolverOptions(track_energy=True))
    driver = mpm.Driver(solver, state, mpm.StepPolicy(duration=0.6 * L / c), mpm.Detection(action="stop"))
    assert driver.run().status == "completed"
    t, dx = driver.time, model.dx
    xi = 0.75 - X[:, 0]  # distance from the loaded end
    front = c * t
    v = state.v.numpy()[:, 0]
    behind, ahead = xi < front - 3 * dx, xi > front + 3 * dx
    assert np.mean(v[behind]) == pytest.approx(ref["velocity"], rel=0.05)
    assert 0.25 < np.mean(v[np.abs(xi - front) < 0.5 * dx]) / ref["velocity"] < 0.75
    assert np.abs(v[ahead]).max() < 0.05 * ref["velocity"]
    end = model.loads.members(0)
    moved = float(np.mean(state.x.numpy()[end, 0] - X[end, 0]))
    assert moved == pytest.approx(ref["velocity"] * t, rel=0.03)


def test_the_speed_criterion_allows_for_the_loads():
    """A free body under a force F can reach sqrt(2 F / M H) crossing the
    domain (H its largest extent, 1 m); the detection takes the load's
    acceleration F / M like gravity's, so its speed limit is speed_factor
    (c + sqrt(2 F / M H)) (c = 10 m/s, g = 0). At F / M = 2e5 m/s^2 that is
    above the reachable 632 m/s, where the limit without the load,
    speed_factor c = 100 m/s, is not."""
    M = 100.0 * 0.05  # [kg/m] the bar's mass
    a = 2.0e5  # [m/s^2]
    scene = bar_scene([Load("body", (a * M / 0.05, 0.0))], resolution=16)
    model, state = mpm.build(scene, QUADRATIC, "float64")
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(track_energy=True))
    driver = mpm.Driver(solver, state, mpm.StepPolicy(steps=3, dt=1e-6), mpm.Detection(action="stop"))
    assert driver.run().status == "completed"
    assert model.loads.acceleration([M]) == pytest.approx(a, rel=1e-12)
    limit = driver.detector.speed_limit(0, 1.0, 0.0)
    reachable = math.sqrt(2.0 * a * 1.0)
    assert limit == pytest.approx(10.0 * (10.0 + reachable), rel=1e-9)
    assert limit > reachable > 10.0 * 10.0
