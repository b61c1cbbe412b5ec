"""Checkpoints of the command line (pipelines.run.checkpoints): a run
pre-empted by SIGUSR1 leaves a checkpoint and exit code 75, and resumed with
``run.resume=true`` ends bit for bit as the run that was never stopped, its
metrics.json describing the whole run; a run writes its checkpoints every
``run.checkpoint_every`` and keeps the last two; ``run.resume`` takes the
newest that reads back and refuses, in one line, a folder without one or one
of another configuration or code version."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import mpm
from helpers import ROOT, run_cli
from pipelines.config.fields import ConfigError
from pipelines.recording import recordings
from pipelines.run import checkpoints

STEPS = ["run.steps=1500", "log.every=50"]
SAME = ("steps", "sim_time", "config_hash", "energy_final", "fracture", "config_updates", "dt", "dt_min", "dt_max",
        "dt_binding")


def _preempted(args: list[str], out) -> tuple[int, str]:
    """Run ``python <args>``, send it SIGUSR1 (as a scheduler pre-empts) once it has written a checkpoint newer
    than those in ``out`` now (it is stepping); its exit code and stderr."""
    before = checkpoints.listed(out / checkpoints.DIR)[:1]
    proc = subprocess.Popen([sys.executable, *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        deadline = time.time() + 300
        while (time.time() < deadline and checkpoints.listed(out / checkpoints.DIR)[:1] == before
               and proc.poll() is None):
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()[1]
        proc.send_signal(signal.SIGUSR1)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    return proc.returncode, err


@pytest.mark.slow
def test_a_preempted_run_resumes_to_the_end_of_the_whole_run_bit_for_bit(tmp_path):
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    p = run_cli([*STEPS, "run.checkpoint_every=0", f"hydra.run.dir={whole}"], cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    # a checkpoint every 0.02 s of simulated time shows it is stepping; then SIGUSR1, as a scheduler pre-empts;
    # twice: the resumed run is pre-empted too, and keeps the recording's parts for the next
    stops = []
    for args in ([], ["run.resume=true"]):
        code, err = _preempted(["-m", "pipelines.run", *STEPS, "run.checkpoint_every=0.02", *args,
                                f"hydra.run.dir={cut}"], cut)
        assert code == checkpoints.PREEMPTED == 75, err
        stopped = json.loads((cut / "metrics.json").read_text())
        assert stopped["status"] == "preempted" and stopped["reason"].startswith("SIGUSR1 at step"), stopped["reason"]
        assert 0 < stopped["steps"] < 1500
        kept = checkpoints.listed(cut / checkpoints.DIR)
        assert 1 <= len(kept) <= checkpoints.KEEP and kept[0].name == f"ckpt-{stopped['steps']}.npz"
        stops.append(stopped["steps"])
    assert (cut / f"recording.resumed-{stops[0]}.rrd").is_file() and (cut / "recording.resumed-0.rrd").is_file()
    assert recordings.read(cut / "recording.rrd").end[0] == stops[1]  # joined so far, to the second stop

    p = run_cli([*STEPS, "run.checkpoint_every=0.02", "run.resume=true", f"hydra.run.dir={cut}"], cwd=ROOT,
                timeout=300)
    assert p.returncode == 0, p.stderr
    a, b = np.load(whole / "final_state.npz"), np.load(cut / "final_state.npz")
    assert a.files == b.files
    for name in a.files:
        assert np.array_equal(a[name], b[name]), name
    m_whole, m_cut = (json.loads((d / "metrics.json").read_text()) for d in (whole, cut))
    assert m_cut["status"] == "completed" and m_cut["resumed_at"] == stops
    assert {k: m_cut.get(k) for k in SAME} == {k: m_whole.get(k) for k in SAME}
    assert len(checkpoints.listed(cut / checkpoints.DIR)) == checkpoints.KEEP
    # one recording in one file: the resumed part appended to the first, every step's scalars as the whole run's
    assert sorted(p.name for p in cut.glob("*.rrd")) == ["recording.rrd", "recording.timings.rrd"]
    one, other = (recordings.read(d / "recording.rrd") for d in (whole, cut))
    assert set(one.scalars) == set(other.scalars) and {"kinetic_energy", "elastic_energy", "dt"} <= set(one.scalars)
    for name in one.scalars:
        (s1, v1), (s2, v2) = one.scalars[name], other.scalars[name]
        assert np.array_equal(s1, s2) and np.array_equal(v1, v2), name
    assert np.array_equal(one.steps, other.steps) and len(one.steps) == 1500 // 50 + 1  # the particle frames
    assert all(np.array_equal(a, b) for a, b in zip(one.positions, other.positions))


HANDED_ON = """
import runpy, signal, sys
marker = sys.argv.pop(1)
signal.signal(signal.SIGUSR1, lambda signum, frame: open(marker, "w").write(str(signum)))
sys.argv[0] = "pipelines.run"
runpy.run_module("pipelines.run", run_name="__main__")
"""


def test_a_preemption_hands_its_signal_on_to_the_handler_that_was_there_before(tmp_path):
    """A scheduler's own handler (submitit's requeue on its pre-emption signal) still hears the signal, once the
    run has written its checkpoint and metrics.json: the run then ends as pre-empted runs do (exit code 75)."""
    marker, out = tmp_path / "handed_on", tmp_path / "run"
    code, err = _preempted(["-c", HANDED_ON, str(marker), *STEPS, "run.checkpoint_every=0.02",
                            f"hydra.run.dir={out}"], out)
    assert code == checkpoints.PREEMPTED, err
    assert json.loads((out / "metrics.json").read_text())["status"] == "preempted"
    assert marker.read_text() == str(int(signal.SIGUSR1))  # after the checkpoint, not instead of it


def test_resume_without_a_checkpoint_is_refused_in_one_line_unless_null(tmp_path):
    p = run_cli(["run.steps=5", "run.resume=true", f"hydra.run.dir={tmp_path}"], cwd=ROOT, timeout=300)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1, p.stderr
    assert lines[0].startswith(f"error: run.resume: no checkpoint in {tmp_path / checkpoints.DIR}"), p.stderr
    # null (a requeued job's command): start anew where there is none
    p = run_cli(["run.steps=5", "run.resume=null", f"hydra.run.dir={tmp_path}"], cwd=ROOT, timeout=300)
    assert p.returncode == 0 and "resumed_at" not in json.loads((tmp_path / "metrics.json").read_text()), p.stderr


def _driver(steps: int, end: int | None = None) -> mpm.Driver:
    """A small run after ``steps`` of its ``end`` (None: as many) steps."""
    scene = mpm.Scene(dim=2, domain=(1.0, 1.0), resolution=16,
                      bodies=[mpm.Body(mpm.Sphere((0.5, 0.4), 0.1), mpm.NeoHookean(E=1e5, nu=0.3))])
    model, state = mpm.build(scene, mpm.QUADRATIC)
    driver = mpm.Driver(mpm.Solver(model, mpm.EMPM()), state, mpm.StepPolicy(steps=end or steps))
    driver.start()
    for _ in range(steps):
        driver.advance()
    return driver


def test_the_newest_checkpoint_that_reads_back_is_taken_and_another_config_refused(tmp_path):
    identity = {"config_hash": "abc"}
    every = checkpoints.Checkpoints(tmp_path, 0.0, identity, "rec-id")
    recorder = type("Recorder", (), {})()
    recorder.step_ms = [1.0, 2.0]
    for steps in (2, 3, 4):  # three written, two kept
        every.write(_driver(steps), recorder)
    assert [p.name for p in checkpoints.listed(tmp_path / checkpoints.DIR)] == ["ckpt-4.npz", "ckpt-3.npz"]
    data, notes = checkpoints.choose(tmp_path, identity)
    assert data.step == 4 and notes == [] and data.meta["recording_id"] == "rec-id"
    assert data.meta["recorder"]["step_ms"] == ("value", [1.0, 2.0])
    newest = tmp_path / checkpoints.DIR / "ckpt-4.npz"
    newest.write_bytes(newest.read_bytes()[:1000])  # a write cut short by a crash
    data, notes = checkpoints.choose(tmp_path, identity)
    assert data.step == 3 and len(notes) == 1 and "ckpt-4.npz: damaged" in notes[0] and "\n" not in notes[0]
    with pytest.raises(ConfigError) as e:
        checkpoints.choose(tmp_path, {"config_hash": "another"})
    assert str(e.value).startswith("run.resume: ") and "of another configuration" in str(e.value)
    assert "\n" not in str(e.value)


def test_the_checkpoints_fall_due_every_simulated_interval(tmp_path):
    every = checkpoints.Checkpoints(tmp_path, 0.01, {}, None)
    driver = _driver(1, 10)
    driver.time = 0.004
    assert not every.due(driver)
    driver.time = 0.0101
    assert every.due(driver)
    every.write(driver, type("Recorder", (), {})())
    assert not every.due(driver)
    driver.time = 0.02
    assert every.due(driver)
    assert not checkpoints.Checkpoints(tmp_path, 0.0, {}, None).due(driver)
    auto = checkpoints.Checkpoints(tmp_path, None, {}, None)
    assert "every 5 minutes of wall time" in auto.describe() and not auto.due(driver)
    auto._since -= checkpoints.AUTO_WALL_S
    assert auto.due(driver)


@pytest.mark.slow
def test_a_rerun_sweep_resumes_its_unfinished_job_from_its_checkpoint(tmp_path):
    """Two jobs that differ in their frames only; the sweep is killed (SIGKILL) once the second has
    written a checkpoint; the same command again skips the first and continues the second from its
    checkpoint, to the first's final state bit for bit."""
    sweep = tmp_path / "sweep"
    args = ["-m", "log.every=50,51", "run.steps=1500", "scene.resolution=32", "run.checkpoint_every=0.01",
            "hydra/launcher=basic", f"hydra.sweep.dir={sweep}"]
    proc = subprocess.Popen([sys.executable, "-m", "pipelines.run", *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.time() + 300
        while time.time() < deadline and proc.poll() is None and not checkpoints.listed(sweep / "1" / checkpoints.DIR):
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    finally:
        proc.kill()
    assert json.loads((sweep / "1" / "metrics.json").read_text())["status"] == "running"
    kept = checkpoints.listed(sweep / "1" / checkpoints.DIR)
    p = run_cli(args, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    assert f"skipped: {sweep / '0'} already holds this config's completed run" in p.stderr
    first, second = (json.loads((sweep / j / "metrics.json").read_text()) for j in ("0", "1"))
    assert second["status"] == "completed" and second["resumed_at"][0] >= int(kept[0].stem.split("-")[1])
    a, b = (np.load(sweep / j / "final_state.npz") for j in ("0", "1"))
    assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files)
    assert sorted(p.name for p in (sweep / "1").glob("*.rrd")) == ["recording.rrd", "recording.timings.rrd"]


def test_resuming_cuts_the_recording_back_to_its_sizes_at_the_checkpoint_whatever_a_kill_left(tmp_path):
    """The first file renamed to part 0 (also when a kill came between renaming it and its timings),
    each part cut back to its size in the checkpoint, the parts of later killed runs removed."""
    (tmp_path / "recording.rrd").write_bytes(b"a" * 100)
    (tmp_path / "recording.resumed-0.timings.rrd").write_bytes(b"t" * 50)  # renamed before the kill
    (tmp_path / "recording.resumed-7.rrd").write_bytes(b"b" * 80)
    (tmp_path / "recording.resumed-7.timings.rrd").write_bytes(b"u" * 40)
    (tmp_path / "recording.resumed-9.rrd").write_bytes(b"c" * 10)  # a later run's, killed before its checkpoint
    segments = [["recording.rrd", 60, 30], ["recording.resumed-7.rrd", 70, 20]]
    data = type("Checkpoint", (), {"path": tmp_path / "ckpt-9.npz", "meta": {"segments": segments}})
    parts = checkpoints.resume_segments(tmp_path, "recording.rrd", data)  # type: ignore[arg-type]
    assert parts == [["recording.resumed-0.rrd", 60, 30], ["recording.resumed-7.rrd", 70, 20]]
    sizes = {p.name: p.stat().st_size for p in tmp_path.glob("*.rrd")}
    assert sizes == {"recording.resumed-0.rrd": 60, "recording.resumed-0.timings.rrd": 30,
                     "recording.resumed-7.rrd": 70, "recording.resumed-7.timings.rrd": 20}
    data.meta["segments"][1][1] = 90  # a part shorter than the checkpoint says: refused in one line
    with pytest.raises(ConfigError) as e:
        checkpoints.resume_segments(tmp_path, "recording.rrd", data)  # type: ignore[arg-type]
    assert "recording.resumed-7.rrd is shorter than when ckpt-9.npz was written" in str(e.value)
