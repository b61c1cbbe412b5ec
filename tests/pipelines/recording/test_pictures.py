"""What a person sees: the view a recording declares (y up, camera, time
series with units on the simulated-time timeline), its colours, and the
frames of ``pipelines.replay --frames`` looked at as images."""

import subprocess
import sys

import numpy as np
import pytest
from omegaconf import OmegaConf
from PIL import Image

from helpers import ROOT, compose_cfg
from pipelines.config.validate import resolve
from pipelines.recording import layout, recordings
from pipelines.recording.display import render_frames
from pipelines.recording.colours import PALETTE, colormap, values_range
from pipelines.run.runner import execute


def run(tmp_path, overrides):
    cfg = compose_cfg(overrides)
    m = execute(resolve(cfg), tmp_path, OmegaConf.to_yaml(cfg), overrides)
    assert m["status"] == "completed", m
    return tmp_path / "recording.rrd"


def pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int32)


def mask(img: np.ndarray, rgb, tol: int = 30) -> np.ndarray:
    """Pixels within ``tol`` of ``rgb`` per channel (anti-aliased marker
    edges blend with white and are left out)."""
    return np.all(np.abs(img - np.asarray(rgb, np.int32)) <= tol, axis=-1)


def _longest_run(present: np.ndarray) -> slice:
    """The longest run of True in a 1D array."""
    best, start = slice(0, 0), None
    for i, p in enumerate(np.append(present, False)):
        if p and start is None:
            start = i
        elif not p and start is not None:
            best = max(best, slice(start, i), key=lambda s: s.stop - s.start)
            start = None
    return best


def blob(m: np.ndarray) -> np.ndarray:
    """The mask cut to its largest block of contiguous rows, then columns
    (a body, apart from the small legend marker of its colour)."""
    grown = m.copy()  # markers touch at a point: close the gaps of a few pixels between them
    for k in (1, 2, 3):
        grown[k:] |= m[:-k]
        grown[:-k] |= m[k:]
    rows = _longest_run(grown.any(axis=1))
    out = np.zeros_like(m)
    out[rows] = m[rows]
    cols = _longest_run(np.convolve(out.any(axis=0), np.ones(7), "same") > 0)
    keep = np.zeros_like(m)
    keep[:, cols] = out[:, cols]
    return keep


# ---------------------------------------------------------------- the recording's view

def test_a_2d_recording_is_drawn_y_up_on_the_sim_time_timeline(tmp_path):
    """Rerun's 2D views draw y down: every spatial entity carries a static
    transform that mirrors y; the blueprint opens on sim_time, every time
    series view names its unit, and each scalar series is named with its unit."""
    path = run(tmp_path, ["scene.resolution=16", "run.steps=4", "log.every=2"])
    d = layout.declared(path)
    assert d["up"] == "+y"
    assert d["flip"] == {p: layout.FLIP_2D for p in layout.SPATIAL_2D}
    assert d["flip"]["particles"][1] < 0 < d["flip"]["particles"][0]
    assert d["views"]["particles"] == "2D" and d["timeline"] == "sim_time"
    series = [name for name, kind in d["views"].items() if kind == "TimeSeries"]
    assert "energy [J/m]" in series and "wall clock [ms]" in series
    assert all(name.endswith("]") and " [" in name for name in series), series
    from rerun.chunk import RrdReader

    static = RrdReader(str(path)).stream().collect().reader(index=None, contents="/scalars/**").to_pandas()
    names = {c.split(":")[0]: static[c].iloc[0][0] for c in static.columns if c.endswith(":SeriesLines:names")}
    assert names["/scalars/kinetic_energy"] == "kinetic energy [J/m]"
    assert names["/scalars/dt"] == "time step [s]"
    # the particle data stay in the scene's coordinates (y up): the ball starts above the middle
    rec = recordings.read(path)
    assert rec.positions[0][:, 1].mean() > 0.5
    # EMPM's reference is fresh at every step: the step allowed now is the step taken, one curve named for both
    assert np.array_equal(rec.scalars["dt"][1], rec.scalars["dt_fresh"][1])
    assert "time step (= time step allowed now) [s]" in series and "time step [s]" not in series
    # the particle view is named by what its colours mean, and its key (a swatch per body) is recorded
    assert d["title"] == "particles: ball blue"
    key = RrdReader(str(path)).stream().collect().reader(index=None, contents="/particles/key/**").to_pandas()
    assert [v[0] for c in key.columns if c.endswith(":labels") for v in key[c]] == ["ball (blue)"]


def test_a_step_that_differs_from_the_one_allowed_now_is_drawn_beside_it(tmp_path):
    """Under A-ULMPM the reference ages between updates and the step taken
    falls below the one a fresh reference would allow: both curves share
    one plot, neither left out."""
    path = run(tmp_path, ["scheme=aulmpm", "scene.resolution=16", "run.duration=0.4", "log.every=0"])
    rec = recordings.read(path)
    assert not np.array_equal(rec.scalars["dt"][1], rec.scalars["dt_fresh"][1])
    series = [name for name, kind in layout.declared(path)["views"].items() if kind == "TimeSeries"]
    assert "time step [s]" in series and not any("(= " in name for name in series)


def test_legends_sit_above_the_data(tmp_path):
    """Rerun places a plot's legend in a corner, over the curves that pass
    there: a plot of several series puts it top left, and the blueprint sent
    when the run ends sets the y range to the run's data plus room above
    them (layout.LEGEND_ROOM of their span); a one-series plot shows no legend."""
    path = run(tmp_path, ["scene.resolution=16", "run.steps=40", "log.every=0"])
    d = layout.declared(path)
    rec = recordings.read(path)
    energies = np.concatenate([rec.scalars[n][1] for n in
                               ("kinetic_energy", "elastic_energy", "potential_energy", "total_energy")])
    lo, hi = d["y_range"]["energy [J/m]"]
    span = energies.max() - energies.min()
    assert d["legend"]["energy [J/m]"] == "LeftTop"
    assert lo <= energies.min() and hi >= energies.max() + 0.9 * layout.LEGEND_ROOM * span
    assert "max speed [m/s]" not in d["y_range"]  # one series, no legend


def test_a_3d_recording_declares_y_up_and_a_camera_above_the_floor(tmp_path):
    """View coordinates RUB (x right, y up, z back: right-handed, y up), an
    orbital camera above the floor and the bodies, looking at the domain
    with every particle within 45 degrees of its axis, and a grid on the floor."""
    path = run(tmp_path, ["scene=elastic_ball_3d", "scene.resolution=12", "run.steps=2", "log.every=1"])
    d = layout.declared(path)
    assert d["coordinates"] == "RUB" and d["up"] == "+y" and d["flip"] == {}
    assert d["views"]["particles"] == "3D" and d["timeline"] == "sim_time"
    rec = recordings.read(path)
    eye, target = np.array(d["eye"]["position"]), np.array(d["eye"]["look_target"])
    assert d["eye"]["eye_up"] == [0.0, 1.0, 0.0]
    floor = d["grid"][3]  # the plane y = floor (normal +y)
    assert d["grid"][:3] == [0.0, 1.0, 0.0] and 0 < floor < rec.positions[0][:, 1].min()
    assert eye[1] > rec.positions[0][:, 1].max() > floor
    axis = (target - eye) / np.linalg.norm(target - eye)
    to = rec.positions[0] - eye
    cos = to @ axis / np.linalg.norm(to, axis=1)
    assert cos.min() > np.cos(np.radians(45.0))


def test_field_colours_use_the_runs_own_range(tmp_path):
    """log.color=dJ: every frame's colours are the map over one range, the
    run's own (from 0 to the largest dJ of any logged frame: nothing is
    clipped, and not a running maximum); the range, map and source are
    recording properties, and the particle view's name states them."""
    path = run(tmp_path, ["scene=rotating_plate_2d", "scheme=tlmpm", "scene.resolution=16", "run.steps=20",
                          "log.every=10", "log.color=dJ"])
    rec = recordings.read(path)
    lo, hi = values_range("dJ", rec.dJ)
    assert lo == 0.0 and hi == max(float(d.max()) for d in rec.dJ) > 0
    p = rec.properties
    assert p["color:field"] == ["dJ"] and p["color:colormap"] == ["viridis"] and p["color:source"] == ["the run's range"]
    assert np.isclose(p["color:low"][0], lo) and np.isclose(p["color:high"][0], hi, rtol=1e-6)
    from rerun.chunk import RrdReader

    df = RrdReader(str(path)).stream().collect().reader(index="step", contents="/particles").to_pandas()
    colors = [np.asarray(c, np.uint32) for c in df["/particles:Points2D:colors"] if c is not None]
    assert len(colors) == len(rec.steps) == 3
    for c, dJ in zip(colors, rec.dJ):
        assert np.array_equal(c, colormap(dJ.astype(np.float32), p["color:high"][0], p["color:low"][0]))
    assert np.ptp(rec.dJ[-1]) > 0  # the frames do differ, so the check above can tell a range apart
    assert np.any(colors[-1] == colormap(np.array([hi], np.float32), hi)[0])  # the top colour is used
    assert layout.declared(path)["title"] == f"particles: dJ 0 to {hi:.3g} (the run's range)"


def test_speed_colours_follow_the_speed_map_over_the_runs_range(tmp_path):
    """log.color=speed: the particles' |v| [m/s] is recorded and coloured on
    the map from 0 to the fastest particle of any logged frame; the ball
    falls from rest, so that is g t at the last frame (t = 0.04 s)."""
    path = run(tmp_path, ["scene.resolution=16", "run.steps=40", "log.every=20", "log.color=speed"])
    rec = recordings.read(path)
    final = np.load(tmp_path / "final_state.npz")
    assert np.allclose(rec.fields[-1]["speed"], np.linalg.norm(final["v"], axis=1), rtol=1e-6)
    assert rec.fields[0]["speed"].max() == 0.0  # the ball starts at rest
    p = rec.properties
    assert p["color:field"] == ["speed"] and p["color:unit"] == ["m/s"] and p["color:source"] == ["the run's range"]
    top = max(float(f["speed"].max()) for f in rec.fields)
    assert p["color:low"] == [0.0] and np.isclose(p["color:high"][0], top, rtol=1e-6)
    assert np.isclose(top, 9.81 * rec.times[-1], rtol=1e-3)  # free fall: v = g t (float32)
    from rerun.chunk import RrdReader

    df = RrdReader(str(path)).stream().collect().reader(index="step", contents="/particles").to_pandas()
    colors = [np.asarray(c, np.uint32) for c in df["/particles:Points2D:colors"] if c is not None]
    assert len(colors) == len(rec.steps) == 3
    for c, speed in zip(colors, rec.fields):
        assert np.array_equal(c, colormap(speed["speed"], p["color:high"][0], 0.0))
    assert not np.array_equal(colors[0], colors[-1])  # the ball has picked up speed: its colour changed
    legend = RrdReader(str(path)).stream().collect().reader(index=None, contents="/legend").to_pandas()
    assert f"speed 0 to {top:.3g} m/s" in str(legend.iloc[0].to_dict())
    # a range given in the config replaces the run's; a bad one is refused naming the key
    path = run(tmp_path / "given", ["scene.resolution=16", "run.steps=1", "log.color=speed",
                                    "log.color_range=[0,2.5]"])
    assert recordings.read(path).properties["color:high"] == [2.5]
    with pytest.raises(ValueError, match=r"^log.color_range: \[2.0, 1.0\]; accepted: \[low, high\]"):
        resolve(compose_cfg(["log.color_range=[2,1]"]))


# ---------------------------------------------------------------- frames, looked at

def test_a_falling_body_moves_down_the_frames(tmp_path):
    """The ball falls: its pixels move down the picture by its fall at the
    picture's scale (pixels per metre measured on the ball's width)."""
    path = run(tmp_path, ["scene.resolution=16", "run.duration=0.15", "log.every=1000000"])
    rec = recordings.read(path)
    frames = render_frames(rec, tmp_path / "frames")
    assert len(frames) == 2
    body = PALETTE[0]
    rows, widths = [], []
    for f in frames:
        m = blob(mask(pixels(f), body))
        r, c = np.nonzero(m)
        assert len(r) > 200, "the ball is drawn"
        rows.append(r.mean())
        widths.append(c.max() - c.min() + 1)
    x = rec.positions[0]
    per_metre = widths[0] / (np.ptp(x[:, 0]) + 2 * rec.radius)  # the drawn ball's width
    fall = rec.positions[0][:, 1].mean() - rec.positions[-1][:, 1].mean()  # [m], > 0
    assert fall > 0.05
    moved = rows[1] - rows[0]  # image rows grow downwards
    # 15 %: a pixel of rounding at each edge of the ~100 px ball and the ball's slight squash
    assert moved == pytest.approx(fall * per_metre, rel=0.15), (moved, fall * per_metre)


@pytest.fixture(scope="module")
def two_bodies(tmp_path_factory):
    """two_disks with body b made of a plastic material (body a has no plastic strain)."""
    d = tmp_path_factory.mktemp("two")
    return recordings.read(run(d, ["scene=two_disks", "scene.bodies.1.material.model=von_mises",
                                   "run.steps=2", "log.every=1"]))


def test_every_body_of_a_two_body_scene_is_drawn_with_a_legend(tmp_path, two_bodies):
    """Coloured by body: both disks (equal areas) in their colours."""
    frames = render_frames(two_bodies, tmp_path / "body", every=10)
    img = pixels(frames[0])
    a, b = mask(img, PALETTE[0]).sum(), mask(img, PALETTE[1]).sum()
    assert a > 500 and b > 500 and 0.8 < a / b < 1.25  # two equal disks; the legend's markers are tiny


def test_a_field_that_one_body_lacks_draws_that_body_grey(tmp_path, two_bodies):
    """--color plastic_strain: body a has no value (NaN) and is drawn grey;
    body b on the colour map; both disks, of equal areas."""
    from pipelines.recording.display import NO_VALUE

    frames = render_frames(two_bodies, tmp_path / "field", color="plastic_strain", every=10)
    img = pixels(frames[0])
    grey = mask(img, np.round(np.array(NO_VALUE) * 255), tol=8).sum()
    viridis0 = mask(img, (68, 1, 84), tol=30).sum()  # plastic strain 0: the map's lowest colour
    assert grey > 500 and viridis0 > 500 and 0.7 < grey / viridis0 < 1.4


@pytest.mark.slow
@pytest.mark.parametrize("view", ["xy", "xz", "3d"])
def test_colliders_appear_in_every_view(tmp_path_factory, view):
    """A 3D scene with a collider (the cup): the frames with the collider
    differ from the same frames without it, inside the picture's axes."""
    cup = _cup(tmp_path_factory)
    out = tmp_path_factory.mktemp(f"cup-{view}")
    with_it = pixels(render_frames(cup, out / "with", view=view)[0])
    bare = recordings.Recording(**{**cup.__dict__, "colliders": {}})
    without = pixels(render_frames(bare, out / "without", view=view)[0])
    changed = np.any(with_it != without, axis=-1)
    assert changed.sum() > 2000, changed.sum()


_CUP = {}


def _cup(factory):
    if "rec" not in _CUP:
        d = factory.mktemp("cup")
        _CUP["rec"] = recordings.read(run(d, ["scene=viscous_cup", "scene.resolution=20", "scene.wall_cells=1",
                                              "run.steps=1", "log.every=1"]))
    return _CUP["rec"]


def test_frames_from_the_command_line_state_time_and_refuse_unknown_fields(tmp_path):
    """The CLI writes a frame per logged step; an unknown field is one line, exit 2."""
    path = run(tmp_path / "r", ["scene.resolution=16", "run.steps=2", "log.every=1"])
    p = subprocess.run([sys.executable, "-m", "pipelines.replay", str(path), "--frames", str(tmp_path / "f")],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert len(list((tmp_path / "f").glob("frame_*.png"))) == 3
    p = subprocess.run([sys.executable, "-m", "pipelines.replay", str(path), "--frames", str(tmp_path / "f"),
                        "--color", "nope"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 2 and p.stderr.strip().splitlines() == [
        "error: --color nope: not in this recording; accepted: body, dJ"]


def test_series_names_carry_units_per_dimension():
    """2D quantities are per metre of depth; counts and fractions say so."""
    assert layout.label("kinetic_energy", 3) == "kinetic energy [J]"
    assert layout.label("kinetic_energy", 2) == "kinetic energy [J/m]"
    assert layout.label("angular_momentum_z", 3) == "angular momentum z [kg m²/s]"
    assert layout.label("momentum_x", 2) == "momentum x [kg/s]"
    assert layout.label("/timings/step_time_ms", 2) == "step time [ms]"
    assert layout.label("marked_fraction/ball", 2) == "marked fraction/ball (fraction)"
    assert layout.unit("something_new", 2) == ""


def test_the_viewer_opens_the_timings_file_too(tmp_path, monkeypatch):
    """replay --web hands the viewer both files, so the wall-clock series shows."""
    from pipelines.recording import display as replay

    path = run(tmp_path, ["scene.resolution=16", "run.steps=1", "log.every=1"])
    called = []
    monkeypatch.setattr(replay.subprocess, "call", lambda cmd: called.append(cmd) or 0)
    assert replay.open_viewer(path, web=True) == 0
    assert called[0][1:] == [str(path), str(recordings.timings_path(path)), "--web-viewer"]
