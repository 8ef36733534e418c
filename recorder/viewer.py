"""The rerun viewer as a program: where its binary is, whether it can start here, headless screenshots.

Used by the recorder (a live viewer beside a run; :func:`compact` at the end) and
by ``auv-swarm view``. A headless viewer renders with Vulkan only: on a
machine without a Vulkan driver it panics ("Failed to get render context"), so
:func:`headless_problem` looks for the driver manifests the Vulkan loader reads, and
:func:`screenshot` also reads the viewer's own output if it dies anyway. A windowed
viewer needs a display (:func:`window_problem`).
"""

from __future__ import annotations

import importlib.util
import logging
import os
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

log = logging.getLogger("recorder")

TIMELINE = "sim_time"
"""The recording's timeline: simulation time (s)."""
VULKAN_PACKAGE = "mesa-vulkan-drivers"
"""The Debian/Ubuntu package with a software Vulkan driver (lavapipe) for headless rendering."""
NO_RENDERER_HINTS = ("Failed to get render context", "No graphics adapter", "No suitable adapter")
"""What the viewer prints when it finds no usable GPU driver."""
SCREENSHOT_STEPS = 4
"""Steps of :func:`screenshot` reported to its ``on_step`` callback."""
DEFAULT_VIEWER_PORT = 9876
"""Where a live viewer listens by default (rerun's gRPC port)."""
LIVE_VIEWER_START_S = 15.0
"""Wall time a live viewer spawned beside a run gets to start listening (s)."""
VIEWER_START_S = 30.0
"""Wall time a headless viewer gets to start listening (s)."""


class NoRendererError(RuntimeError):
    """The viewer cannot render on this machine; the message says what to install."""


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


def compact(rrd_path: Path, timeout_s: float = 120.0) -> tuple[int, int]:
    """Rewrite a finished recording with its small chunks merged (``rerun rrd optimize``); returns (bytes before, after).

    The recorder sends rows in small batches while a mission runs, so that a live
    viewer stays current and a kill -9 loses little: a paced run (``--speed``)
    sends a few rows per entity every half second of wall time and its file holds
    thousands of small chunks, each with its own schema (about 8 times the bytes
    of an unpaced run of the same mission). Merged, the same data takes about the
    same size whatever the pacing. The file is replaced only once the merged copy
    is complete; on failure the original stays and RuntimeError says why.
    """
    rrd_path = Path(rrd_path)
    before = rrd_path.stat().st_size
    merged = rrd_path.with_name(rrd_path.name + ".compacting")
    try:
        done = subprocess.run(
            [viewer_binary(), "rrd", "optimize", "-o", str(merged), str(rrd_path)],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            timeout=timeout_s,
            check=False,
        )
        if done.returncode != 0 or not merged.is_file():
            tail = done.stderr.decode(errors="replace").strip().splitlines()[-1:] or ["no output"]
            raise RuntimeError(f"rerun rrd optimize exited with {done.returncode}: {tail[0][:200]}")
        os.replace(merged, rrd_path)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise RuntimeError(f"could not compact {rrd_path}: {exc}") from exc
    finally:
        merged.unlink(missing_ok=True)
    return before, rrd_path.stat().st_size


def vulkan_icd_dirs(env: Mapping[str, str] | None = None) -> list[Path]:
    """The folders where the Vulkan loader looks for driver manifests (``icd.d/*.json``), in its order."""
    env = os.environ if env is None else env
    home = Path(env.get("HOME", "~")).expanduser()
    config_dirs = (env.get("XDG_CONFIG_DIRS") or "/etc/xdg").split(os.pathsep)
    data_home = env.get("XDG_DATA_HOME") or str(home / ".local" / "share")
    data_dirs = (env.get("XDG_DATA_DIRS") or "/usr/local/share:/usr/share").split(os.pathsep)
    roots = [*config_dirs, "/etc", data_home, *data_dirs]
    return [Path(root) / "vulkan" / "icd.d" for root in roots if root]


def vulkan_drivers(env: Mapping[str, str] | None = None) -> list[Path]:
    """The Vulkan driver manifests the loader would find: ``VK_DRIVER_FILES`` / ``VK_ICD_FILENAMES`` if set, else the folders."""
    env = os.environ if env is None else env
    explicit = env.get("VK_DRIVER_FILES") or env.get("VK_ICD_FILENAMES")
    places = [Path(p) for p in explicit.split(os.pathsep) if p] if explicit else vulkan_icd_dirs(env)
    extra = [Path(p) for p in env.get("VK_ADD_DRIVER_FILES", "").split(os.pathsep) if p]
    found: list[Path] = []
    for place in [*places, *extra]:
        if place.is_dir():
            found += sorted(place.glob("*.json"))
        elif place.is_file():
            found.append(place)
    return found


def headless_problem(env: Mapping[str, str] | None = None) -> str | None:
    """Why a headless viewer cannot render here (one line with the fix), or None if a Vulkan driver is installed."""
    if vulkan_drivers(env):
        return None
    return (
        "no Vulkan driver found for the headless viewer (no driver manifest in vulkan/icd.d); "
        f"install a software one: apt-get install {VULKAN_PACKAGE}"
    )


def window_problem(env: Mapping[str, str] | None = None) -> str | None:
    """Why a viewer window cannot open here (one line), or None if there is a display."""
    env = os.environ if env is None else env
    if env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"):
        return None
    return "no display (DISPLAY and WAYLAND_DISPLAY are unset), so no viewer window can open"


def screenshot(
    rrd_path: Path,
    png_path: Path,
    *,
    t_s: float | None = None,
    settle_s: float = 6.0,
    on_step: Callable[[], None] | None = None,
) -> float:
    """Render a recording in a headless viewer to ``png_path`` at sim time ``t_s`` (default: the end); returns t_s.

    Software rendering works (Vulkan through Debian's mesa-vulkan-drivers); without
    a Vulkan driver it raises :class:`NoRendererError` before starting the viewer,
    or when the viewer's output shows it found none. The viewer is a child of this
    process, its output goes to a temporary log, and it is stopped before
    returning. ``settle_s`` (wall clock) lets the viewer's start-up notifications
    fade before the capture. ``on_step()`` is called after each of the
    :data:`SCREENSHOT_STEPS` steps (viewer up, recording loaded, settled, saved).
    """
    from rerun.experimental import ViewerClient

    rrd_path, png_path = Path(rrd_path), Path(png_path)
    if not rrd_path.is_file():
        raise FileNotFoundError(f"no recording at {rrd_path}")
    if settle_s < 0:
        raise ValueError(f"settle_s must be >= 0 s, got {settle_s!r}")
    problem = headless_problem()
    if problem is not None:
        raise NoRendererError(problem)
    with tempfile.TemporaryDirectory(prefix="auv-swarm-viewer-") as tmp:
        log_path = Path(tmp) / "viewer.log"
        proc, port = _start_headless(log_path)
        step = on_step or (lambda: None)
        step()
        try:
            viewer = ViewerClient(f"rerun+http://127.0.0.1:{port}/proxy")
            return _capture(viewer, proc, log_path, rrd_path, png_path, t_s, settle_s, step)
        finally:
            _stop(proc)


def _start_headless(log_path: Path) -> tuple[subprocess.Popen, int]:
    """Start a headless viewer on a free port with its output in ``log_path``; wait until it listens."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = int(sock.getsockname()[1])
    cmd = [viewer_binary(), "--headless", "--port", str(port), "--hide-welcome-screen", "--expect-data-soon"]
    with open(log_path, "wb") as out:
        proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            env={**os.environ, "RERUN_APP_ONLY": "true"},
        )
    deadline = time.monotonic() + VIEWER_START_S
    while True:
        _check_alive(proc, log_path)
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return proc, port
        except OSError:
            if time.monotonic() > deadline:
                _stop(proc)
                raise TimeoutError(f"the headless viewer did not listen within {VIEWER_START_S:g} s") from None
            time.sleep(0.1)


def _check_alive(proc: subprocess.Popen, log_path: Path) -> None:
    """Raise if the viewer died: NoRendererError when its output says it found no graphics driver."""
    text = log_path.read_text(encoding="utf-8", errors="replace") if log_path.exists() else ""
    if any(hint in text for hint in NO_RENDERER_HINTS):
        raise NoRendererError(
            f"the headless viewer found no usable Vulkan driver; install a software one: apt-get install {VULKAN_PACKAGE}"
        )
    if proc.poll() is not None:
        last = text.strip().splitlines()[-1:] or ["no output"]
        raise RuntimeError(f"the headless viewer exited with {proc.returncode}: {last[0][:200]}")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5.0)


def _capture(
    viewer: object,
    proc: subprocess.Popen,
    log_path: Path,
    rrd_path: Path,
    png_path: Path,
    t_s: float | None,
    settle_s: float,
    step: Callable[[], None],
) -> float:
    """Load the recording into the running viewer, move to ``t_s`` (default: the end) and save the PNG."""
    try:
        viewer.open(str(rrd_path.resolve()))
        end_ns = None
        deadline = time.monotonic() + 30.0
        while end_ns is None and time.monotonic() < deadline:
            _check_alive(proc, log_path)
            state = viewer.get_state()
            timelines = [tl for rec in state.recordings for tl in rec.timelines if tl.name == TIMELINE]
            if timelines and not state.loading:
                end_ns = max(tl.end for tl in timelines)
            else:
                time.sleep(0.1)
        if end_ns is None:
            raise RuntimeError(f"the viewer did not load {rrd_path} within 30 s")
        step()
        at = end_ns / 1e9 if t_s is None else float(t_s)
        viewer.set_time(TIMELINE, duration=at, play_state="paused")
        time.sleep(settle_s)
        step()
        png_path.parent.mkdir(parents=True, exist_ok=True)
        _check_alive(proc, log_path)
        viewer.save_screenshot(str(png_path.resolve()))
        step()
        return at
    except NoRendererError:
        raise
    except Exception as exc:  # the viewer is another program: whatever its client raises becomes one line
        _check_alive(proc, log_path)
        raise RuntimeError(f"the headless viewer failed: {str(exc).splitlines()[0][:200]}") from exc


def viewer_reachable(url: str, timeout_s: float) -> bool:
    """True if a TCP connection to the host and port of a rerun gRPC ``url`` succeeds within ``timeout_s``."""
    parsed = urlparse(url)
    host = parsed.hostname or "127.0.0.1"
    port = parsed.port or (443 if parsed.scheme.endswith("https") else DEFAULT_VIEWER_PORT)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def check_url(url: str) -> str:
    """Validate a rerun gRPC url (``rerun+http://HOST:PORT/proxy``); ValueError names the allowed form."""
    parsed = urlparse(str(url))
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or not parsed.hostname or parsed.path != "/proxy":
        raise ValueError(f"rerun url must look like rerun+http://HOST:PORT/proxy, got {url!r}")
    return str(url)


def spawn_live_viewer(port: int, log_path: Path, closed: Callable[[], bool]) -> subprocess.Popen | None:
    """Start the viewer binary (detached, so it outlives the run) and wait until it listens on ``port``.

    ``rr.spawn`` is not used: it holds the GIL while it waits for the viewer, which would
    stall the mission. The viewer's output goes to ``log_path``. Stops waiting when
    ``closed()`` turns true. Returns the process, or None if it could not start.
    """
    try:
        with open(log_path, "ab") as out:
            viewer = subprocess.Popen(
                [viewer_binary(), "--port", str(port), "--hide-welcome-screen", "--expect-data-soon"],
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
    except OSError as exc:
        log.warning("recorder: could not start the rerun viewer: %s", exc)
        return None
    deadline = time.monotonic() + LIVE_VIEWER_START_S
    while time.monotonic() < deadline and not closed():
        if viewer.poll() is not None:
            log.warning("recorder: the rerun viewer exited with %s; see %s", viewer.returncode, log_path)
            return viewer
        if viewer_reachable(f"rerun+http://127.0.0.1:{port}/proxy", 0.2):
            return viewer
        time.sleep(0.1)
    return viewer


def release_live(live: Any) -> None:
    """Flush a live ``rr.RecordingStream`` briefly and disconnect it off the caller's thread (a vanished viewer can
    take 5 s)."""

    def release() -> None:
        try:
            live.flush(timeout_sec=2.0)
        except RuntimeError as exc:
            log.warning("recorder: live viewer did not take the last data: %s", exc)
        live.disconnect()

    worker = threading.Thread(target=release, name="rerun-live-release", daemon=True)
    worker.start()
    worker.join(timeout=3.0)
