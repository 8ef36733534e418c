"""Seeded random streams: one independent ``numpy.random.Generator`` per component."""

from __future__ import annotations

import zlib

import numpy as np


def stream(seed: int, name: str, index: int = 0) -> np.random.Generator:
    """A generator for component ``name`` (e.g. "world", "channel", "agent") and ``index``.

    Streams with different names or indices are independent; the same triple
    always yields the same sequence, in any process.
    """
    return np.random.default_rng([int(seed), zlib.crc32(name.encode()), int(index)])
