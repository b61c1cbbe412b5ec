"""Early detection of blow-ups (mpm.stability): an unstable step is caught
before any value is non-finite, stable runs never trip it, the work of
gravity and of kinematic regions is not mistaken for a blow-up, inversion
of a model that cannot invert is named, and ``warn`` lets the run go on."""

import numpy as np
import pytest

import mpm
from helpers import compose_cfg, spec_for
from mpm.integrators import Implicit
from pipelines.runner import execute
from pipelines.sinks import Sink
from pipelines.validate import ConfigError, resolve

BALL = ["scene.resolution=24", "log.every=0"]  # the default elastic ball (slip walls, gravity), small


def cfl_limit(spec) -> float:
    """The explicit step limit dx / c [s] (CFL number 1) of the scene at rest."""
    model, _ = mpm.build(spec.scene, spec.kernel, "float32", "cpu")
    return model.dx / spec.scene.bodies[0].material.wave_speed()


def nonfinite_step(spec, dt: float, steps: int = 40) -> int:
    """The first step after which a value is non-finite, stepping on through
    particles leaving the domain (no detection: the plain solver)."""
    model, state = mpm.build(spec.scene, spec.kernel, "float32", "cpu")
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
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", "cpu")
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
    detector = mpm.Detector(options, scene, solver.boundary_speed(), 0.0, model.kernel.n_grids,
                            float(model.mass.numpy().sum()))
    blind = mpm.Detector(options, scene, solver.boundary_speed(), 0.0, model.kernel.n_grids,
                         float(model.mass.numpy().sum()))
    names = solver.diagnostic_names()
    dt = (1.0 if integrator.name == "explicit" else 10.0) * solver.stable_dt(0.4, max_speed=0.2)
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
    the ball (det F <= 0) before the energy criterion; fixed corotated, which
    inverts gracefully, is not checked for it."""
    over = BALL + ["material=neo_hookean"]
    dt = 5.0 * cfl_limit(spec_for(over))
    m = execute(spec_for(over + [f"run.dt={dt}"]), tmp_path / "nh", sink=Sink())
    assert m["unstable_criterion"] == "inversion" and m["unstable_body"] == "ball", m["reason"]
    fc = execute(spec_for(BALL + [f"run.dt={dt}"]), tmp_path / "fc", sink=Sink())
    assert fc["unstable_criterion"] != "inversion"


@pytest.mark.parametrize("override, key", [("detect.action=halt", "detect.action"),
                                           ("detect.energy_growth=0", "detect.energy_growth"),
                                           ("detect.min_J=1.5", "detect.min_J")])
def test_bad_detection_options_are_refused(override, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        resolve(compose_cfg([override]))
