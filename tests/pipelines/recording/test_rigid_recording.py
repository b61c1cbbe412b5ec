"""A rigid body in the recording (pipelines.run.rigid_track): its shape
placed at its Newton pose on every particle frame, its series (state at
the frames, coupling force and torque every step), its final state in metrics.json,
drawn and exported where it is, and a rerun reproducing the recording."""

import json
import subprocess
import sys

import numpy as np
import pytest

from helpers import ROOT, run_cli, spec_for
from pipelines.recording import layout, recordings
from pipelines.recording.display import _collider_shifts
from pipelines.run.recorder import Recorder
from pipelines.run.rigid_track import rotation
from pipelines.run.runner import execute

# the floating box released above the water: it falls in by about 0.04 s, the water pushes it back
BOX = ["scene=floating_box_2d", "run.duration=0.06", "log.every=60", "log.progress=false"]
CENTRE = np.array([0.2, 0.22625])  # the box's initial centre (conf/scene/floating_box_2d.yaml)


@pytest.fixture(scope="module")
def floating(tmp_path_factory):
    """The floating box run in this process, the Newton state (body_q, body_qd, body_f) read beside
    each particle frame: (run folder, {step: (time, q, qd, f)})."""
    out = tmp_path_factory.mktemp("rigid") / "box"
    seen = {}
    original = Recorder.particles

    def particles(self):
        s = self.solver.conditions.rigid.state
        seen[self.step] = (self.t, s.body_q.numpy().astype(np.float64), s.body_qd.numpy().astype(np.float64),
                           s.body_f.numpy().astype(np.float64))
        original(self)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Recorder, "particles", particles)
        m = execute(spec_for(BOX), out)
    assert m["status"] == "completed"
    return out, seen


def test_the_body_is_recorded_at_its_newton_pose(floating):
    out, seen = floating
    rec = recordings.read(out / "recording.rrd")
    steps, shifts = rec.collider_shift["rigid/box"]
    at, mats = rec.collider_turn["rigid/box"]
    assert list(steps) == list(at) == list(rec.steps) == sorted(seen) and len(steps) >= 5
    rest = np.concatenate(rec.colliders["rigid/box"]).astype(np.float64)  # the outline at rest
    np.testing.assert_allclose(0.5 * (rest.min(axis=0) + rest.max(axis=0)), CENTRE, atol=1e-6)
    for k, step in enumerate(steps):
        t, q, _, _ = seen[step]
        assert rec.times[k] == pytest.approx(t)
        R = rotation(q[0, 3:])
        np.testing.assert_allclose(mats[k], R, atol=1e-6)
        np.testing.assert_allclose(mats[k][:2, :2] @ CENTRE + shifts[k][:2], q[0, :2], atol=1e-6)
        drawn = _collider_shifts(rec, int(step))["rigid/box"](rest)
        np.testing.assert_allclose(drawn, (rest - CENTRE) @ R[:2, :2].T + q[0, :2], atol=1e-6)
    assert seen[steps[-1]][1][0, 1] < CENTRE[1] - 0.005  # it fell: the check sees it move
    assert layout.declared(out / "recording.rrd")["flip"]["rigid"] == layout.FLIP_2D  # drawn y up in 2D


def test_the_body_series_and_final_state(floating):
    out, seen = floating
    rec = recordings.read(out / "recording.rrd", particles=False)
    units = {"position_x": "m", "position_y": "m", "velocity_x": "m/s", "velocity_y": "m/s",
             "angle": "rad", "angular_velocity": "rad/s", "torque": "N m/m", "force_x": "N/m", "force_y": "N/m"}
    for q, u in units.items():
        assert f"rigid/box/{q}" in rec.scalars
        assert layout.unit(f"rigid/box/{q}", 2) == u
    frames = sorted(seen)
    for q, k, (i, j) in (("position", 1, (0, 3)), ("velocity", 2, (0, 3))):
        for a, axis in enumerate("xy"):
            steps, values = rec.scalars[f"rigid/box/{q}_{axis}"]
            assert list(steps) == frames
            np.testing.assert_array_equal(values, [seen[s][k][0, i:j][a] for s in frames])
    steps, w = rec.scalars["rigid/box/angular_velocity"]
    np.testing.assert_array_equal(w, [seen[s][2][0, 5] for s in frames])
    m = json.loads((out / "metrics.json").read_text())
    # the force and the torque every step (logged at the step's start), the Coupler's at each frame's last step
    steps, fy = rec.scalars["rigid/box/force_y"]
    assert list(steps) == list(range(m["steps"]))
    assert fy.max() > 1.0  # the water pushed the box up
    steps, tau = rec.scalars["rigid/box/torque"]
    assert list(steps) == list(range(m["steps"]))
    assert np.abs(tau).max() > 0.0  # (the water's torque on the box is not exactly nil)
    for s in frames[1:]:
        np.testing.assert_allclose(fy[s - 1], seen[s][3][0, 1], rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(tau[s - 1], seen[s][3][0, 5], rtol=1e-5, atol=1e-9)
    _, q, qd, f = seen[frames[-1]]
    final = m["rigid_bodies"]["box"]
    assert final["position"] == list(q[0, :2]) and final["quaternion"] == list(q[0, 3:])
    assert final["velocity"] == list(qd[0, :2]) and final["angular_velocity"] == qd[0, 5]
    assert final["torque"] == f[0, 5] and final["mass"] == pytest.approx(500.0 * 0.1 * 0.06)
    assert final["angle"] == pytest.approx(2 * np.arctan2(q[0, 5], q[0, 6]), abs=1e-12)


def test_the_body_energy_in_the_series_and_the_balance(floating):
    """The box's energies at each frame from its Newton state (1/2 m |v|^2,
    1/2 I w^2 with I = m (a^2 + b^2) / 12 for the 0.1 x 0.06 m box, -m g . x
    with g = 9.81 m/s^2 down), ``rigid_energy`` their sum, ``system_energy``
    the material's total plus that at the frames' steps; metrics.json: the
    body's final energies, ``total_energy_*`` the material's plus the body's,
    and ``energy_change`` weighing the totals against the boundaries' work."""
    out, seen = floating
    rec = recordings.read(out / "recording.rrd", particles=False)
    frames = sorted(seen)
    mass = 500.0 * 0.1 * 0.06
    inertia = mass * (0.1**2 + 0.06**2) / 12.0
    expected = {"kinetic_energy": [0.5 * mass * seen[s][2][0, :3] @ seen[s][2][0, :3] for s in frames],
                "rotational_energy": [0.5 * inertia * seen[s][2][0, 5] ** 2 for s in frames],
                "potential_energy": [mass * 9.81 * seen[s][1][0, 1] for s in frames]}
    total = np.zeros(len(frames))
    for q, values in expected.items():
        steps, logged = rec.scalars[f"rigid/box/{q}"]
        assert list(steps) == frames and layout.unit(f"rigid/box/{q}", 2) == "J/m"
        np.testing.assert_allclose(logged, values, rtol=1e-5, atol=1e-12)  # (the inertia float32 in Newton)
        total += logged
    steps, rigid = rec.scalars["rigid_energy"]
    assert list(steps) == frames and layout.unit("rigid_energy", 2) == "J/m"
    np.testing.assert_allclose(rigid, total, rtol=1e-12)
    steps, system = rec.scalars["system_energy"]
    material_steps, material = rec.scalars["total_energy"]
    assert list(steps) == frames
    np.testing.assert_allclose(system, material[np.searchsorted(material_steps, frames)] + rigid, rtol=1e-12)
    m = json.loads((out / "metrics.json").read_text())
    final = m["rigid_bodies"]["box"]
    assert m["rigid_energy_final"] == pytest.approx(rigid[-1], rel=1e-12)
    assert m["rigid_energy_final"] == pytest.approx(
        final["kinetic_energy"] + final["rotational_energy"] + final["potential_energy"], rel=1e-12)
    assert m["rigid_energy_initial"] == pytest.approx(rigid[0], rel=1e-12)
    assert m["rigid_energy_initial"] == pytest.approx(mass * 9.81 * CENTRE[1], rel=1e-6)  # released at rest
    for k in ("initial", "final"):
        assert m[f"total_energy_{k}"] == m[f"energy_{k}"] + m[f"rigid_energy_{k}"]
    d = m["detect"]
    assert m["energy_change"] == pytest.approx(
        (m["total_energy_final"] - m["total_energy_initial"] - d["boundary_work"]) / d["energy_scale"], rel=1e-12)


def test_a_scene_without_rigid_bodies_reports_no_body_energy(tmp_path):
    """A scene without rigid bodies (the default, 40 steps): none of the bodies' energy keys or series, and
    ``energy_change`` the material's alone, as before."""
    out = tmp_path / "plain"
    m = execute(spec_for(["run.steps=40", "log.every=20", "log.progress=false"]), out)
    assert m["status"] == "completed"
    assert not [k for k in m if k.startswith(("rigid", "total_energy"))]
    d = m["detect"]
    assert m["energy_change"] == (m["energy_final"] - m["energy_initial"] - d["boundary_work"]) / d["energy_scale"]
    rec = recordings.read(out / "recording.rrd", particles=False)
    assert "total_energy" in rec.scalars
    assert not [k for k in rec.scalars if k.startswith("rigid") or k == "system_energy"]


def test_the_body_is_drawn_and_exported_where_it_is(floating, tmp_path):
    pytest.importorskip("vtkmodules.vtkIOXML")
    from test_export import pvd, read_vtp
    from pipelines.export import command

    out, seen = floating
    assert command.main([str(out), "--format", "vtk", "--out", str(tmp_path / "vtk")]) == 0
    series = pvd(tmp_path / "vtk" / "collider_rigid_box.pvd")
    assert len(series) == len(seen)
    for (t, name), step in zip(series, sorted(seen)):
        assert t == pytest.approx(seen[step][0])
        points = read_vtp(tmp_path / "vtk" / name)[1][:, :2]
        centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
        np.testing.assert_allclose(centre, seen[step][1][0, :2], atol=1e-6)
    from pxr import Gf, Usd, UsdGeom

    assert command.main([str(out), "--format", "usd", "--out", str(tmp_path / "usd")]) == 0
    stage = Usd.Stage.Open(str(tmp_path / "usd" / "stage.usdc"))
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/World/colliders/rigid_box")).GetOrderedXformOps()[0]
    codes = op.GetTimeSamples()
    assert len(codes) == len(seen)
    for code, step in zip(codes, sorted(seen)):
        centre = list(op.Get(code).Transform(Gf.Vec3d(*CENTRE, 0.0)))[:2]
        np.testing.assert_allclose(centre, seen[step][1][0, :2], atol=1e-6)
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(out / "recording.rrd"), "--frames",
                        str(tmp_path / "frames")], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert len(list((tmp_path / "frames").glob("frame_*.png"))) == len(seen)


def test_a_3d_body_is_recorded_at_its_pose(tmp_path):
    """A spinning box above the colliding spheres (3D): its transform on the last frame, its rotation
    series and metrics.json's final state agree; the series' units are the 3D ones."""
    centre = np.array([0.5, 0.8, 0.3])
    m = execute(spec_for(["scene=colliding_spheres", "scene.resolution=16", "run.steps=20", "log.every=10",
                          "log.progress=false", "+scene.rigid_bodies=[{name: cube, shape: {type: box, center: "
                          "[0.5, 0.8, 0.3], half_size: [0.08, 0.05, 0.06]}, density: 500, angular_velocity: "
                          "[1.0, 2.0, 0.5], velocity: [0.1, 0, 0]}]"]), tmp_path)
    rec = recordings.read(tmp_path / "recording.rrd")
    final = m["rigid_bodies"]["cube"]
    R, b = rec.collider_turn["rigid/cube"][1][-1], rec.collider_shift["rigid/cube"][1][-1]
    np.testing.assert_allclose(R, rotation(np.array(final["quaternion"])), atol=1e-6)
    np.testing.assert_allclose(R @ centre + b, final["position"], atol=1e-6)
    assert final["velocity"][0] == pytest.approx(0.1) and len(final["angular_velocity"]) == 3
    for k, axis in enumerate("xyz"):
        assert rec.scalars[f"rigid/cube/rotation_{axis}"][1][-1] == final["rotation"][k]
        assert rec.scalars[f"rigid/cube/angular_velocity_{axis}"][1][-1] == final["angular_velocity"][k]
    assert float(np.linalg.norm(final["rotation"])) > 0.02  # it turned
    for axis in "xyz":  # the torque every step, as the force
        assert list(rec.scalars[f"rigid/cube/torque_{axis}"][0]) == list(rec.scalars["rigid/cube/force_x"][0])
    assert list(rec.scalars["rigid/cube/force_x"][0]) == list(range(m["steps"]))
    assert [layout.unit(f"rigid/cube/{q}_z", 3) for q in ("force", "torque", "angular_velocity", "rotation")] == [
        "N", "N m", "rad/s", "rad"]


def test_a_scene_without_rigid_bodies_records_none(tmp_path):
    """No /rigid entity, no rigid series, no flip of /rigid, no rigid_bodies in metrics.json (its
    recording is otherwise the one it was before rigid bodies were recorded)."""
    m = execute(spec_for(["scene.resolution=16", "run.steps=10", "log.every=5", "log.progress=false"]), tmp_path)
    rec = recordings.read(tmp_path / "recording.rrd")
    assert "rigid_bodies" not in m and not any(k.startswith("rigid") for k in rec.scalars)
    assert not any(k.startswith("rigid") for k in (rec.colliders or {}))
    assert "rigid" not in layout.declared(tmp_path / "recording.rrd")["flip"]


@pytest.mark.slow
@pytest.mark.bitwise
def test_a_rerun_of_the_floating_box_reproduces_its_recording(tmp_path):
    run_dir = tmp_path / "run"
    p = run_cli(BOX[:1] + ["run.duration=0.03", "log.every=50", f"hydra.run.dir={run_dir}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(run_dir / "recording.rrd"), "--reproduce"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "identical bit for bit" in r.stdout


def test_the_pendulum_striking_a_jelly_block_is_recorded_hinged(tmp_path):
    """scene=pendulum_jelly_2d up to just past the strike (0.45 s): the run
    completes, the recording draws the disc (rigid/bob) at its Newton pose
    on every frame, its centre 0.3 m from the hinge's anchor (0.5, 0.45) on
    every frame to float32 rounding, and the jelly was pushed (its centre
    moved along +x)."""
    m = execute(spec_for(["scene=pendulum_jelly_2d", "run.duration=0.45", "log.every=50", "log.progress=false"]),
                tmp_path)
    assert m["status"] == "completed"
    rec = recordings.read(tmp_path / "recording.rrd")
    centre = np.array([0.2203883, 0.3412927])  # conf/scene/pendulum_jelly_2d.yaml
    steps, shifts = rec.collider_shift["rigid/bob"]
    _, mats = rec.collider_turn["rigid/bob"]
    assert len(steps) >= 5
    placed = np.array([R[:2, :2] @ centre + b[:2] for R, b in zip(mats, shifts)])
    np.testing.assert_allclose(np.linalg.norm(placed - [0.5, 0.45], axis=1), 0.3, atol=2e-6)
    _, x = rec.scalars["rigid/bob/position_x"]
    assert x[-1] > 0.5  # it swung past the bottom
    final = m["rigid_bodies"]["bob"]
    assert np.linalg.norm(np.array(final["position"]) - [0.5, 0.45]) == pytest.approx(0.3, abs=2e-6)
    jelly = rec.positions[0][:, 0].mean(), rec.positions[-1][:, 0].mean()
    assert jelly[1] > jelly[0] + 1e-3, jelly
