"""Early detection of blow-ups (mpm.stepping.detection): an unstable step is caught
before any value is non-finite, stable runs never trip it, the work of
gravity and of kinematic regions is not mistaken for a blow-up, inversion
of a model that cannot invert is named, and ``warn`` lets the run go on."""

import dataclasses
import numpy as np
import pytest

import mpm
from helpers import DEVICE, spec_for
from mpm.integrators import Implicit
from pipelines.run.runner import execute
from pipelines.recording.sinks import Sink

BALL = ["scene.resolution=24", "log.every=0"]  # the default elastic ball (slip walls, gravity), small


def cfl_limit(spec) -> float:
    """The explicit step limit dx / c [s] (CFL number 1) of the scene at rest."""
    model, _ = mpm.build(spec.scene, spec.kernel, "float32", DEVICE)
    return model.dx / spec.scene.bodies[0].material.wave_speed()


def nonfinite_step(spec, dt: float, steps: int = 40) -> int:
    """The first step after which a value is non-finite, stepping on through
    particles leaving the domain (no detection: the plain solver)."""
    model, state = mpm.build(spec.scene, spec.kernel, "float32", DEVICE)
    solver = mpm.Solver(model, spec.scheme)
    solver.prepare(state)
    for k in range(1, steps + 1):
        report = solver.advance(state, dt)
        if report.nonfinite:
            return k
    raise AssertionError(f"no non-finite value in {steps} steps")


def test_five_times_the_cfl_step_stops_on_energy_before_nan(tmp_path):
    """dt = 5 dx / c: the energy criterion stops the run at a step where
    every value is still finite, earlier than the step at which the same
    run without detection turns non-finite; the metrics name the
    criterion, step and time. With detect.action=warn the run goes on and
    records the warning; with off, it stops only when particles leave."""
    spec = spec_for(BALL)
    dt = 5.0 * cfl_limit(spec)
    m = execute(spec_for(BALL + [f"run.dt={dt}"]), tmp_path / "stop", sink=Sink())
    assert m["status"] == "unstable" and m["unstable_criterion"] == "energy", m["reason"]
    assert m["unstable_body"] is None and m["unstable_step"] == m["steps"]
    assert m["unstable_time"] == pytest.approx(m["steps"] * dt)
    assert "energy" in m["detect"]["fired"] and m["detect"]["energy_growth_max"] > 0.5
    assert np.isfinite(m["energy_final"])
    assert m["unstable_step"] < nonfinite_step(spec, dt)

    warned = execute(spec_for(BALL + [f"run.dt={dt}", "detect.action=warn"]), tmp_path / "warn", sink=Sink())
    assert warned["unstable_criterion"] in ("outside", "nonfinite")
    assert {w["criterion"] for w in warned["detect_warnings"]} >= {"energy"}
    off = execute(spec_for(BALL + [f"run.dt={dt}", "detect.action=off"]), tmp_path / "off", sink=Sink())
    assert off["unstable_criterion"] in ("outside", "nonfinite") and "detect" not in off


@pytest.mark.parametrize("scheme", ["empm", "tlmpm", "aulmpm"])
def test_stable_ball_never_trips(tmp_path, scheme):
    """The elastic ball falls under gravity, hits the slip floor and bounces
    for 2 s at the adaptive step: gravity's work is the potential's change,
    the walls only take energy out, so the energy never grows beyond its
    start (growth <= 0 up to round-off) and no criterion fires."""
    m = execute(spec_for(BALL + [f"scheme={scheme}", "run.duration=2.0"]), tmp_path, sink=Sink())
    assert m["status"] == "completed", m["reason"]
    assert m["detect"]["fired"] == []
    assert m["detect"]["energy_growth_max"] <= 1e-3


def pulled_bar(integrator):
    """A bar clamped at its top by a kinematic region and pulled down at its
    bottom by another at 0.2 m/s (no gravity: the regions' work is all the
    energy there is)."""
    top = mpm.KinematicRegion(body=0, select=mpm.Box((0.5, 0.79), (0.05, 0.06)))
    bottom = mpm.KinematicRegion(body=0, select=mpm.Box((0.5, 0.41), (0.05, 0.06)), velocity=(0.0, -0.2))
    bar = mpm.Body(mpm.Box((0.5, 0.6), (0.03, 0.25)), mpm.NeoHookean(E=2e4, nu=0.3))
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, bodies=[bar], gravity=(0.0, 0.0),
                      walls=("slip",) * 4, regions=[top, bottom], ppc=4)
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", DEVICE)
    solver = mpm.Solver(model, mpm.EMPM(), mpm.SolverOptions(integrator=integrator, track_J=True))
    solver.prepare(state)
    return scene, model, solver, state


@pytest.mark.parametrize("integrator", [mpm.Explicit(), Implicit()], ids=["explicit", "implicit"])
def test_work_of_a_kinematic_region_is_not_a_blow_up(integrator):
    """The pulled bar stores the region's work as elastic energy: counted as
    the boundaries' work W_in, nothing fires; the same energies without
    W_in would read as growth beyond the threshold (so the accounting is
    what keeps the criterion quiet). The region's speed enters the speed
    limit."""
    scene, model, solver, state = pulled_bar(integrator)
    options = mpm.Detection()
    detector = mpm.Detector(options, scene, solver.conditions.speed(), 0.0, model.kernel.n_grids,
                            float(model.mass.numpy().sum()))
    blind = mpm.Detector(options, scene, solver.conditions.speed(), 0.0, model.kernel.n_grids,
                         float(model.mass.numpy().sum()))
    names = solver.diagnostics.names
    dt = (1.0 if integrator.name == "explicit" else 10.0) * solver.timestep.stable_dt(0.4, max_speed=0.2)
    blind_trips = []
    for _ in range(int(0.5 / dt)):
        d = solver.measure(state)
        energies = [float(d[names.index(k)]) for k in ("kinetic_energy", "elastic_energy", "potential_energy")]
        assert detector.energy(*energies) == []
        blind_trips += blind.energy(*energies)
        report = solver.advance(state, dt)
        assert report.reason is None
        assert detector.step(report) == []
    assert detector.work > 0.5 * detector.scale  # the region did work of the order of the energy in play
    assert [t.criterion for t in blind_trips] == ["energy"]  # blind: the same energies without W_in


def test_inversion_of_a_model_that_cannot_invert_is_named(tmp_path):
    """Neo-Hookean (log J) at 5x the CFL step: the run stops on inversion of
    the ball (det F <= 0) before the energy criterion, and the recording's
    last event names the criterion and the body; fixed corotated, which
    inverts gracefully, is not checked for it."""
    over = BALL + ["material=neo_hookean"]
    dt = 5.0 * cfl_limit(spec_for(over))
    m = execute(spec_for(over + [f"run.dt={dt}"]), tmp_path / "nh")  # with its recording
    assert m["unstable_criterion"] == "inversion" and m["unstable_body"] == "ball", m["reason"]
    from rerun.chunk import RrdReader

    events = RrdReader(str(tmp_path / "nh" / "recording.rrd")).store().stream().collect().reader(
        index="step", contents="/events").to_pandas()
    last = events.iloc[-1]
    assert int(last["step"]) == m["unstable_step"]
    assert list(last["/events:criterion"]) == ["inversion"] and list(last["/events:body"]) == ["ball"]
    fc = execute(spec_for(BALL + [f"run.dt={dt}"]), tmp_path / "fc", sink=Sink())
    assert fc["unstable_criterion"] != "inversion"


def test_initial_deformation_and_lattice_offset(tmp_path):
    """Scene options of the suite: ``lattice_offset`` (0.5, 0.5) with one
    particle per cell puts every particle on a grid node; a body's
    ``deformation`` F samples the particles in the shape and places them at
    x = c + F (X - c) with F as their elastic state, and an inverted
    (det F <= 0) or degenerate (a singular value below
    mpm.model.MIN_INITIAL_STRETCH) F is refused before anything is built.
    The ball compressed by F = diag(0.1, 1) springs back: its first 40 steps
    fire no criterion."""
    over = ["+extreme=compressed_start", "run.steps=40"]
    spec = spec_for(over)
    model, state = mpm.build(spec.scene, spec.kernel, "float64", DEVICE)
    F = np.diag([0.1, 1.0])
    assert np.allclose(state.F0s.numpy(), F)
    x, c = state.x.numpy(), np.array([0.5, 0.5])
    X = (x - c) @ np.linalg.inv(F).T  # back in the reference ball
    assert np.linalg.norm(X, axis=1).max() < 0.15 and np.linalg.norm(X, axis=1).max() > 0.15 - model.dx
    m = execute(spec, tmp_path / "fc", sink=Sink())
    assert m["status"] == "completed" and m["detect"]["fired"] == []
    for bad in ([[-1.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 5e-4]], [[0.0, 1.0], [1.0, 0.0]]):
        scene = dataclasses.replace(spec.scene, bodies=[dataclasses.replace(spec.scene.bodies[0], deformation=bad)])
        with pytest.raises(mpm.SceneError, match=r"bodies\[0\]\.deformation: .*det F > 0"):
            mpm.build(scene, spec.kernel, "float64", DEVICE)

    nodes = spec_for(["+extreme=particles_on_nodes_float32"])
    model, state = mpm.build(nodes.scene, nodes.kernel, "float32", DEVICE)
    x = state.x.numpy() / model.dx
    assert np.abs(x - np.round(x)).max() < 1e-5 and len(x) == 8 * 8  # one per cell of the 8 x 8-cell box


def test_detector_criteria_on_synthetic_reports():
    """mpm.stepping.detection.Detector alone: the speed limit is speed_factor (c_b +
    u_boundary + sqrt(v0^2 + 2 |g| H)); a degenerate F (a singular value
    below min_stretch) or det F <= min_J trips inversion only for a model
    that cannot invert; each criterion is reported once; the energy
    criterion compares with the scale of the earlier states."""
    from types import SimpleNamespace

    bodies = [mpm.Body(mpm.Sphere((0.3, 0.5), 0.1), mpm.NeoHookean(E=1e4), name="soft"),
              mpm.Body(mpm.Sphere((0.7, 0.5), 0.1), mpm.FixedCorotated(E=1e4), name="fc")]
    scene = mpm.Scene(dim=2, domain=(1.0, 2.0), resolution=16, bodies=bodies, gravity=(0.0, -10.0))
    det = mpm.Detector(mpm.Detection(speed_factor=4.0), scene, boundary_speed=3.0, v0=1.0, n_grids=1,
                       total_mass=2.0)
    c = bodies[0].material.wave_speed()
    limit = 4.0 * (c + 3.0 + np.sqrt(1.0 + 2 * 10.0 * 2.0))

    def report(speed, J, stretch):
        return SimpleNamespace(boundary_work=0.0, load_work=0.0, min_J=np.array([J, J]), stiffening=np.zeros(2),
                               body_speed=np.array([speed, 0.0]), min_F_stretch=np.array([stretch, stretch]))

    assert det.speed_limit(0, 1.0, 0.0) == pytest.approx(limit)
    assert det.step(report(0.99 * limit, 0.5, 0.5)) == []
    trips = det.step(report(1.01 * limit, 0.5, 5e-4))
    assert [(t.criterion, t.body) for t in trips] == [("speed", "soft"), ("inversion", "soft")]
    assert det.step(report(2 * limit, -1.0, 0.0)) == []  # each criterion once
    fresh = mpm.Detector(mpm.Detection(), scene, 0.0, 0.0, 1, 2.0)
    assert [(t.criterion, t.body) for t in fresh.step(report(0.0, -0.1, 0.5))] == [("inversion", "soft")]
    assert fresh.energy(1.0, 1.0, 0.0) == []  # E0 = 2 J
    assert fresh.energy(0.5, 1.5, 0.0) == []  # exchanged, not grown
    trips = fresh.energy(2.0, 1.1, 0.0)  # grown by 1.1 J against the scale 2 J: 0.55 > 0.5
    assert [t.criterion for t in trips] == ["energy"] and trips[0].value == pytest.approx(0.55)


def test_a_crushed_reference_is_named_as_the_lagrangian_limit(tmp_path):
    """The soft ball (E = 1e3 Pa) hitting the floor: EMPM completes, while
    TLMPM's reference cells are crushed and its step collapses at step 125;
    the reason says it is the reference (its narrowest cell below
    mpm.stepping.driver.CRUSHED of its width) and, for TLMPM, that this is the
    method's limit, not a runaway flow."""
    over = ["scene=stability_ball_2d", "material.E=1e3", "run.duration=0.5", "log.every=0", "log.progress=false"]
    empm = execute(spec_for(over + ["scheme=empm"]), tmp_path / "empm", sink=Sink())
    assert empm["status"] == "completed", empm["reason"]
    tl = execute(spec_for(over + ["scheme=tlmpm"]), tmp_path / "tlmpm", sink=Sink())
    assert tl["status"] == "unstable" and tl["unstable_criterion"] == "dt_collapse"
    assert "a reference cell is crushed to " in tl["reason"] and "TLMPM never updates its reference" in tl["reason"]


def test_aulmpm_defaults_complete_the_soft_impact(tmp_path):
    """The same soft ball: A-ULMPM's solid defaults (stretch bound 0.5, C
    rotated over an update) update before a reference cell collapses and
    complete like EMPM; eq. 33 alone (10 % of the particles at dJ >= 0.5)
    never fires before TLMPM's collapse, and re-expressing C in the crushed
    reference (C (F^sn)^-1, |F^sn^-1| up to 1/s) blows it up. Measured with
    the floor of earlier versions (scene.boundary_rule=nodes), where the ball
    is crushed this way; on the floor where it touches, the transformed C
    completes."""
    over = ["scene=stability_ball_2d", "material.E=1e3", "run.duration=0.5", "log.every=0", "log.progress=false",
            "scheme=aulmpm", "scene.boundary_rule=nodes"]
    au = execute(spec_for(over), tmp_path / "defaults", sink=Sink())
    assert au["status"] == "completed", au["reason"]
    assert (au["affine"], au["config_updates"]["total"] > 0) == ("rotate", True)
    paper = execute(spec_for(over + ["scheme.criterion=paper"]), tmp_path / "paper", sink=Sink())
    assert paper["status"] == "unstable" and paper["unstable_criterion"] == "dt_collapse"
    assert "A-ULMPM's criterion did not update it in time" in paper["reason"]
    transform = execute(spec_for(over + ["scheme.affine=transform"]), tmp_path / "transform", sink=Sink())
    assert transform["status"] == "unstable", "C (F^sn)^-1 at a crushed particle no longer blows up"


def test_aulmpm_keeps_C_of_an_inverted_reference(tmp_path):
    """A point of the stability map (+experiment=stability): the soft ball
    with the linear kernel at a fixed 0.3 x dx / (c + v0), where EMPM and
    TLMPM complete. A-ULMPM updates it at almost every step after the impact
    (a particle squeezed below the stretch bound), some particles with an
    inverted F^sn; turning their C by the 'closest rotation' of an inverted
    F^sn (which flips a direction: no spin) made the energy grow until the
    run stopped at step 97. Keeping C there, the run completes. (On the
    floor of earlier versions, scene.boundary_rule=nodes, where the map was
    measured: on the floor where the ball touches, this point's energy grows
    at step 98 from another cause, open.)"""
    over = ["scene=stability_ball_2d", "scene.resolution=32", "material.E=1e3", "kernel=linear",
            "run.dt=0.0043397981854132416", "run.steps=100", "log.every=0", "log.progress=false", "scheme=aulmpm",
            "scene.boundary_rule=nodes"]
    au = execute(spec_for(over), tmp_path / "aulmpm", sink=Sink())
    assert au["status"] == "completed", au["reason"]
    assert au["affine"] == "rotate" and au["config_updates"]["total"] > 10
