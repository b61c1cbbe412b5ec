"""A turning collider in the recording: its pose (rotation and translation)
logged at every particle frame, read back, drawn turned in the replay's
frames and exported turned to VTK and USD."""

import numpy as np
import pytest

from helpers import ROOT, run_cli
from mpm.colliders import Collider
from pipelines.export import command
from pipelines.recording import recordings
from pipelines.recording.display import _collider_shifts

PADDLE = Collider.box((0.3, 0.75), (0.12, 0.02), name="paddle", velocity=(0.5, 0.0), angular_velocity=6.0,
                      pivot=(0.25, 0.75))


@pytest.fixture(scope="module")
def run_turning(tmp_path_factory):
    """The default ball with a paddle above it that turns at 6 rad/s about
    a pivot off its centre while it moves sideways: 5 frames."""
    run = tmp_path_factory.mktemp("turning") / "paddle"
    p = run_cli(["run.duration=0.1", "scene.resolution=32", "log.every=50", "log.progress=false",
                 "+scene.colliders=[{type: box, name: paddle, center: [0.3, 0.75], half_size: [0.12, 0.02], "
                 "velocity: [0.5, 0], angular_velocity: 6.0, pivot: [0.25, 0.75]}]", f"hydra.run.dir={run}"],
                cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    return run


def test_a_turning_collider_is_recorded_and_drawn_at_its_pose(run_turning):
    rec = recordings.read(run_turning / "recording.rrd")
    assert rec.collider_turn is not None and rec.collider_shift is not None
    steps, mats = rec.collider_turn["paddle"]
    assert np.array_equal(steps, rec.steps) and len(steps) >= 3
    rest = np.concatenate(rec.colliders["paddle"]).astype(np.float64)  # the outline at rest
    for k, t in enumerate(rec.times):
        R, b = PADDLE.pose(float(t), 2)
        np.testing.assert_allclose(mats[k][:2, :2], R, atol=1e-6)  # float32 as recorded
        drawn = _collider_shifts(rec, int(rec.steps[k]))["paddle"](rest)
        np.testing.assert_allclose(drawn, PADDLE.place(rest, float(t)), atol=1e-6)
    assert rec.times[-1] > 0.05  # turned by more than 0.3 rad: the check sees the turn


def test_a_turning_collider_is_exported_turned(run_turning):
    pytest.importorskip("vtkmodules.vtkIOXML")
    from test_export import pvd, read_vtp
    from pxr import Gf, Usd, UsdGeom

    rec = recordings.read(run_turning / "recording.rrd")
    rest = np.concatenate(rec.colliders["paddle"]).astype(np.float64)
    out = run_turning / "export"
    assert command.main([str(run_turning), "--format", "vtk", "--out", str(out / "vtk")]) == 0
    series = pvd(out / "vtk" / "collider_paddle.pvd")
    assert [t for t, _ in series] == list(rec.times)
    for t, name in series:
        np.testing.assert_allclose(read_vtp(out / "vtk" / name)[1][:, :2], PADDLE.place(rest, t), atol=1e-6)
    assert command.main([str(run_turning), "--format", "usd", "--out", str(out / "usd")]) == 0
    stage = Usd.Stage.Open(str(out / "usd" / "stage.usdc"))
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/World/colliders/paddle")).GetOrderedXformOps()[0]
    codes = op.GetTimeSamples()
    assert len(codes) == len(rec.times)
    for code, t in zip(codes, rec.times):
        M = op.Get(code)
        moved = np.array([list(M.Transform(Gf.Vec3d(x, y, 0.0)))[:2] for x, y in rest])
        np.testing.assert_allclose(moved, PADDLE.place(rest, float(t)), atol=1e-6)
