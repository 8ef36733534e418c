"""The rerun viewer as a program: where its binary is, and headless screenshots of a recording.

Used by the recorder (a live viewer beside a run) and by ``auv-swarm view``.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import socket
import time
from pathlib import Path

TIMELINE = "sim_time"
"""The recording's timeline: simulation time (s)."""


def viewer_binary() -> str:
    """The rerun viewer executable: the binary shipped in rerun-sdk, else ``rerun`` on PATH.

    The ``rerun`` console script is a wrapper that starts the binary as a child;
    running the binary directly leaves one process to stop.
    """
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin is not None:
        binary = Path(spec.origin).parent / "rerun"
        if binary.is_file() and os.access(binary, os.X_OK):
            return str(binary)
    found = shutil.which("rerun")
    if found is None:
        raise FileNotFoundError("the rerun viewer is not installed (pip install rerun-sdk)")
    return found


def screenshot(rrd_path: Path, png_path: Path, *, t_s: float | None = None, settle_s: float = 6.0) -> float:
    """Render a recording in a headless viewer to ``png_path`` at sim time ``t_s`` (default: the end); returns t_s.

    Software rendering works (Vulkan through Debian's mesa-vulkan-drivers). The
    viewer is a child of this process and is stopped before returning. ``settle_s``
    (wall clock) lets the viewer's start-up notifications fade before the capture.
    """
    from rerun.experimental import ViewerClient

    rrd_path, png_path = Path(rrd_path), Path(png_path)
    if not rrd_path.is_file():
        raise FileNotFoundError(f"no recording at {rrd_path}")
    if settle_s < 0:
        raise ValueError(f"settle_s must be >= 0 s, got {settle_s!r}")
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = int(sock.getsockname()[1])
    viewer = ViewerClient.spawn(headless=True, port=port, hide_welcome_screen=True, detach_process=False)
    try:
        viewer.open(str(rrd_path.resolve()))
        end_ns = None
        deadline = time.monotonic() + 30.0
        while end_ns is None and time.monotonic() < deadline:
            state = viewer.get_state()
            timelines = [tl for rec in state.recordings for tl in rec.timelines if tl.name == TIMELINE]
            if timelines and not state.loading:
                end_ns = max(tl.end for tl in timelines)
            else:
                time.sleep(0.1)
        if end_ns is None:
            raise RuntimeError(f"the viewer did not load {rrd_path} within 30 s")
        at = end_ns / 1e9 if t_s is None else float(t_s)
        viewer.set_time(TIMELINE, duration=at, play_state="paused")
        time.sleep(settle_s)
        png_path.parent.mkdir(parents=True, exist_ok=True)
        viewer.save_screenshot(str(png_path.resolve()))
        return at
    finally:
        viewer.quit()
