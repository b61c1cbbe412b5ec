"""Early detection of blow-ups (mpm.stability): an unstable step is caught
before any value is non-finite, stable runs never trip it, the work of
gravity and of kinematic regions is not mistaken for a blow-up, inversion
of a model that cannot invert is named, and ``warn`` lets the run go on."""

import numpy as np
import pytest

import mpm
from helpers import DEVICE, compose_cfg, group_options, spec_for
from mpm.integrators import Implicit
from pipelines.run.runner import execute
from pipelines.recording.sinks import Sink
from pipelines.config.validate import ConfigError, resolve

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


@pytest.mark.parametrize("override, key", [("detect.action=halt", "detect.action"),
                                           ("detect.energy_growth=0", "detect.energy_growth"),
                                           ("detect.min_J=1.5", "detect.min_J")])
def test_bad_detection_options_are_refused(override, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        resolve(compose_cfg([override]))


# ---------------------------------------------------------------------- maps and the suite
@pytest.mark.parametrize("scale", ["default", "paper"])
@pytest.mark.parametrize("case", group_options("extreme"))
def test_every_extreme_case_resolves(case, scale):
    """Each case of the suite composes with the experiment at both scales,
    validates, and states its expected outcome."""
    cfg = compose_cfg(["+experiment=extreme", f"+extreme={case}", f"scale={scale}"])
    assert cfg.expected and len(cfg.expected) > 20
    spec = resolve(cfg)
    assert spec.stability_map is None


def test_map_job_runs_its_points(tmp_path):
    """A stability-map job (pipelines.sweeps.stability.run_map): every point runs at
    k times the CFL limit of its stiffness; below the limit the point
    completes, far above it the point stops unstable with its step and
    criterion; the job's metrics.json holds the map and the points' own
    metrics are not jobs of the sweep."""
    from pipelines.report.jobs import load_jobs
    from pipelines.report.sections.stability import largest_stable
    from pipelines.sweeps.stability import run_map
    from pipelines.config.validate import MapSpec

    spec = spec_for(["scene=stability_ball_2d"])
    m = run_map(spec, MapSpec(E=[1e4, 1e8], dt_cfl=[0.5, 5.0], steps=10), tmp_path, {"config_hash": "h"})
    points = m["stability_map"]["points"]
    assert [(p["E"], p["k"]) for p in points] == [(1e4, 0.5), (1e4, 5.0), (1e8, 0.5), (1e8, 5.0)]
    for p in points:
        lam_2mu = p["E"] * 0.7 / (1.3 * 0.4)  # lambda + 2 mu at nu = 0.3
        c = np.sqrt(lam_2mu / 1000.0)  # P-wave speed [m/s]
        assert p["dt"] == pytest.approx(p["k"] * (1.0 / 32) / (c + 1.0))  # dx / (c + v0), v0 = 1 m/s
        if p["k"] < 1:
            assert p["status"] == "completed" and p["steps"] == 10
        else:
            assert p["status"] == "unstable" and 1 <= p["unstable_step"] < 10 and p["criterion"]
    assert largest_stable(points, 1e4) == 0.5
    assert m["status"] == "completed" and m["config_hash"] == "h"
    assert (tmp_path / "points" / "E10000_k0.5" / "point.json").is_file()
    jobs, _ = load_jobs(tmp_path)
    assert [j.rel for j in jobs] == ["."]


def _map_job(root, name, kernel, rows):
    from test_report import _job

    m = {"status": "completed", "reason": "", "steps": 10, "sim_time": 0.0, "scene": "stability_ball_2d",
         "scheme": "empm", "kernel": kernel, "transfer": "mls", "integrator": "explicit",
         "config_hash": name,
         "stability_map": {"E": [1e3, 1e6], "dt_cfl": [0.5, 1.0, 2.0], "steps": 10, "points": rows}}
    return _job(root, name, m, ["scene=stability_ball_2d", f"kernel={kernel}", "+experiment=stability"])


def _point(E, k, status, step=None, criterion=None):
    return {"E": E, "k": k, "dt": k * 1e-4, "status": status, "steps": 10 if step is None else step,
            "unstable_step": step, "criterion": criterion, "body": None, "reason": "", "wall_time_s": 0.1}


def test_report_reads_a_synthetic_stability_sweep(tmp_path):
    """Two maps and two extreme-suite jobs: stability.md tabulates the
    largest stable multiple per combination and stiffness (a failure
    below a stable point counts), draws the heat maps, and lists the suite
    with the outcome and the expected text."""
    import json

    from pipelines.report import write_report
    from test_report import _job

    ok, bad = "completed", "unstable"
    _map_job(tmp_path, "a", "quadratic", [
        _point(1e3, 0.5, ok), _point(1e3, 1.0, ok), _point(1e3, 2.0, bad, 3, "energy"),
        _point(1e6, 0.5, ok), _point(1e6, 1.0, bad, 5, "speed"), _point(1e6, 2.0, ok)])
    _map_job(tmp_path, "b", "cubic", [
        _point(1e3, 0.5, bad, 1, "outside"), _point(1e3, 1.0, ok), _point(1e3, 2.0, ok),
        _point(1e6, 0.5, ok), _point(1e6, 1.0, ok), _point(1e6, 2.0, ok)])
    for scheme, status in (("empm", "completed"), ("tlmpm", "unstable")):
        m = {"status": status, "reason": "", "steps": 40, "sim_time": 0.01, "scene": "elastic_ball_2d",
             "scheme": scheme, "kernel": "quadratic", "transfer": "mls", "config_hash": f"x{scheme}",
             "energy_initial": 10.0, "energy_final": 9.0, "fracture": {"total": 0.25},
             "detect": {"energy_scale": 4.0, "energy_growth_max": 0.0},
             "unstable_criterion": "inversion", "unstable_step": 7}
        d = _job(tmp_path, f"x{scheme}", m, ["+extreme=inverted_start", f"scheme={scheme}",
                                             "+experiment=extreme"])
        (d / ".hydra" / "config.yaml").write_text("expected: recovers from the inversion\n"
                                                  "scene: {name: elastic_ball_2d}\n")
    write_report(tmp_path)
    text = (tmp_path / "stability.md").read_text()
    assert "| empm · quadratic · mls · explicit | 1 | 0.5 |" in text
    assert "| empm · cubic · mls · explicit | <0.5 | 2 |" in text
    assert (tmp_path / "stability_stability_ball_2d.png").stat().st_size > 10_000
    assert "| inverted_start | empm | completed | 40 | 0.01 | -0.25 | 0 | 0.25 |" in text
    assert "| inverted_start | tlmpm | unstable (inversion, step 7) |" in text
    assert "- `inverted_start`: recovers from the inversion" in text
    rows = (tmp_path / "stability.csv").read_text().splitlines()
    assert len(rows) == 1 + 12
    assert "Stability maps" in (tmp_path / "report.md").read_text()
    assert json.loads((tmp_path / "a" / "metrics.json").read_text())["stability_map"]["steps"] == 10


def test_initial_deformation_and_lattice_offset(tmp_path):
    """Scene options of the suite: ``lattice_offset`` (0.5, 0.5) with one
    particle per cell puts every particle on a grid node; a body's
    ``deformation`` places it deformed with F as its elastic state. A ball
    reflected by F = diag(-1, 1) (det F = -1): fixed corotated, defined for
    inverted F, runs its first 40 steps with no criterion firing (what
    follows is the extreme suite's business); neo-Hookean (log J) is
    stopped before its first step by the inversion criterion."""
    over = ["+extreme=inverted_start", "run.steps=40"]
    spec = spec_for(over)
    model, state = mpm.build(spec.scene, spec.kernel, "float64", DEVICE)
    F = state.F0s.numpy()
    assert np.allclose(np.linalg.det(F), -1.0)
    x, c = state.x.numpy(), np.array([0.5, 0.5])
    assert np.allclose(np.sort((x - c)[:, 0]), np.sort(-(x - c)[:, 0]))  # the ball is its own mirror image
    m = execute(spec, tmp_path / "fc", sink=Sink())
    assert m["status"] == "completed" and m["detect"]["fired"] == []
    nh = execute(spec_for(over + ["material=neo_hookean"]), tmp_path / "nh", sink=Sink())
    assert nh["unstable_criterion"] == "inversion" and nh["unstable_step"] == 0  # the initial state

    nodes = spec_for(["+extreme=particles_on_nodes_float32"])
    model, state = mpm.build(nodes.scene, nodes.kernel, "float32", DEVICE)
    x = state.x.numpy() / model.dx
    assert np.abs(x - np.round(x)).max() < 1e-5 and len(x) == 8 * 8  # one per cell of the 8 x 8-cell box


def test_linear_bound_of_the_lumped_hat_kernel_is_the_cfl_number_one():
    """pipelines.cfl_bound against the closed form: linear elements with
    lumped mass have omega_max = 2 c / dx, i.e. k* = 1 exactly, in 1D and
    2D, with MLS or gradient weights; the smoother B-splines allow more
    (quadratic sqrt(3) in 1D with the exact gradient on a fine periodic
    lattice, within the lattice's resolution of the highest mode)."""
    from pipelines.cfl_bound import bound

    for dim in (1, 2):
        for mls in (True, False):
            assert bound("linear", mls, dim=dim, cells=8) == pytest.approx(1.0, rel=1e-9)
    assert bound("quadratic", False, dim=1, cells=40) == pytest.approx(np.sqrt(3.0), rel=1e-3)
    assert bound("linear", dim=1) < bound("quadratic", dim=1) < bound("cubic", dim=1)


def test_detector_criteria_on_synthetic_reports():
    """mpm.stability.Detector alone: the speed limit is speed_factor (c_b +
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
        return SimpleNamespace(boundary_work=0.0, min_J=np.array([J, J]), stiffening=np.zeros(2),
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
