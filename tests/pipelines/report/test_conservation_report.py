"""The conservation section: the linear momentum's drift of every run, net
of the gravity and boundary impulse the recording holds, and what it could
not net named."""

import csv
import json
import shutil

import pytest
import yaml
from omegaconf import OmegaConf

from helpers import compose_cfg
from pipelines.config.validate import resolve
from pipelines.report import write_report
from pipelines.report.sections.conservation import external_forces
from pipelines.run.runner import execute


@pytest.mark.parametrize("scene, expected", [
    ({"gravity": [0.0, 0.0], "walls": ["slip"] * 4}, []),
    ({"gravity": [0.0, -9.81]}, ["gravity"]),
    ({"gravity": [0.0, 0.0], "colliders": [{"type": "sphere"}], "regions": [{"type": "anchor"}],
      "loads": [{"type": "point"}]}, ["colliders", "kinematic regions", "loads"]),
    ({"gravity": [0, 0], "solution": {"type": "vortex"}}, ["body force"]),
    ({"gravity": [0, 0], "solution": {"type": "vibrating_bar"}}, []),  # an initial velocity, no force
    ({"gravity": [0, 0], "walls": ["slip", "open", "slip", "slip"]}, ["open walls"]),
])
def test_external_forces_are_read_from_the_config(scene, expected):
    assert external_forces({"scene": scene}) == expected
    assert external_forces(None) == ["unknown config"]


def _job(sweep, name, overrides):
    """A finished tiny run laid out as a sweep's job (its composed config in .hydra/)."""
    d = sweep / name
    cfg = compose_cfg(overrides)
    assert execute(resolve(cfg), d, OmegaConf.to_yaml(cfg), overrides)["status"] == "completed"
    (d / ".hydra").mkdir()
    (d / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    (d / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
    return d


def test_every_run_is_plotted_and_what_is_not_netted_is_named(tmp_path):
    """A free rotating plate and the same recording under gravity: both are
    plotted (the linear momentum net of the external impulse); a recording
    without the boundary impulse says so; with no recording, no plot."""
    sweep = tmp_path / "sweep"
    tiny = ["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=3", "log.every=0"]
    free = _job(sweep, "free", tiny + ["scheme=empm"])
    forced = sweep / "forced"
    shutil.copytree(free, forced)
    config = yaml.safe_load((forced / ".hydra" / "config.yaml").read_text())
    config["scene"]["gravity"] = [0.0, -9.81]
    (forced / ".hydra" / "config.yaml").write_text(yaml.safe_dump(config))
    metrics = json.loads((forced / "metrics.json").read_text())
    (forced / "metrics.json").write_text(json.dumps({**metrics, "config_hash": "forced"}))
    report = write_report(sweep).read_text()
    section = report.split("## Conservation", 1)[1].split("\n## ", 1)[0]
    assert "read from 2 recording(s)" in section and "conservation.png" in section
    assert "net of the gravity impulse" in section
    assert "| none |" in section and "| gravity |" in section  # the table's external column
    assert (sweep / "conservation.png").stat().st_size > 0
    rows = {r["dir"]: r for r in csv.DictReader((sweep / "momentum_net_drift.csv").open())}
    assert set(rows) == {"free", "forced"}
    if not _recorded(free):  # a recording made without the per-step boundary impulse
        assert "boundary impulse not recorded" in rows["free"]["not_netted"]
        assert "forced (boundary impulse not recorded)" in section
    # the recording did not fall: netting a gravity impulse it never felt shows as drift
    assert float(rows["forced"]["gravity_impulse"]) > 0
    assert float(rows["forced"]["net_drift"]) > 1e3 * max(float(rows["free"]["net_drift"]), 1e-16)

    shutil.rmtree(free)
    (sweep / "conservation.png").unlink()
    section = write_report(sweep).read_text().split("## Conservation", 1)[1].split("\n## ", 1)[0]
    assert "read from 1 recording(s)" in section and (sweep / "conservation.png").exists()


def _recorded(job) -> bool:
    from pipelines.recording.recordings import read

    return "boundary_impulse_y" in read(job / "recording.rrd", particles=False).scalars


def bouncing_ball(path, impulse: bool = True):
    """A 2D ball dropped onto the floor under gravity (float64), simulated
    with the solver and recorded through the run's sink with the scalars the
    runner logs: mass, momentum, its scale, dt and (``impulse``) the step's
    boundary impulse."""
    import mpm
    from pipelines.recording.rerun_sink import RerunSink
    from pipelines.recording.sinks import RunMeta

    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=32, gravity=(0.0, -9.81),
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.3), 0.1), mpm.NeoHookean(E=2e4, nu=0.3),
                                       velocity=(0.4, -2.0))])
    model, state = mpm.build(scene, mpm.KERNELS["quadratic"], "float64", "cpu")
    solver = mpm.Solver(model)
    solver.prepare(state)
    names = solver.diagnostics.names
    sink = RerunSink(path, threaded=False)
    sink.start(RunMeta(name="ball", dim=2, domain=model.domain, wall_cells=3, dx=model.dx, body_names=["ball"],
                       particle_body=model.body.numpy(), particle_radius=0.005))
    keep = ("mass", "momentum_x", "momentum_y", "momentum_scale")
    d = solver.measure(state, elastic=False)
    sink.scalars(0, 0.0, {n: float(d[names.index(n)]) for n in keep})
    dt = mpm.cfl_dt(model.dx, model.wave_speed(), 2.5, 0.4)
    for k in range(1, int(0.08 / dt)):
        r = solver.advance(state, dt)
        d = solver.measure(state, elastic=False)
        row = {n: float(d[names.index(n)]) for n in keep} | {"dt": r.dt}
        if impulse:
            row |= {f"boundary_impulse_{a}": float(j) for a, j in zip("xy", r.boundary_impulse)}
        sink.scalars(k, solver.time, row)
    sink.close()


def test_the_momentum_of_a_bouncing_ball_is_drawn_net_of_gravity_and_the_floor(tmp_path):
    """A ball bouncing on the floor under gravity: its momentum changes by
    about its own scale, yet, net of the recorded gravity and boundary
    impulse, drifts by round-off only; without the boundary impulse recorded
    the report says so and the floor's impulse shows as drift."""
    sweep = tmp_path / "sweep"
    for name, impulse in (("recorded", True), ("older", False)):
        d = sweep / name
        (d / ".hydra").mkdir(parents=True)
        bouncing_ball(d / "recording.rrd", impulse)
        (d / ".hydra" / "config.yaml").write_text(yaml.safe_dump(
            {"scene": {"name": "ball", "gravity": [0.0, -9.81], "walls": ["slip"] * 4, "resolution": 32}}))
        (d / "metrics.json").write_text(json.dumps({"status": "completed", "config_hash": name}))
    section = write_report(sweep).read_text().split("## Conservation", 1)[1].split("\n## ", 1)[0]
    rows = {r["dir"]: r for r in csv.DictReader((sweep / "momentum_net_drift.csv").open())}
    recorded, older = rows["recorded"], rows["older"]
    assert float(recorded["drift"]) > 0.1  # the momentum did change: gravity and the bounce
    assert float(recorded["boundary_impulse"]) > 0.1 * float(recorded["gravity_impulse"]) > 0
    assert float(recorded["net_drift"]) < 1e-13, recorded  # round-off (float64)
    assert recorded["not_netted"] == "" and older["not_netted"] == "boundary impulse not recorded"
    assert float(older["net_drift"]) > 0.1
    assert "older (boundary impulse not recorded)" in section and "recorded (" not in section
