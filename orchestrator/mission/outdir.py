"""Results folders (``--out``): checked before any work starts, and never overwritten by surprise.

Every verb that writes results (``auv-swarm run``, ``auv-swarm bench table3 --out``, the
drills) calls :func:`prepare` before it starts a process or a mission. A folder is
accepted if it is new, empty, or holds only other files; a folder that already holds
results (any of :data:`RESULT_FILES`) is refused unless ``force`` is given. A path that
cannot be a writable folder (a file, under ``/proc`` or ``/dev/null``, a read-only file
system) is refused with one line naming the path and the reason.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

RESULT_FILES = ("metrics.json", "table3.json", "drill-report.json", "sweep.sqlite")
"""Files whose presence marks a folder as holding results."""


class OutDirError(ValueError):
    """The results folder cannot be used; the message is one line for the user."""


def existing_results(path: Path, own: tuple[str, ...] = ()) -> list[str]:
    """The names of :data:`RESULT_FILES` present in the folder ``path`` (empty if none, or no folder), less
    ``own``."""
    return [name for name in RESULT_FILES if name not in own and (Path(path) / name).exists()]


def prepare(path: Path, *, force: bool = False, flag: str = "--out", own: tuple[str, ...] = ()) -> Path:
    """Create (if needed) and check the results folder ``path``; returns it.

    Raises :class:`OutDirError` if ``path`` is not a folder, cannot be created or
    written, or already holds results and ``force`` is False. ``flag`` names the
    option in the message; ``own`` names result files the caller resumes from (``auv-swarm sweep`` and
    ``bench table3`` accept a ``sweep.sqlite``: the store checks that it is theirs).
    """
    path = Path(path)
    try:
        if path.exists() and not path.is_dir():
            raise OutDirError(f"{flag} {path}: is a file, not a folder")
        found = existing_results(path, own) if path.is_dir() else []
        if found and not force:
            raise OutDirError(
                f"{flag} {path} already holds results ({', '.join(found)}); "
                "choose a new folder, or pass --force to overwrite them"
            )
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-check-", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutDirError(f"{flag} {path}: cannot write a results folder there ({_reason(exc)})") from exc
    return path


def _reason(exc: OSError) -> str:
    """The OS's reason in words, with the path it concerns when that is not the folder itself."""
    reason = exc.strerror or type(exc).__name__
    return f"{reason}: {exc.filename}" if exc.filename else reason
