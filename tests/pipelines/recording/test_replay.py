"""pipelines.replay: reproduce a recording bit for bit, render frames."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from helpers import ROOT, run_cli
from pipelines.recording import recordings


@pytest.mark.slow
@pytest.mark.bitwise
def test_reproduce_reports_a_match_and_frames_are_written(tmp_path):
    run_dir = tmp_path / "run"
    p = run_cli(["scene=rotating_plate_2d", "run.steps=30", "log.every=10", f"hydra.run.dir={run_dir}"],
                cwd=ROOT)
    assert p.returncode == 0, p.stderr
    rec = run_dir / "recording.rrd"
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(rec), "--reproduce"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "match: 4 particle frames" in r.stdout and "identical bit for bit" in r.stdout
    assert len(list(run_dir.glob("reproduce-*/recording.rrd"))) == 1  # beside the recording, not in /tmp
    frames = tmp_path / "frames"
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(rec), "--frames", str(frames)],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    pngs = sorted(frames.glob("frame_*.png"))
    assert len(pngs) == 4 and all(p.stat().st_size > 1000 for p in pngs)
    assert pngs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_compare_reports_the_largest_deviation(tmp_path):
    recs = []
    for E in ("1e3", "1.1e3"):
        d = tmp_path / E
        p = run_cli(["scene=rotating_plate_2d", "run.steps=20", "log.every=10",
                     f"scene.bodies.0.material.E={E}", f"hydra.run.dir={d}"], cwd=ROOT)
        assert p.returncode == 0, p.stderr
        recs.append(recordings.read(d / "recording.rrd"))
    same = recordings.compare(recs[0], recs[0])
    assert same["match"] and not same["largest"]
    diff = recordings.compare(*recs)
    assert not diff["match"]
    assert 0 < diff["largest"]["positions"] < 1e-2
    assert "scalar:elastic_energy" in diff["largest"]
    assert recs[0].properties["config:overrides"][-1].startswith("scene.bodies.0.material.E=")
    assert np.array_equal(recs[0].steps, [0, 10, 20])


def test_compare_takes_frames_left_empty():
    """Every particle removed (through an open wall): the last frames hold
    none, and two such recordings still compare (they failed on their empty
    dJ)."""
    def rec(x):
        frames = [x, x[:0], x[:0]]
        return recordings.Recording(
            steps=np.arange(3), times=np.arange(3) * 0.1, positions=frames, dJ=[np.ones(len(f)) for f in frames],
            fields=[{}] * 3, body=None, colors=None, scalars={}, properties={}, update_steps=np.zeros(0, np.int64))

    x = np.random.default_rng(0).uniform(size=(10, 2))
    assert recordings.compare(rec(x), rec(x))["match"]
    assert not recordings.compare(rec(x), rec(x + 1e-3))["match"]


@pytest.mark.slow
def test_frames_of_a_3d_scene_with_colliders(tmp_path):
    """The cup is read back from the recording and drawn; a field colours the
    particles; an unknown field is refused in one line."""
    run_dir = tmp_path / "run"
    p = run_cli(["scene=viscous_cup", "scene.resolution=20", "scene.wall_cells=1", "run.steps=4",
                 "log.every=2", f"hydra.run.dir={run_dir}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr
    rec = recordings.read(run_dir / "recording.rrd")
    v, f = rec.colliders["cup"]
    assert v.shape[1] == 3 and f.shape[1] == 3 and f.max() < len(v)
    frames = tmp_path / "frames"
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(run_dir / "recording.rrd"), "--frames",
                        str(frames), "--color", "dJ"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert len(sorted(frames.glob("frame_*.png"))) == 3
    fresh = tmp_path / "frames_nope"
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(run_dir / "recording.rrd"), "--frames",
                        str(fresh), "--color", "nope"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        "error: --color nope: not in this recording; accepted: body, dJ"]
    assert not fresh.exists()  # refused before its folder is made (it was left behind, empty)


@pytest.mark.slow
def test_a_killed_run_is_read_and_repaired(tmp_path):
    """SIGKILL leaves no footer and no chance to finish: metrics.json still
    says running, the recording is read all the same (frames render, with a
    note), and --repair gives it a footer and marks the run killed."""
    run_dir = tmp_path / "run"
    cmd = [sys.executable, "-m", "pipelines.run", "scene.resolution=16", "run.steps=1000000",
           "log.every=5", "log.flush_every=20", "log.progress=false", f"hydra.run.dir={run_dir}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    rec = run_dir / "recording.rrd"
    try:
        deadline = time.monotonic() + 300
        while not (rec.is_file() and rec.stat().st_size > 300_000):  # some frames and scalar rows
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline
            time.sleep(0.2)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert json.loads((run_dir / "metrics.json").read_text())["status"] == "running"
    assert not recordings.is_complete(rec)
    killed = recordings.read(rec)
    assert not killed.complete and len(killed.steps) >= 2 and killed.end[0] >= killed.steps[-1]
    # power lost in the middle of writing a message: the messages before it are read
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(rec.read_bytes()[:-777])
    partial = recordings.read(cut)
    assert not partial.complete and 1 <= len(partial.steps) <= len(killed.steps)
    assert np.array_equal(partial.positions[0], killed.positions[0])
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(run_dir), "--frames",
                        str(tmp_path / "frames"), "--every", "1000"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0 and "has no footer" in r.stderr and "--repair" in r.stderr, r.stderr
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(run_dir), "--repair"], cwd=ROOT,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    repaired = recordings.read(rec)
    assert repaired.complete and recordings.compare(killed, repaired)["match"]
    assert (run_dir / "recording.backup.rrd").is_file()
    v = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(rec)], capture_output=True, text=True)
    assert v.returncode == 0, v.stderr
    m = json.loads((run_dir / "metrics.json").read_text())
    assert m["status"] == "killed" and m["steps"] == repaired.end[0] >= 5


def test_a_file_that_is_no_recording_is_one_line(tmp_path):
    bad = tmp_path / "recording.rrd"
    bad.write_text("not a recording")
    r = subprocess.run([sys.executable, "-m", "pipelines.replay", str(tmp_path), "--frames", str(tmp_path / "f")],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == [r.stderr.strip()] and "not a readable Rerun recording" in r.stderr


@pytest.mark.parametrize("every", ["0", "-3"])
def test_every_below_one_is_refused_in_one_line(tmp_path, every):
    """--every N takes every N-th logged step: N < 1 is refused before the
    recording is read, naming the option and what it accepts."""
    from pipelines.replay import main

    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main([str(tmp_path), "--frames", str(tmp_path / "f"), "--every", every])
    assert code == 2 and not (tmp_path / "f").exists()
    assert err.getvalue().strip() == f"error: --every: {every}; accepted: an integer >= 1 (every N-th logged step)"


def test_a_failed_reproduction_leaves_no_folder(tmp_path, monkeypatch):
    """--reproduce whose re-run fails (here: its process exits 1) says so
    and removes the reproduce-* folder it made beside the recording (it was
    left in the run directory)."""
    from pipelines import replay

    run_dir = tmp_path / "run"
    p = run_cli(["scene=rotating_plate_2d", "scene.resolution=16", "run.steps=2", "log.every=1",
                 f"hydra.run.dir={run_dir}"], cwd=ROOT)
    assert p.returncode == 0, p.stderr

    def failing(cmd, **keys):
        return subprocess.CompletedProcess(cmd, 1, "", "error: something broke")

    monkeypatch.setattr(replay.subprocess, "run", failing)
    r = replay.reproduce(run_dir / "recording.rrd")
    assert not r["match"] and "re-run failed (1): error: something broke" in r["problems"][0]
    assert not list(run_dir.glob("reproduce-*"))
