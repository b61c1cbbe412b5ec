"""Recordings: complete, readable back, bit-identical between two runs (by
our reader and by Rerun's own ``rerun rrd compare``); the wall-clock side in
a file of its own."""

import subprocess
import sys

import numpy as np
import pytest

from omegaconf import OmegaConf

from helpers import compose_cfg
from pipelines.recording import recordings
from pipelines.config.validate import resolve
from pipelines.run.runner import execute


def run_twice(tmp_path, overrides):
    out = []
    for name in ("a", "b"):
        cfg = compose_cfg(overrides)
        metrics = execute(resolve(cfg), tmp_path / name, OmegaConf.to_yaml(cfg), overrides)
        assert metrics["status"] == "completed"
        out.append(recordings.read(tmp_path / name / "recording.rrd"))
    return out


@pytest.mark.bitwise
def test_two_runs_are_bit_identical_and_complete(tmp_path):
    steps = 12
    overrides = ["scene=rotating_plate_2d", f"run.steps={steps}", "log.every=3"]
    a, b = run_twice(tmp_path, overrides)
    # particles on steps 0, 3, ..., 12, each with positions and dJ
    assert a.steps.tolist() == list(range(0, steps + 1, 3))
    assert a.dim == 2
    n = len(a.positions[0])
    assert n > 100
    for field in ("positions", "dJ"):
        for k, (xa, xb) in enumerate(zip(getattr(a, field), getattr(b, field), strict=True)):
            assert xa is not None and xa.shape[0] == n
            assert np.array_equal(xa, xb), (field, k)
    # dJ = |det(I + dt C) - 1| is zero before the first step; for the spinning
    # plate det(I + dt W) = 1 + (omega dt)^2 after it
    assert np.all(a.dJ[0] == 0)
    assert np.max(a.dJ[-1]) > 0
    # scalars every step (0..steps), identical
    sa, sb = a.scalars, b.scalars
    for name in ("mass", "momentum_x", "momentum_y", "angular_momentum", "kinetic_energy",
                 "elastic_energy", "potential_energy", "total_energy", "max_speed", "dt",
                 "config_updates"):
        assert name in sa, name
    assert sa["mass"][0].tolist() == list(range(steps + 1))
    for name in sa:
        assert np.array_equal(sa[name][0], sb[name][0]), name
        assert np.array_equal(sa[name][1], sb[name][1]), name
    # the wall clock is in the timings file: a step time for steps 1..steps, and when and where
    assert "step_time_ms" not in sa
    assert a.timings["step_time_ms"][0].tolist() == list(range(1, steps + 1))
    assert np.all(a.timings["step_time_ms"][1] > 0)
    assert set(a.run) == {"started", "host", "command"}
    assert a.complete and a.end == (steps, float(a.times[-1]))
    assert sa["config_updates"][1].tolist() == list(range(steps + 1))
    # recording properties
    props = a.properties
    for key in ("config:overrides", "config:yaml", "provenance:git_commit", "provenance:git_dirty",
                "provenance:device", "provenance:precision", "provenance:seed", "packages:warp-lang",
                "packages:rerun-sdk", "packages:hydra-core"):
        assert key in props, key
    assert props["config:overrides"] == overrides
    assert "scene:" in props["config:yaml"][0]


@pytest.mark.bitwise
def test_rerun_compare_finds_two_identical_runs_equal(tmp_path):
    """The standard tool agrees: identical physics gives identical recordings
    (the wall-clock timings differ, in their own files); another Young's
    modulus does not."""
    base = ["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=6", "log.every=2",
            "scheme=aulmpm", "scheme.epsilon=1e-6"]
    for name, extra in (("a", []), ("b", []), ("c", ["scene.bodies.0.material.E=1.1e3"])):
        cfg = compose_cfg(base + extra)
        m = execute(resolve(cfg), tmp_path / name, OmegaConf.to_yaml(cfg), base)
        assert m["status"] == "completed" and m["config_updates"]["total"] > 0

    def compare(x, y, file="recording.rrd"):
        return subprocess.run([sys.executable, "-m", "rerun", "rrd", "compare", "--unordered",
                               str(tmp_path / x / file), str(tmp_path / y / file)],
                              capture_output=True, text=True)

    same = compare("a", "b")
    assert same.returncode == 0, same.stderr[-2000:]
    assert compare("a", "c").returncode != 0
    assert compare("a", "b", "recording.timings.rrd").returncode != 0  # step times differ


def test_particles_are_logged_at_a_frame_rate_in_simulated_time(tmp_path):
    """log.every null: a frame at the first step at or past each multiple of
    1 / log.fps, and the last step; coloured by body by default."""
    fps, duration = 100.0, 0.05
    cfg = compose_cfg(["scene.resolution=24", f"run.duration={duration}", f"log.fps={fps}"])
    spec = resolve(cfg)
    assert spec.log.every is None and spec.log.color == "body"
    m = execute(spec, tmp_path, OmegaConf.to_yaml(cfg), [])
    assert m["status"] == "completed" and m["steps"] > 20
    rec = recordings.read(tmp_path / "recording.rrd")
    steps, times = rec.scalars["dt"][0], np.cumsum(rec.scalars["dt"][1])  # t after steps 1, 2, ...
    t_of = dict(zip(steps.tolist(), times.tolist()))
    t_of[0] = 0.0
    frames = rec.steps.tolist()
    assert frames[0] == 0 and frames[-1] == m["steps"]
    k = np.floor(np.array([t_of[s] for s in frames]) * fps * (1 + 1e-9))
    assert np.all(np.diff(k[:-1]) == 1)  # one frame per 1/fps interval
    for s in frames[1:-1]:  # each is the first step past its multiple
        assert np.floor(t_of[s - 1] * fps * (1 + 1e-9)) < np.floor(t_of[s] * fps * (1 + 1e-9))
    assert len(frames) in (round(duration * fps) + 1, round(duration * fps) + 2)  # the last may land on one
    assert m["recording_estimate_mb"] > 0
    # the scalar rows' clock: the simulated time after each step
    assert np.allclose(np.interp(steps, *rec.clock), times, rtol=1e-6, atol=0)
    # without the frames (what the reports read): the same scalars, properties and clock
    light = recordings.read(tmp_path / "recording.rrd", particles=False)
    assert light.positions == [] and len(light.steps) == 0
    assert light.scalars.keys() == rec.scalars.keys() and light.properties == rec.properties
    for name, (s, v) in rec.scalars.items():
        assert np.array_equal(light.scalars[name][0], s) and np.array_equal(light.scalars[name][1], v)
    assert np.array_equal(light.clock[0], rec.clock[0]) and light.end == rec.end


def test_the_colour_map_spans_viridis_from_zero_to_the_top():
    """0 and below -> viridis' first colour, top and above -> its last; a
    value u in between -> the map interpolated at floor(255 u) / 255 (256
    levels), rounded; NaN -> grey."""
    from pipelines.recording.colours import GREY, VIRIDIS, colormap, packed

    values = np.array([-1.0, 0.0, 0.5, 1.0, 2.0, np.nan], np.float32)
    c = colormap(values, 1.0)
    assert c.dtype == np.uint32
    assert c[0] == c[1] == packed(VIRIDIS[0])[0] and c[3] == c[4] == packed(VIRIDIS[-1])[0]
    assert c[5] == packed(GREY)[0]
    rgb = np.array([(c[2] >> s) & 255 for s in (24, 16, 8)], float)
    u = np.floor(0.5 * 255) / 255
    expected = [np.interp(u, np.linspace(0.0, 1.0, len(VIRIDIS)), VIRIDIS[:, k]) for k in range(3)]
    assert np.all(np.abs(rgb - expected) <= 0.5 + 1e-9), (rgb, expected)
