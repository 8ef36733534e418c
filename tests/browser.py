"""Headless Chromium driven over the DevTools protocol (websocket), for the web-viewer tests.

A plain ``chromium --screenshot`` fires before rerun's web viewer has started and
shows a blank or "Loading" page; over the DevTools protocol the test navigates,
then captures screenshots until the page shows the viewer with data.
"""

from __future__ import annotations

import base64
import itertools
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--hide-scrollbars",
    "--window-size=1400,900",
)


def chromium_binary() -> str | None:
    """Debian's ``chromium`` (or another Chromium on PATH), else None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


class Chromium:
    """A headless Chromium in its own process group with a DevTools websocket to its first page."""

    def __init__(self, binary: str, port: int) -> None:
        import websocket

        self.profile = tempfile.mkdtemp(prefix="auvswarm-chromium-")
        self.proc = subprocess.Popen(
            [
                binary,
                *CHROMIUM_FLAGS,
                f"--remote-debugging-port={port}",
                f"--user-data-dir={self.profile}",
                "about:blank",
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        self._ids = itertools.count(1)
        deadline = time.monotonic() + 30.0
        page = None
        while page is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=2.0) as resp:
                    pages = [t for t in json.load(resp) if t.get("type") == "page"]
                page = pages[0] if pages else None
            except OSError:
                page = None
            if page is None:
                if time.monotonic() > deadline or self.proc.poll() is not None:
                    self.close()
                    raise RuntimeError("chromium's DevTools endpoint did not come up within 30 s")
                time.sleep(0.2)
        self.ws = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=60.0, suppress_origin=True)

    def call(self, method: str, **params: object) -> dict:
        """One DevTools command; its result (events in between are skipped)."""
        msg_id = next(self._ids)
        self.ws.send(json.dumps({"id": msg_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == msg_id:
                if "error" in reply:
                    raise RuntimeError(f"DevTools {method} failed: {reply['error']}")
                return reply.get("result", {})

    def navigate(self, url: str) -> None:
        self.call("Page.enable")
        self.call("Page.navigate", url=url)

    def screenshot(self, path: Path) -> Path:
        data = self.call("Page.captureScreenshot", format="png")["data"]
        path = Path(path)
        path.write_bytes(base64.b64decode(data))
        return path

    def close(self) -> None:
        """Stop the browser's whole process group and remove its profile."""
        ws = getattr(self, "ws", None)
        if ws is not None:
            ws.close()
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10.0)
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def distinct_colours(
    png: Path, box: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0), min_chroma: int = 0
) -> int:
    """How many distinct RGB colours the PNG has inside ``box`` (fractions x0, y0, x1, y1 of the image).

    With ``min_chroma`` only colours whose largest and smallest channel differ by at least that
    much count: the greys of a loading page's anti-aliased text do not, the AUVs' tracks do.
    """
    import numpy as np
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"))
    h, w = img.shape[:2]
    x0, y0, x1, y1 = box
    part = img[int(y0 * h) : int(y1 * h), int(x0 * w) : int(x1 * w)].reshape(-1, 3).astype(int)
    part = part[part.max(axis=1) - part.min(axis=1) >= min_chroma]
    return len(np.unique(part, axis=0))


VIEWER_STATE_JS = (
    "(() => { try { return window._handle ? Array.from(window._handle.viewer_state()) : null }"
    " catch (e) { return null } })()"
)
"""rerun's page keeps its ``WebHandle`` as ``window._handle`` once started; ``viewer_state()`` is the encoded
``GetStateResponse`` of the Viewer Control API (protobuf), computed at once."""


def _protobuf_fields(buf: bytes) -> list[tuple[int, object]]:
    """Decode protobuf wire format without its schema: (field, int | nested fields | bytes) in order.

    A length-delimited field that parses as a message is returned as its fields, otherwise as bytes;
    fixed-width fields are skipped. Raises ValueError on a malformed buffer.
    """
    out: list[tuple[int, object]] = []
    i = 0

    def varint() -> int:
        nonlocal i
        value, shift = 0, 0
        while True:
            if i >= len(buf) or shift > 63:
                raise ValueError("truncated varint")
            b = buf[i]
            i += 1
            value |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                return value

    while i < len(buf):
        key = varint()
        field, wire_type = key >> 3, key & 7
        if field == 0:
            raise ValueError("field number 0")
        if wire_type == 0:
            out.append((field, varint()))
        elif wire_type == 2:
            n = varint()
            if i + n > len(buf):
                raise ValueError("truncated field")
            raw = bytes(buf[i : i + n])
            i += n
            try:
                out.append((field, _protobuf_fields(raw)))
            except ValueError:
                out.append((field, raw))
        elif wire_type in (1, 5):
            i += 8 if wire_type == 1 else 4
        else:
            raise ValueError(f"wire type {wire_type}")
    return out


def _ints(fields: object) -> list[int]:
    if isinstance(fields, int):
        return [fields]
    if isinstance(fields, list):
        return [x for _, v in fields for x in _ints(v)]
    return []


def timeline_time_s(state: bytes, timeline: str) -> float | None:
    """The newest time (s) the viewer state holds for ``timeline`` (a duration timeline), else None.

    The state names each timeline in a message ``{1: {1: name}, ...}`` next to its times (ns): the time
    cursor and the data's range. While the viewer follows a live stream these are the newest data it has
    taken in; the largest of them is returned.
    """
    name = timeline.encode()
    best: int | None = None

    def walk(fields: object) -> None:
        nonlocal best
        if not isinstance(fields, list):
            return
        if any(f == 1 and v == [(1, name)] for f, v in fields):
            times = [x for f, v in fields if f not in (1, 2) for x in _ints(v)]
            if times:
                best = max(times) if best is None else max(best, *times)
        for _, v in fields:
            walk(v)

    walk(_protobuf_fields(state))
    return None if best is None else best / 1e9


def viewer_time_s(browser: Chromium, timeline: str = "sim_time") -> float | None:
    """The newest time on ``timeline`` that rerun's web viewer in ``browser`` shows (s), None before it starts."""
    value = browser.call("Runtime.evaluate", expression=VIEWER_STATE_JS, returnByValue=True)["result"].get("value")
    if not value:
        return None
    return timeline_time_s(bytes(value), timeline)
