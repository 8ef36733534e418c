"""`auv-swarm run --web` in a real browser: headless Chromium over the DevTools protocol shows the viewer with data.

Needs Debian's ``chromium`` (.ci/run installs it) and ``websocket-client`` (dev extras);
skipped, with the reason printed, where either is missing.
"""

from __future__ import annotations

import os
import shutil
import signal
import time
import urllib.request
from pathlib import Path

import pytest

from auv_swarm.orchestrator import procs
from tests.browser import Chromium, chromium_binary, distinct_colours
from tests.processes import processes_with

pytestmark = pytest.mark.integration

MAP_BOX = (0.01, 0.1, 0.58, 0.9)
"""The map view's area in the viewer's layout (fractions of the page: left 3/5, below the top bar)."""
MIN_CHROMA = 60
"""Colours count only when their largest and smallest RGB channels differ by this much (not a grey)."""
MIN_MAP_COLOURS = 100
"""A blank or "Loading" page has no such colours in that area (measured: 0); the map with tracks has hundreds."""
REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(400)
def test_run_web_serves_the_live_viewer_to_a_browser(tmp_path) -> None:
    binary = chromium_binary()
    if binary is None:
        pytest.skip("chromium is not installed (apt-get install chromium; .ci/run does it)")
    pytest.importorskip("websocket", reason="websocket-client is not installed (pip install -e '.[dev]')")
    web_port, grpc_port = procs.free_port(), procs.free_port()
    while grpc_port == web_port:
        grpc_port = procs.free_port()
    out = tmp_path / "run"
    argv = procs.python_argv(
        "auv_swarm", "run", "--duration", "240", "--speed", "12", "--quiet", "--out", str(out),
        "--web", str(web_port), "--web-grpc-port", str(grpc_port),
    )  # fmt: skip
    path = os.pathsep.join(p for p in (str(REPO_ROOT), os.environ.get("PYTHONPATH", "")) if p)
    started = time.monotonic()
    run = procs.spawn(argv, "run-web", env={"PYTHONPATH": path}, log_path=tmp_path / "run.log", cwd=REPO_ROOT)
    shot = tmp_path / "web-viewer.png"
    try:
        url = procs.wait_for_line(run, r"web viewer: open (\S+)", timeout=60.0).group(1)
        assert time.monotonic() - started < 30.0, "the URL must be printed within seconds of the start"
        assert url.startswith(f"http://localhost:{web_port}/?url=")
        with Chromium(binary, procs.free_port()) as browser:
            browser.navigate(url.replace("localhost", "127.0.0.1"))
            colours = 0
            deadline = time.monotonic() + 180.0
            while colours < MIN_MAP_COLOURS and time.monotonic() < deadline:
                time.sleep(3.0)
                colours = distinct_colours(browser.screenshot(shot), MAP_BOX, MIN_CHROMA)
            assert colours >= MIN_MAP_COLOURS, f"the map area shows {colours} colours: not the viewer with data"
            title = browser.call("Runtime.evaluate", expression="document.title")["result"].get("value", "")
            assert "rerun" in title.lower(), f"page title {title!r} is not rerun's viewer"
            procs.wait_for_line(run, r"mission over; the web viewer keeps serving", timeout=180.0)
            time.sleep(3.0)
            colours = distinct_colours(browser.screenshot(shot), MAP_BOX, MIN_CHROMA)
            assert colours >= MIN_MAP_COLOURS, f"after the mission the map shows {colours} colours"
        with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=10.0) as resp:
            assert resp.status == 200, "the page must keep serving after the mission"
        assert run.poll() is None
        os.kill(run.pid, signal.SIGINT)
        assert run.wait(timeout=30.0) == 0, procs.read_log(run)
    finally:
        procs.stop(run, timeout=10.0)
        if shot.is_file() and os.environ.get("AUVSWARM_KEEP_SCREENSHOT"):
            shutil.copy(shot, os.environ["AUVSWARM_KEEP_SCREENSHOT"])
    assert (out / "metrics.json").is_file() and (out / "recording.rrd").is_file()
    assert not procs.group_alive(run.pid), "a process of the run's group is still alive"
    assert processes_with(f"--web-viewer-port {web_port}") == [], "the web viewer outlived the run"
