"""``auv-swarm view DIR``: open a past run's ``recording.rrd`` in the rerun viewer.

``--web [PORT]`` serves it to a browser instead (the page on PORT, default 9090,
its gRPC proxy on ``--web-grpc-port``, default PORT+1, both on 127.0.0.1 unless
``--web-bind ADDR``, which warns), prints the address to open and serves until
Ctrl-C (exit 0). Without DIR, ``--web`` serves an empty
viewer that a recorder streams into (``--rerun-url`` of run/recorder; the
compose ``viewer`` service).

``DIR`` is a results folder (or the .rrd file itself). The viewer runs in the
foreground until its window is closed. ``--screenshot PNG`` renders the recording
in a headless viewer instead (software Vulkan works, e.g. Debian's
mesa-vulkan-drivers), at ``--at`` seconds of sim time or at the end, and exits.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import threading
from pathlib import Path

from auv_swarm.contract.usage import fail
from auv_swarm.orchestrator.mission.progress import Progress
from auv_swarm.recorder import web
from auv_swarm.recorder.viewer import (
    SCREENSHOT_STEPS,
    NoRendererError,
    headless_problem,
    screenshot,
    viewer_binary,
    window_problem,
)

RECORDING = "recording.rrd"


def recording_path(target: Path) -> Path:
    """The .rrd of a results folder, or ``target`` itself if it is a file."""
    target = Path(target)
    return target if target.suffix == ".rrd" or target.is_file() else target / RECORDING


def viewer_command(rrd: Path) -> list[str]:
    """The command line that opens ``rrd`` in the viewer."""
    return [viewer_binary(), str(rrd)]


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm view``."""
    parser = argparse.ArgumentParser(
        prog="auv-swarm view",
        description="Open a past run's recording.rrd in the rerun viewer, render it headless to a PNG, "
        "or serve it to a browser (--web).",
    )
    parser.add_argument("dir", type=Path, nargs="?", default=None, help="results folder of a run (or a .rrd file)")
    parser.add_argument("--screenshot", type=Path, default=None, help="render headless to this PNG and exit")
    parser.add_argument("--at", type=float, default=None, help="sim time (s) of the screenshot (default: the end)")
    add_web_args(parser)
    parser.add_argument("--public-host", default="localhost", help="with --web: host name in the printed address")
    args = parser.parse_args(argv)
    if args.dir is None and args.web is None:
        parser.error("DIR is required (without DIR, --web serves a live viewer for a recorder to stream into)")
    if args.web is not None:
        return serve_web(None if args.dir is None else recording_path(args.dir), args)
    rrd = recording_path(args.dir)
    if not rrd.is_file():
        return fail(f"no recording at {rrd} (a run writes recording.rrd in its results folder)")
    if args.screenshot is not None:
        return _screenshot(rrd, args.screenshot, args.at)
    problem = window_problem()
    if problem is not None:
        print(
            f"error: {problem}; serve it to a browser instead: auv-swarm view {args.dir} --web, "
            f"or render it headless: auv-swarm view {args.dir} --screenshot shot.png",
            file=sys.stderr,
        )
        return 1
    try:
        cmd = viewer_command(rrd)
    except FileNotFoundError as exc:
        return fail(str(exc))
    proc = subprocess.Popen(cmd)
    try:
        return proc.wait()
    except KeyboardInterrupt:
        proc.terminate()
        proc.wait(timeout=10.0)
        return 130


def add_web_args(parser: argparse.ArgumentParser) -> None:
    """--web [PORT] and --web-grpc-port (shared by ``auv-swarm run`` and ``auv-swarm view``)."""
    parser.add_argument(
        "--web",
        type=int,
        nargs="?",
        const=web.DEFAULT_WEB_PORT,
        default=None,
        metavar="PORT",
        help=f"serve rerun's web viewer on PORT (default {web.DEFAULT_WEB_PORT}) and its gRPC proxy on PORT+1",
    )
    parser.add_argument("--web-grpc-port", type=int, default=None, help="with --web: the gRPC proxy's port")
    parser.add_argument(
        "--web-bind",
        default=web.LOOPBACK,
        metavar="ADDR",
        help=f"with --web: the address both listen on (default {web.LOOPBACK}; another lets anyone who reaches it "
        "read and write the stream)",
    )


def web_ports(args: argparse.Namespace) -> tuple[int, int]:
    """(web port, gRPC port) from --web and --web-grpc-port; ValueError on a bad one."""
    ports = (args.web, args.web + 1 if args.web_grpc_port is None else args.web_grpc_port)
    web.check_ports(*ports)
    return ports


def web_bind(args: argparse.Namespace) -> str:
    """The address of --web-bind (ValueError if not an IP address); a one-line warning when it is not loopback."""
    web.check_bind(args.web_bind)
    warning = web.exposure(args.web_bind, *web_ports(args))
    if warning is not None:
        print(warning, file=sys.stderr, flush=True)
    return args.web_bind


def wait_for_interrupt() -> None:
    """Block until SIGINT or SIGTERM."""
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        while not stop.wait(0.5):
            pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def serve_web(rrd: Path | None, args: argparse.Namespace) -> int:
    """Serve ``rrd`` (or an empty live viewer) to browsers until Ctrl-C; 0 then."""
    if rrd is not None and not rrd.is_file():
        return fail(f"no recording at {rrd} (a run writes recording.rrd in its results folder)")
    try:
        web_port, grpc_port = web_ports(args)
        bind = web_bind(args)
    except ValueError as exc:
        return fail(str(exc))
    log_path = (rrd.parent if rrd is not None else Path("/tmp")) / "web-viewer.log"
    try:
        proc = web.start(web_port, grpc_port, log_path, rrd, bind)
    except (RuntimeError, FileNotFoundError) as exc:
        return fail(str(exc), 1)
    what = f"of {rrd}" if rrd is not None else f"live (recorders stream to {web.proxy_url('HOST', grpc_port)})"
    host = web.public_host(bind, args.public_host)
    print(f"web viewer {what}: open {web.page_url(host, web_port, grpc_port)}", flush=True)
    print("serving until Ctrl-C", flush=True)
    try:
        wait_for_interrupt()
    finally:
        web.stop(proc)
    return 0


def _screenshot(rrd: Path, png: Path, at: float | None) -> int:
    problem = headless_problem()
    if problem is not None:
        return fail(f"cannot render {rrd} here: {problem}", 1)
    try:
        with Progress("screenshot", SCREENSHOT_STEPS, "steps (viewer up, loaded, settled, saved)") as progress:
            t_s = screenshot(rrd, png, t_s=at, on_step=progress.advance)
    except NoRendererError as exc:
        return fail(f"cannot render {rrd} here: {exc}", 1)
    except (RuntimeError, TimeoutError, OSError) as exc:
        return fail(f"screenshot of {rrd} failed: {exc}", 1)
    print(f"screenshot of {rrd} at sim time {t_s:g} s written to {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
