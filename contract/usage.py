"""How a command says what is wrong: one line on stderr, ``error: ...``, and the exit code it returns.

Exit codes (docs/exit-codes.md): 2 bad input or usage, 1 a failure at run time.
"""

from __future__ import annotations

import sys

BAD_INPUT = 2
RUN_FAILED = 1


def fail(message: str, code: int = BAD_INPUT) -> int:
    """Print ``error: message`` on stderr and return ``code`` (for ``return fail(...)`` in a ``main``)."""
    print(f"error: {message}", file=sys.stderr, flush=True)
    return code


def plain_description(doc: str | None) -> str:
    """A module docstring's first paragraph as plain text for ``--help`` (reStructuredText ````literals```` unquoted)."""
    first = (doc or "").strip().split("\n\n")[0]
    return " ".join(first.replace("``", "").split())
