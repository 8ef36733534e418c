"""Copy this process's stdout and stderr to a log file as well (env ``AUVSWARM_LOG_FILE``).

Under compose each service writes its output to ``runs/<id>/logs/<service>.log``
beside the results while ``docker-compose logs`` still shows it. File descriptors
1 and 2 are pointed at a pipe (so zenoh's and rerun's native output is caught too)
and a thread copies the pipe to the original stdout and to the file; at exit the
pipe is closed and the thread drained, so the last lines are kept.
"""

from __future__ import annotations

import atexit
import os
import sys
import threading
from pathlib import Path

ENV = "AUVSWARM_LOG_FILE"


def start_from_env() -> None:
    """Start the copy if ``AUVSWARM_LOG_FILE`` names a file whose folder exists; otherwise do nothing."""
    path = os.environ.get(ENV, "").strip()
    if not path:
        return
    try:
        log = open(Path(path), "ab", buffering=0)  # noqa: SIM115 (closed by the copying thread)
    except OSError as exc:
        print(f"warning: cannot write the log file {path}: {exc}; output goes to stdout only", file=sys.stderr)
        return
    sys.stdout.flush()
    sys.stderr.flush()
    original = os.dup(1)
    read_end, write_end = os.pipe()
    os.dup2(write_end, 1)
    os.dup2(write_end, 2)
    os.close(write_end)

    def copy() -> None:
        while chunk := os.read(read_end, 65536):
            os.write(original, chunk)
            log.write(chunk)
        log.close()
        os.close(read_end)

    thread = threading.Thread(target=copy, name="log-tee", daemon=True)
    thread.start()

    def drain() -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        os.close(devnull)
        thread.join(timeout=5.0)

    atexit.register(drain)
