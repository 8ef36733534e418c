"""Reading argparse help text: which options of a ``--help`` page have no help line."""

from __future__ import annotations

import re

_ENTRY = re.compile(r"^  (\S.*?)(?:\s{2,}(\S.*))?$")


def undocumented(help_text: str) -> list[str]:
    """The argument entries of an argparse help page that have no help text (same line or the next, indented)."""
    lines = help_text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.rstrip().endswith(":") and not line.startswith(" ")), None)
    if start is None:
        return []
    missing = []
    for i in range(start, len(lines)):
        match = _ENTRY.match(lines[i])
        if match is None or match.group(2):
            continue
        following = lines[i + 1] if i + 1 < len(lines) else ""
        if not (following.startswith("    ") and following.strip()):
            missing.append(match.group(1).strip())
    return missing
