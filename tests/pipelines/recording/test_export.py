"""pipelines.export: the files read back with VTK's own reader and with pxr
equal the recording (positions, every channel, the simulated times), and
the command's errors are one line with exit code 2."""

import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import pipelines.export
from helpers import ROOT, run_cli
from pipelines.export import command
from pipelines.recording import recordings

vtk_io = pytest.importorskip("vtkmodules.vtkIOXML")
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402
from pxr import Usd, UsdGeom  # noqa: E402


@pytest.fixture(scope="module")
def run_2d(tmp_path_factory):
    """A 2D run whose frames carry speed besides dJ and the body: 5 frames."""
    run = tmp_path_factory.mktemp("export") / "plate"
    p = run_cli(["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=20", "log.every=5",
                 "log.color=speed", "log.progress=false", f"hydra.run.dir={run}"], cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    return run


@pytest.fixture(scope="module")
def run_3d(tmp_path_factory):
    """A 3D run with a collider (the cup) and walls: 3 frames."""
    run = tmp_path_factory.mktemp("export") / "cup"
    p = run_cli(["scene=viscous_cup", "scene.resolution=20", "scene.wall_cells=1", "run.steps=4", "log.every=2",
                 "log.progress=false", f"hydra.run.dir={run}"], cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    return run


@pytest.fixture(scope="module")
def run_moving(tmp_path_factory):
    """The 2D ball thrown through an open wall under a lid that moves down: 5
    frames, particles removed in the last two."""
    run = tmp_path_factory.mktemp("export") / "lid"
    p = run_cli(["scene.walls=[slip,open,slip,slip]", "scene.gravity=[0,0]", "scene.bodies.0.velocity=[8,0]",
                 "run.duration=0.05", "scene.resolution=32", "log.every=20", "log.progress=false",
                 "+scene.colliders=[{type: half_space, name: lid, point: [0.5, 0.9], normal: [0, -1], "
                 "velocity: [0, -1]}]", f"hydra.run.dir={run}"], cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    return run


def export(run, fmt, *more, out=None):
    out = out if out is not None else run / "export" / fmt
    assert command.main([str(run), "--format", fmt, "--out", str(out), *more]) == 0
    return out


def read_vtp(path):
    reader = vtk_io.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    poly = reader.GetOutput()
    data = poly.GetPointData()
    channels = {data.GetArrayName(i): vtk_to_numpy(data.GetArray(i)) for i in range(data.GetNumberOfArrays())}
    return poly, vtk_to_numpy(poly.GetPoints().GetData()), channels


def pvd(path):
    return [(float(d.get("timestep")), d.get("file")) for d in ET.parse(path).getroot().iter("DataSet")]


def recorded_channels(rec, k):
    out = {"dJ": rec.dJ[k], "body": rec.body, **rec.fields[k]}
    return {name: v for name, v in out.items() if v is not None}


def padded(x):
    return np.concatenate([x, np.zeros((len(x), 3 - x.shape[1]))], axis=1)


@pytest.mark.slow
def test_vtk_series_equals_the_recording(run_2d):
    rec = recordings.read(run_2d / "recording.rrd")
    out = export(run_2d, "vtk")
    entries = pvd(out / "particles.pvd")
    assert [t for t, _ in entries] == list(rec.times) and len(entries) == 5
    for k, (t, name) in enumerate(entries):
        poly, x, channels = read_vtp(out / name)
        assert np.array_equal(x.astype(np.float64), padded(rec.positions[k]))
        assert poly.GetNumberOfVerts() == len(x)  # a vertex cell per particle: ParaView draws them
        want = recorded_channels(rec, k)
        assert set(channels) == set(want) == {"dJ", "speed", "body"}
        for c, values in want.items():
            assert np.array_equal(channels[c], values), c
        assert vtk_to_numpy(poly.GetFieldData().GetArray("TimeValue"))[0] == t
    walls, w, _ = read_vtp(out / "walls.vtp")
    assert walls.GetNumberOfLines() == 4 and np.all(w[:, 2] == 0)  # the four walls' inner faces, in z = 0


@pytest.mark.slow
def test_every_2_keeps_every_second_frame(run_2d, tmp_path):
    rec = recordings.read(run_2d / "recording.rrd")
    out = export(run_2d, "vtk", "--every", "2", out=tmp_path / "vtk")
    entries = pvd(out / "particles.pvd")
    assert [t for t, _ in entries] == list(rec.times[::2])
    assert np.array_equal(read_vtp(out / entries[1][1])[1][:, :2], rec.positions[2])
    assert len(list(out.glob("particles_*.vtp"))) == 3


@pytest.mark.slow
def test_usd_time_samples_equal_the_recording(run_2d):
    rec = recordings.read(run_2d / "recording.rrd")
    stage = Usd.Stage.Open(str(export(run_2d, "usd") / "stage.usdc"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    rate = stage.GetTimeCodesPerSecond()
    points = UsdGeom.Points(stage.GetPrimAtPath("/World/particles"))
    codes = points.GetPointsAttr().GetTimeSamples()
    assert np.allclose(np.asarray(codes) / rate, rec.times, rtol=0, atol=1e-12)
    assert rate == 200  # a frame every 5 ms
    assert list(points.GetWidthsAttr().Get()) == pytest.approx([2 * rec.radius])
    primvars = UsdGeom.PrimvarsAPI(points)
    for k, code in enumerate(codes):
        x = np.asarray(points.GetPointsAttr().Get(code), np.float64)
        assert np.array_equal(x, padded(rec.positions[k]))
        for name, values in recorded_channels(rec, k).items():
            assert np.array_equal(np.asarray(primvars.GetPrimvar(name).Get(code)), values), name
    assert primvars.GetPrimvar("body").GetAttr().GetNumTimeSamples() == 0  # constant: no particle removed
    walls = UsdGeom.BasisCurves(stage.GetPrimAtPath("/World/walls"))
    assert list(walls.GetCurveVertexCountsAttr().Get()) == [2, 2, 2, 2]


@pytest.mark.slow
def test_3d_run_with_its_collider_and_walls(run_3d):
    rec = recordings.read(run_3d / "recording.rrd")
    out = export(run_3d, "vtk")
    cup, v, _ = read_vtp(out / "collider_cup.vtp")
    vertices, triangles = rec.colliders["cup"]
    assert np.array_equal(v.astype(np.float64), vertices)
    cells = vtk_to_numpy(cup.GetPolys().GetConnectivityArray())
    assert np.array_equal(cells.reshape(-1, 3), triangles)
    walls = read_vtp(out / "walls.vtp")[0]
    assert walls.GetNumberOfPolys() == 12  # six faces, two triangles each
    for k, (_, name) in enumerate(pvd(out / "particles.pvd")):
        assert np.array_equal(read_vtp(out / name)[1].astype(np.float64), rec.positions[k])
    stage = Usd.Stage.Open(str(export(run_3d, "usd") / "stage.usdc"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/cup"))
    assert mesh and np.array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), triangles.reshape(-1))
    assert np.array_equal(np.asarray(mesh.GetPointsAttr().Get(), np.float64), vertices.astype(np.float32))
    assert len(UsdGeom.Mesh(stage.GetPrimAtPath("/World/walls")).GetFaceVertexCountsAttr().Get()) == 12
    points = UsdGeom.Points(stage.GetPrimAtPath("/World/particles")).GetPointsAttr()
    last = points.GetTimeSamples()[-1]
    assert np.array_equal(np.asarray(points.Get(last), np.float64), rec.positions[-1])


@pytest.mark.slow
def test_a_moving_collider_and_removed_particles(run_moving):
    """A moving collider is a series of its own at the particles' times;
    once particles are removed every frame carries their numbers and the
    body of each."""
    rec = recordings.read(run_moving / "recording.rrd")
    assert rec.index[0] is None and rec.index[-1] is not None and len(rec.positions[-1]) < len(rec.positions[0])
    out = export(run_moving, "vtk")
    steps, shifts = rec.collider_shift["lid"]
    assert np.array_equal(steps, rec.steps) and shifts.shape == (5, 3) and shifts.dtype == np.float64
    moved = padded(shifts)
    base = padded(np.concatenate(rec.colliders["lid"]))
    series = pvd(out / "collider_lid.pvd")
    assert [t for t, _ in series] == list(rec.times) and not (out / "collider_lid.vtp").exists()
    for k, (_, name) in enumerate(series):
        assert np.allclose(read_vtp(out / name)[1], base + moved[k], rtol=0, atol=1e-6)
    for k, (_, name) in enumerate(pvd(out / "particles.pvd")):
        index = rec.index[k] if rec.index[k] is not None else np.arange(len(rec.positions[k]))
        _, x, channels = read_vtp(out / name)
        assert np.array_equal(channels["index"], index) and np.array_equal(channels["body"], rec.body[index])
        assert np.array_equal(x[:, :2], rec.positions[k])
    stage = Usd.Stage.Open(str(export(run_moving, "usd") / "stage.usdc"))
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/World/colliders/lid")).GetOrderedXformOps()[0]
    codes = op.GetTimeSamples()
    assert np.allclose([op.Get(c) for c in codes], moved, rtol=0, atol=1e-7)
    primvars = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/particles"))
    assert [len(primvars.GetPrimvar("index").Get(c)) for c in codes] == [len(x) for x in rec.positions]
    assert [len(primvars.GetPrimvar("body").Get(c)) for c in codes] == [len(x) for x in rec.positions]


@pytest.mark.slow
def test_the_command_line_writes_into_the_run_directory(run_2d):
    p = subprocess.run([sys.executable, "-m", "pipelines.export", str(run_2d), "--format", "usd"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith("5 frames of 36 particles (body, dJ, speed) to ")
    assert (run_2d / "export" / "usd" / "stage.usdc").is_file()


@pytest.mark.parametrize("args, message", [
    (["{missing}", "--format", "vtk"], "error: run dir: {missing}: no such directory; accepted: "),
    (["{empty}", "--format", "vtk"], "error: run dir: {empty}: no recording.rrd in it; accepted: "),
    (["{file}", "--format", "vtk"], "error: run dir: {file} is a file; accepted: "),
    (["{recorded}/recording.timings.rrd", "--format", "usd"],
     "error: run dir: {recorded}/recording.timings.rrd holds a run's wall-clock timings, not its particles"),
    (["{empty}", "--format", "ply"], "error: argument --format: invalid choice: 'ply'"),
    (["{empty}", "--format", "usd", "--every", "0"], "error: --every: 0; accepted: an integer >= 1"),
    (["{recorded}", "--format", "vtk", "--out", "{file}"], "error: --out: {file} is a file; accepted: "),
])
def test_bad_inputs_give_one_line_and_exit_code_2(args, message, tmp_path, capsys):
    paths = {"missing": tmp_path / "nope", "empty": tmp_path / "empty", "recorded": tmp_path / "recorded",
             "file": tmp_path / "file.txt"}
    paths["empty"].mkdir()
    paths["recorded"].mkdir()
    (paths["recorded"] / "recording.rrd").write_bytes(b"")
    (paths["recorded"] / "recording.timings.rrd").write_bytes(b"")
    paths["file"].write_text("x")
    code = exit_code([a.format(**paths) for a in args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith(message.format(**paths)), err


def exit_code(argv) -> int:
    """``main``'s exit code, returned or (argparse's errors) raised."""
    try:
        return command.main(argv)
    except SystemExit as e:
        return e.code


def test_without_vtk_the_error_says_what_to_install(monkeypatch, tmp_path, capsys):
    (tmp_path / "recording.rrd").write_bytes(b"")
    for name in ["vtkmodules", *(m for m in sys.modules if m.startswith("vtkmodules."))]:
        monkeypatch.setitem(sys.modules, name, None)  # import vtkmodules.*: ImportError
    monkeypatch.delitem(sys.modules, "pipelines.export.vtk_series", raising=False)  # imported afresh
    monkeypatch.delattr(pipelines.export, "vtk_series", raising=False)
    assert command.main([str(tmp_path), "--format", "vtk"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['error: --format vtk: the vtk package is not installed; accepted: pip install -e ".[export]"']
