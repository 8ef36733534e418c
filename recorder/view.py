"""``auv-swarm view DIR``: open a past run's ``recording.rrd`` in the rerun viewer.

``DIR`` is a results folder (or the .rrd file itself). The viewer runs in the
foreground until its window is closed. ``--screenshot PNG`` renders the recording
in a headless viewer instead (software Vulkan works, e.g. Debian's
mesa-vulkan-drivers), at ``--at`` seconds of sim time or at the end, and exits.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from orchestrator.progress import Progress
from recorder.viewer import (
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
        description="Open a past run's recording.rrd in the rerun viewer, or render it headless to a PNG.",
    )
    parser.add_argument("dir", type=Path, help="results folder of a run (or a .rrd file)")
    parser.add_argument("--screenshot", type=Path, default=None, help="render headless to this PNG and exit")
    parser.add_argument("--at", type=float, default=None, help="sim time (s) of the screenshot (default: the end)")
    args = parser.parse_args(argv)
    rrd = recording_path(args.dir)
    if not rrd.is_file():
        print(f"error: no recording at {rrd} (a run writes recording.rrd in its results folder)", file=sys.stderr)
        return 2
    if args.screenshot is not None:
        return _screenshot(rrd, args.screenshot, args.at)
    problem = window_problem()
    if problem is not None:
        print(
            f"error: {problem}; render it headless instead: auv-swarm view {args.dir} --screenshot shot.png",
            file=sys.stderr,
        )
        return 1
    try:
        cmd = viewer_command(rrd)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    proc = subprocess.Popen(cmd)
    try:
        return proc.wait()
    except KeyboardInterrupt:
        proc.terminate()
        proc.wait(timeout=10.0)
        return 130


def _screenshot(rrd: Path, png: Path, at: float | None) -> int:
    problem = headless_problem()
    if problem is not None:
        print(f"error: cannot render {rrd} here: {problem}", file=sys.stderr)
        return 1
    try:
        with Progress("screenshot", SCREENSHOT_STEPS, "steps (viewer up, loaded, settled, saved)") as progress:
            t_s = screenshot(rrd, png, t_s=at, on_step=progress.advance)
    except NoRendererError as exc:
        print(f"error: cannot render {rrd} here: {exc}", file=sys.stderr)
        return 1
    except (RuntimeError, TimeoutError, OSError) as exc:
        print(f"error: screenshot of {rrd} failed: {exc}", file=sys.stderr)
        return 1
    print(f"screenshot of {rrd} at sim time {t_s:g} s written to {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
