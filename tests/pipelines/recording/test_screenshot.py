"""``python -m pipelines.recording.screenshot``: what it needs is checked
before anything starts, the picture has the size asked for, and no process
it started (the viewer's server, the browser, their children) outlives it,
after success and after a failure. A stand-in browser
(tests/pipelines/recording/fake_chromium.py) speaks the DevTools calls, so
the tests run without Chromium; the server is Rerun's own. "No process"
means none alive and none a zombie: what the browser detached from its
group (as Chromium's crash handlers) is ended and reaped too."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from PIL import Image

from pipelines.recording import screenshot as shot

FAKE = Path(__file__).with_name("fake_chromium.py")


@pytest.fixture
def recording(tmp_path) -> Path:
    path = tmp_path / "recording.rrd"
    rec = rr.RecordingStream("screenshot_test")
    rec.save(str(path))
    rec.log("points", rr.Points2D(np.zeros((3, 2))))
    rec.flush()
    rec.disconnect()
    return path


@pytest.fixture
def chromium(tmp_path, monkeypatch) -> Path:
    """An executable that runs the stand-in browser with this Python."""
    exe = tmp_path / "chromium"
    exe.write_text(f"#!/bin/sh\nexec {sys.executable} {FAKE} \"$@\"\n")
    exe.chmod(0o755)
    return exe


@pytest.fixture
def detached(tmp_path, monkeypatch) -> Path:
    """The file where the stand-in browser writes its detached process's pid."""
    path = tmp_path / "detached.pid"
    monkeypatch.setenv("FAKE_CHROMIUM_DETACHED", str(path))
    return path


def gone(pid: int) -> bool:
    """No process ``pid``: neither running nor a zombie."""
    return not os.path.exists(f"/proc/{pid}") if os.path.isdir("/proc") else True


def singleton_dirs() -> set[str]:
    return {d for d in os.listdir(tempfile.gettempdir()) if d.startswith("org.chromium.Chromium.")}


@pytest.fixture
def groups(monkeypatch) -> list[subprocess.Popen]:
    """The processes the screenshot starts (each leads a group of its own)."""
    started, start = [], shot._start

    def record(cmd):
        p = start(cmd)
        started.append(p)
        return p

    monkeypatch.setattr(shot, "_start", record)
    return started


def test_the_picture_has_the_size_asked_for_and_nothing_is_left(recording, chromium, groups, detached, tmp_path):
    dirs = singleton_dirs()
    out = shot.screenshot(recording, tmp_path / "out.png", wait=0.0, size=(640, 360), chromium=str(chromium))
    assert Image.open(out).size == (640, 360)
    assert len(groups) == 2  # the server, the browser
    assert all(p.returncode is not None and shot.group_members(p.pid) == [] for p in groups)
    assert gone(int(detached.read_text()))  # the browser's detached process: ended and reaped
    assert singleton_dirs() <= dirs  # the browser's singleton directory removed


def test_a_failed_screenshot_leaves_no_process(recording, chromium, groups, detached, tmp_path, monkeypatch):
    """The browser never answers: the screenshot fails after its start
    timeout, and the server, the browser, the browser's child and its
    detached process are gone (twice, so that a second use finds nothing of
    the first)."""
    monkeypatch.setenv("FAKE_CHROMIUM", "silent")
    for _ in range(2):
        with pytest.raises(OSError):
            shot.screenshot(recording, tmp_path / "out.png", wait=0.0, chromium=str(chromium), start_timeout=2.0)
        assert gone(int(detached.read_text()))
    assert len(groups) == 4
    assert all(shot.group_members(p.pid) == [] for p in groups)
    assert not (tmp_path / "out.png").exists()


def test_missing_requirements_stop_it_before_anything_starts(recording, monkeypatch, capsys):
    monkeypatch.setattr(shot.shutil, "which", lambda name: None)
    monkeypatch.setattr(shot, "_start", lambda cmd: pytest.fail(f"started {cmd}"))
    assert shot.main([str(recording), "out.png"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: the screenshot needs chromium (apt-get install chromium)")


@pytest.mark.parametrize("args,key", [(["--size", "1600"], "--size"), (["--size", "0x900"], "--size"),
                                      (["--wait", "nan"], "--wait"), (["--wait", "-1"], "--wait")])
def test_bad_arguments_are_one_line(recording, args, key, monkeypatch, capsys):
    monkeypatch.setattr(shot, "_start", lambda cmd: pytest.fail(f"started {cmd}"))
    assert shot.main([str(recording), "out.png", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {key}: ") and "accepted: " in err


@pytest.mark.parametrize("fault,said", [
    ("hang", "the browser did not answer Page.captureScreenshot within 2 s"),
    ("close", "the browser closed the DevTools connection during Page.captureScreenshot"),
    ("error", "the browser refused Page.captureScreenshot: Unable to capture screenshot"),
])
def test_a_browser_that_hangs_drops_or_refuses_is_one_line_and_leaves_nothing(
        recording, chromium, groups, detached, tmp_path, monkeypatch, fault, said):
    """At the screenshot call the stand-in browser never answers (each call
    has CALL_TIMEOUT: here 2 s; it blocked forever with both processes
    running), drops the connection or replies with an error (a TypeError or
    KeyError traceback): one line saying which, and nothing left running."""
    monkeypatch.setenv("FAKE_CHROMIUM", fault)
    monkeypatch.setattr(shot, "CALL_TIMEOUT", 2.0)
    with pytest.raises(RuntimeError) as caught:
        shot.screenshot(recording, tmp_path / "out.png", wait=0.0, chromium=str(chromium))
    assert str(caught.value) == said
    assert len(groups) == 2 and all(shot.group_members(p.pid) == [] for p in groups)
    assert gone(int(detached.read_text())) and not (tmp_path / "out.png").exists()


def dead(pid: int) -> bool:
    """``pid`` is not running: absent, or a zombie its new parent has not reaped."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_what_it_starts_dies_with_it_even_when_it_is_killed():
    """A process that started a child through screenshot._start (its own
    session, as the server and the browser) is SIGKILLed, leaving no cleanup
    to run: the child dies too (it outlived it)."""
    code = ("import sys, time; from pipelines.recording.screenshot import _start; "
            "p = _start(['sleep', '300']); print(p.pid, flush=True); time.sleep(300)")
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    assert not dead(child)
    parent.kill()
    parent.wait()
    for _ in range(100):
        if dead(child):
            break
        import time
        time.sleep(0.05)
    assert dead(child)


def test_a_second_signal_waits_for_the_cleanup():
    """While the cleanup ends the processes, SIGTERM and SIGINT are held
    (a second one skipped the rest of it) and acted on once it is done."""
    import signal

    class Stopped(Exception):
        pass

    def stop(signum, frame):
        raise Stopped(signum)

    before = signal.signal(signal.SIGTERM, stop)
    try:
        held = shot._hold_signals()
        os.kill(os.getpid(), signal.SIGTERM)  # during the cleanup: held
        with pytest.raises(Stopped):
            shot._release_signals(held)  # then acted on
        assert signal.getsignal(signal.SIGTERM) is stop
    finally:
        signal.signal(signal.SIGTERM, before)
