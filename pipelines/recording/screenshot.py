"""``python -m pipelines.recording.screenshot <recording.rrd | run dir> <out.png>``:
a picture of a recording in Rerun's web viewer, without a display.

Serves the recording (and its timings file) with ``rerun --serve-web`` on
the loopback interface, opens the viewer in headless Chromium (software GL)
and takes the screenshot through the DevTools protocol once the viewer has
had ``--wait`` seconds to load (its wasm takes about a minute on two cores).
Needs Chromium (``apt-get install chromium``) and ``aiohttp`` (``pip install
-e ".[screenshot]"``), both checked before anything starts. The server and
the browser run in process groups of their own, ended on every way out
(success, failure, Ctrl-C, SIGTERM; a second signal during that cleanup
waits for it), and on Linux die with this process even when it is killed
(a parent-death signal). Each DevTools call gets CALL_TIMEOUT seconds and
the capture DEADLINE beyond ``--wait``; an error reply, a dropped
connection or a missed deadline is one line. On Linux this process also adopts what
the browser detaches from its group (its crash handlers) and ends and reaps
it, so that not even a zombie is left when it returns (a child another
thread starts meanwhile would be taken for one of the browser's).
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import ctypes
import json
import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

from .display import rerun_executable
from .sinks import timings_path

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for(url: str, seconds: float) -> None:
    end = time.monotonic() + seconds
    while True:
        try:
            urllib.request.urlopen(url, timeout=2).read()
            return
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.5)


def requirements(chromium: str | None = None) -> tuple[str, list[str]]:
    """The Chromium executable, and what is missing (one phrase each: what
    to install); nothing is started."""
    chromium = chromium or shutil.which("chromium") or shutil.which("chromium-browser") or ""
    missing = [] if chromium else ["chromium (apt-get install chromium)"]
    if importlib.util.find_spec("aiohttp") is None:
        missing.append('aiohttp (pip install -e ".[screenshot]")')
    return chromium, missing


def _parent_death_signal() -> None:
    """In the child before it runs (Linux): SIGKILL when this process dies,
    even by SIGKILL, which leaves no cleanup to run (prctl PR_SET_PDEATHSIG)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1


def _start(cmd: list[str]) -> subprocess.Popen:
    """``cmd`` in a process group of its own (the group's id is its pid),
    killed if this process dies (:func:`_parent_death_signal`)."""
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            preexec_fn=_parent_death_signal if sys.platform.startswith("linux") else None)


def _escalate(send, alive) -> None:
    """``send(SIGTERM)``, then ``send(SIGKILL)`` if ``alive()`` still holds
    5 s later (``alive`` may reap what has exited)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        send(sig)
        end = time.monotonic() + 5.0
        while alive() and time.monotonic() < end:
            time.sleep(0.05)
        if not alive():
            return


def _end(p: subprocess.Popen) -> None:
    """End ``p``'s whole process group (a wrapper's children too, e.g. the
    venv's ``rerun`` script and the viewer binary it starts): SIGTERM, then
    SIGKILL to what is left after 5 s."""
    def send(sig):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, sig)

    def alive():
        p.poll()  # reap the leader
        return bool(group_members(p.pid))

    _escalate(send, alive)
    p.wait()


def _children() -> set[int]:
    """The pids whose parent is this process (Linux; elsewhere none)."""
    return {pid for pid, ppid, _, _ in _proc_stats() if ppid == os.getpid()}


def _proc_stats():
    """(pid, ppid, pgid, state) of every process in /proc."""
    if not os.path.isdir("/proc"):
        return
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            yield int(entry), int(fields[1]), int(fields[2]), fields[0]  # fields: state, ppid, pgrp, ...


def _subreaper(on: bool) -> bool:
    """Linux: make this process (or stop it being) the parent of its
    orphaned descendants (prctl PR_SET_CHILD_SUBREAPER); returns whether it
    was one before. Elsewhere nothing, False."""
    if not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(None, use_errno=True)
    was = ctypes.c_int(0)
    libc.prctl(37, ctypes.byref(was), 0, 0, 0)  # PR_GET_CHILD_SUBREAPER
    libc.prctl(36, int(on), 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    return bool(was.value)


def _end_adopted(pids: set[int]) -> None:
    """End and reap the adopted orphans ``pids`` (children of this process
    not started by it): SIGTERM, then SIGKILL to what is left after 5 s."""
    left = set(pids)

    def send(sig):
        for pid in left:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)

    def alive():
        for pid in list(left):
            try:
                done = os.waitpid(pid, os.WNOHANG)[0]
            except ChildProcessError:
                done = pid
            if done:
                left.discard(pid)
        return bool(left)

    _escalate(send, alive)
    for pid in left:
        os.waitpid(pid, 0)


def _remove_singleton_dir(profile: str) -> None:
    """Remove the temporary directory holding the browser's singleton
    socket (``/tmp/org.chromium.Chromium.*``, linked from its profile),
    which a headless browser leaves behind."""
    link = Path(profile) / "SingletonSocket"
    if link.is_symlink():
        target = Path(os.readlink(link)).parent
        if target.name.startswith("org.chromium.Chromium.") and target.parent == Path(tempfile.gettempdir()):
            shutil.rmtree(target, ignore_errors=True)


def group_members(pgid: int) -> list[int]:
    """The live (not zombie) processes of process group ``pgid`` (Linux:
    from /proc; elsewhere [pgid] while the group exists)."""
    if not os.path.isdir("/proc"):
        try:
            os.killpg(pgid, 0)
            return [pgid]
        except ProcessLookupError:
            return []
    return [pid for pid, _, group, state in _proc_stats() if group == pgid and state != "Z"]


CALL_TIMEOUT = 30.0  # [s] a DevTools call's answer at most
DEADLINE = 60.0  # [s] the whole capture at most, beyond --wait


async def _capture(port: int, url: str, out: Path, wait: float, size: tuple[int, int]) -> None:
    import aiohttp

    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5) as r:
        page = next(t for t in json.load(r) if t["type"] == "page")
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(page["webSocketDebuggerUrl"], max_msg_size=0) as ws:
            ids = iter(range(1, 1000))

            async def answer(n: int, method: str):
                async for msg in ws:
                    if msg.type != aiohttp.WSMsgType.TEXT:
                        break
                    data = json.loads(msg.data)
                    if data.get("id") == n:
                        if "error" in data:
                            raise RuntimeError(f"the browser refused {method}: "
                                               f"{data['error'].get('message', data['error'])}")
                        return data.get("result", {})
                raise RuntimeError(f"the browser closed the DevTools connection during {method}")

            async def call(method: str, **params):
                n = next(ids)
                await ws.send_json({"id": n, "method": method, "params": params})
                try:
                    return await asyncio.wait_for(answer(n, method), CALL_TIMEOUT)
                except asyncio.TimeoutError:
                    raise RuntimeError(f"the browser did not answer {method} within {CALL_TIMEOUT:g} s") from None

            await call("Page.enable")
            # the page's size is the picture's (the window's would lose the browser's own frame)
            await call("Emulation.setDeviceMetricsOverride", width=size[0], height=size[1], deviceScaleFactor=1,
                       mobile=False)
            await call("Page.navigate", url=url)
            await asyncio.sleep(wait)
            shot = await call("Page.captureScreenshot", format="png")
            if "data" not in shot:
                raise RuntimeError("the browser's Page.captureScreenshot returned no picture")
            out.write_bytes(base64.b64decode(shot["data"]))


async def _within(coroutine, seconds: float):
    """``coroutine`` with an overall deadline (RuntimeError, one line, past it)."""
    try:
        return await asyncio.wait_for(coroutine, seconds)
    except asyncio.TimeoutError:
        raise RuntimeError(f"the capture took longer than {seconds:g} s") from None


def screenshot(recording: Path, out: Path, wait: float = 90.0, size=(1600, 900), chromium: str | None = None,
               start_timeout: float = 60.0) -> Path:
    """``out``: the web viewer's picture of ``recording`` after ``wait``
    seconds [s], ``size`` pixels (width, height); the server and the browser
    each get ``start_timeout`` seconds to answer."""
    chromium, missing = requirements(chromium)
    if missing:
        raise RuntimeError(f"the screenshot needs {' and '.join(missing)}")
    web, grpc, devtools = _free_port(), _free_port(), _free_port()
    files = [str(recording)] + ([str(timings_path(recording))] if timings_path(recording).is_file() else [])
    profile = tempfile.mkdtemp(prefix="chromium-")
    started: list[subprocess.Popen] = []
    previous = signal.getsignal(signal.SIGTERM)
    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread:
        signal.signal(signal.SIGTERM, _terminated)  # SIGTERM unwinds through the finally below
    children, was_subreaper = _children(), _subreaper(True)
    try:
        started.append(_start([rerun_executable(), "--serve-web", "--web-viewer-port", str(web), "--port", str(grpc),
                               *files]))
        _wait_for(f"http://127.0.0.1:{web}/", start_timeout)
        url = f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
        started.append(_start([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                               f"--window-size={size[0]},{size[1]}", f"--remote-debugging-port={devtools}",
                               "about:blank"]))
        _wait_for(f"http://127.0.0.1:{devtools}/json/version", start_timeout)
        try:
            asyncio.run(_within(_capture(devtools, url, Path(out), wait, size), wait + DEADLINE))
        except (OSError, StopIteration, ValueError, KeyError) as e:  # aiohttp's connection errors are OSErrors
            raise RuntimeError(f"the browser's DevTools connection failed: "
                               f"{str(e).splitlines()[0] if str(e) else type(e).__name__}") from e
    finally:
        held = _hold_signals() if main_thread else {}  # a second SIGTERM or Ctrl-C waits for the cleanup
        for p in reversed(started):
            _end(p)
        _end_adopted(_children() - children - {p.pid for p in started})
        if not was_subreaper:
            _subreaper(False)
        _remove_singleton_dir(profile)
        shutil.rmtree(profile, ignore_errors=True)
        if main_thread:
            _release_signals(held)
            signal.signal(signal.SIGTERM, previous)
    return Path(out)


def _hold_signals() -> dict:
    """Ignore SIGTERM and SIGINT while the started processes are ended (a
    second one would skip the rest of the cleanup); the handlers before, and
    whether one came meanwhile, for :func:`_release_signals`."""
    came: list[int] = []
    held = {sig: signal.signal(sig, lambda signum, frame: came.append(signum)) for sig in (signal.SIGTERM,
                                                                                           signal.SIGINT)}
    return {"handlers": held, "came": came}


def _release_signals(held: dict) -> None:
    """The handlers :func:`_hold_signals` replaced; a signal that came
    meanwhile is acted on now (the cleanup is done)."""
    for sig, handler in held["handlers"].items():
        signal.signal(sig, handler)
    if held["came"]:
        signal.raise_signal(held["came"][0])


def _terminated(signum, frame):
    raise SystemExit(128 + signum)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--wait", type=float, default=90.0, help="seconds the viewer gets to load before the picture")
    p.add_argument("--size", default="1600x900", help="window size [px], WIDTHxHEIGHT")
    args = p.parse_args(argv)
    rec = args.recording / "recording.rrd" if args.recording.is_dir() else args.recording
    if not rec.is_file():
        print(f"error: recording: {rec}: no such file", file=sys.stderr)
        return 2
    try:
        w, h = (int(v) for v in args.size.split("x"))
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise ValueError
    except ValueError:
        print(f"error: --size: {args.size!r}; accepted: WIDTHxHEIGHT in pixels (16 to 8192), e.g. 1600x900",
              file=sys.stderr)
        return 2
    if not (args.wait >= 0.0 and args.wait < float("inf")):
        print(f"error: --wait: {args.wait}; accepted: a finite number of seconds >= 0", file=sys.stderr)
        return 2
    _, missing = requirements()
    if missing:
        print(f"error: the screenshot needs {' and '.join(missing)}", file=sys.stderr)
        return 2
    try:
        print(screenshot(rec, args.out, args.wait, (w, h)))
    except (OSError, RuntimeError) as e:
        print(f"error: screenshot: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
