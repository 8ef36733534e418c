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


def plural(count: int, noun: str) -> str:
    """``1 mission``, ``2 missions``: a count and its noun (an ``s`` added for any count but 1)."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"


def plain_description(doc: str | None) -> str:
    """A module docstring's first paragraph as plain text for ``--help`` (reStructuredText ````literals```` unquoted)."""
    first = (doc or "").strip().split("\n\n")[0]
    return " ".join(first.replace("``", "").split())


SEEDS_HELP = "A-B (seeds A to B) or N (seeds 1 to N)"
"""The one ``--seeds`` convention of every command that runs several seeds (docs/cli.md)."""


def parse_seeds(text: str | int) -> list[int]:
    """``--seeds``: ``A-B`` gives seeds A to B inclusive (0 <= A <= B), ``N`` seeds 1 to N (N >= 1); ValueError
    (one line naming the convention) otherwise. ``run --seed S`` is the one-seed option."""
    value = str(text).strip()
    a, sep, b = value.partition("-")
    try:
        if sep:
            lo, hi = int(a), int(b)
            if lo < 0 or hi < lo:
                raise ValueError
            return list(range(lo, hi + 1))
        n = int(value)
        if n < 1:
            raise ValueError
        return list(range(1, n + 1))
    except ValueError:
        raise ValueError(f"--seeds must be A-B (0 <= A <= B) or N >= 1, got {value!r}") from None


def seeds_text(seeds: list[int]) -> str:
    """Seeds as the ``--seeds`` argument that gives them back where one exists (``1-10``), else listed."""
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(map(str, seeds))
