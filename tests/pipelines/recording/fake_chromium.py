"""A stand-in for Chromium in the screenshot tests: it answers the DevTools
calls the screenshot makes (``/json/version``, ``/json/list`` and a page's
WebSocket) and returns, for ``Page.captureScreenshot``, a PNG of the size
``Emulation.setDeviceMetricsOverride`` set. It starts a child process of its
own (``sleep``), as a browser does, so that a test sees whether the whole
process group ends, and, as Chromium's crash handler, a second one detached
in a session of its own (its pid written to ``FAKE_CHROMIUM_DETACHED``); it
links ``SingletonSocket`` in its profile to a directory
``org.chromium.Chromium.*`` in the temporary directory, as Chromium does.
``FAKE_CHROMIUM=silent``: it never answers; ``hang``, ``close``, ``error``:
at ``Page.captureScreenshot`` it never answers, drops the connection, or
replies with an error."""

from __future__ import annotations

import asyncio
import base64
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def png(width: int, height: int) -> bytes:
    import numpy as np
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.zeros((height, width, 3), np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def main() -> None:
    port = next(int(a.split("=", 1)[1]) for a in sys.argv[1:] if a.startswith("--remote-debugging-port="))
    subprocess.Popen(["sleep", "300"])  # a child, as the browser's renderer
    # a grandchild in a session of its own, its parent gone: an orphan, as the crash handler
    detached = subprocess.Popen([sys.executable, "-c", "import subprocess; "
                                 "print(subprocess.Popen(['sleep', '300'], start_new_session=True, "
                                 "stdout=subprocess.DEVNULL).pid)"],
                                stdout=subprocess.PIPE, text=True)
    pid = detached.communicate()[0].strip()
    if os.environ.get("FAKE_CHROMIUM_DETACHED"):
        Path(os.environ["FAKE_CHROMIUM_DETACHED"]).write_text(pid)
    profile = next(a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--user-data-dir="))
    singleton = tempfile.mkdtemp(prefix="org.chromium.Chromium.")
    os.symlink(f"{singleton}/SingletonSocket", f"{profile}/SingletonSocket")
    if os.environ.get("FAKE_CHROMIUM") == "silent":
        time.sleep(300)
        return
    from aiohttp import web

    size = [800, 600]
    ws_url = f"ws://127.0.0.1:{port}/devtools/page/1"

    async def version(request):
        return web.json_response({"Browser": "fake"})

    async def pages(request):
        return web.json_response([{"type": "page", "webSocketDebuggerUrl": ws_url}])

    async def page(request):
        ws = web.WebSocketResponse(max_msg_size=0)
        await ws.prepare(request)
        async for msg in ws:
            call = json.loads(msg.data)
            result = {}
            if call["method"] == "Emulation.setDeviceMetricsOverride":
                size[:] = [call["params"]["width"], call["params"]["height"]]
            if call["method"] == "Page.captureScreenshot":
                fault = os.environ.get("FAKE_CHROMIUM")
                if fault == "hang":  # a renderer that never answers
                    await asyncio.sleep(300)
                if fault == "close":  # the connection drops
                    await ws.close()
                    break
                if fault == "error":  # an error reply
                    await ws.send_str(json.dumps({"id": call["id"], "error": {
                        "code": -32000, "message": "Unable to capture screenshot"}}))
                    continue
                result = {"data": base64.b64encode(png(*size)).decode()}
            await ws.send_str(json.dumps({"id": call["id"], "result": result}))
        return ws

    app = web.Application()
    app.add_routes([web.get("/json/version", version), web.get("/json/list", pages),
                    web.get("/devtools/page/1", page)])
    web.run_app(app, host="127.0.0.1", port=port, print=None)


if __name__ == "__main__":
    main()
