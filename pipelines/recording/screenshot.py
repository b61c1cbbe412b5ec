"""``python -m pipelines.recording.screenshot <recording.rrd | run dir> <out.png>``:
a picture of a recording in Rerun's web viewer, without a display.

Serves the recording (and its timings file) with ``rerun --serve-web`` on
the loopback interface, opens the viewer in headless Chromium (software GL)
and takes the screenshot through the DevTools protocol once the viewer has
had ``--wait`` seconds to load (its wasm takes about a minute on two cores).
Needs Chromium (``apt-get install chromium``) and ``aiohttp``.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import shutil
import socket
import subprocess
import sys
import tempfile
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


async def _capture(port: int, url: str, out: Path, wait: float) -> None:
    import aiohttp

    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5) as r:
        page = next(t for t in json.load(r) if t["type"] == "page")
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(page["webSocketDebuggerUrl"], max_msg_size=0) as ws:
            ids = iter(range(1, 1000))

            async def call(method: str, **params):
                n = next(ids)
                await ws.send_json({"id": n, "method": method, "params": params})
                async for msg in ws:
                    data = json.loads(msg.data)
                    if data.get("id") == n:
                        return data.get("result", {})

            await call("Page.enable")
            await call("Page.navigate", url=url)
            await asyncio.sleep(wait)
            shot = await call("Page.captureScreenshot", format="png")
            out.write_bytes(base64.b64decode(shot["data"]))


def screenshot(recording: Path, out: Path, wait: float = 90.0, size=(1600, 900)) -> Path:
    """``out``: the web viewer's picture of ``recording`` after ``wait`` seconds [s]."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise RuntimeError("no chromium here (apt-get install chromium)")
    web, grpc, devtools = _free_port(), _free_port(), _free_port()
    files = [str(recording)] + ([str(timings_path(recording))] if timings_path(recording).is_file() else [])
    server = subprocess.Popen([rerun_executable(), "--serve-web", "--web-viewer-port", str(web), "--port", str(grpc),
                               *files], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    profile = tempfile.mkdtemp(prefix="chromium-")
    browser = None
    try:
        _wait_for(f"http://127.0.0.1:{web}/", 60)
        url = f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
        browser = subprocess.Popen([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                    f"--window-size={size[0]},{size[1]}", f"--remote-debugging-port={devtools}",
                                    "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _wait_for(f"http://127.0.0.1:{devtools}/json/version", 60)
        asyncio.run(_capture(devtools, url, Path(out), wait))
    finally:
        for p in (browser, server):
            if p is not None:
                p.terminate()
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
        shutil.rmtree(profile, ignore_errors=True)
    return Path(out)


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
    except ValueError:
        print(f"error: --size: {args.size!r}; accepted: WIDTHxHEIGHT in pixels, e.g. 1600x900", file=sys.stderr)
        return 2
    print(screenshot(rec, args.out, args.wait, (w, h)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
