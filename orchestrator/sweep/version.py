"""The auv-swarm version a process runs: the package version plus the git commit where known.

A sweep's client and every worker report it; a result from another version stops the sweep (docs/sweeps.md).
``AUVSWARM_FAKE_VERSION`` set in a process's environment replaces its version (for tests of that check).
"""

from __future__ import annotations

import functools
import os
import subprocess
from importlib import metadata
from pathlib import Path

FAKE_VERSION_ENV = "AUVSWARM_FAKE_VERSION"
"""Environment variable: when set, :func:`version` returns its value (tests fake a worker of another version)."""


@functools.cache
def _real_version() -> str:
    try:
        package = metadata.version("auv-swarm")
    except metadata.PackageNotFoundError:
        package = "unknown"
    source = Path(__file__).resolve().parents[1]
    try:
        done = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return package
    commit = done.stdout.strip()
    return f"{package}+g{commit}" if done.returncode == 0 and commit else package


def version() -> str:
    """``<package version>+g<commit>`` (the commit only in a git checkout), or ``AUVSWARM_FAKE_VERSION``."""
    return os.environ.get(FAKE_VERSION_ENV) or _real_version()
