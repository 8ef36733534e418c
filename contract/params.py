"""How a scenario parameter is declared: its default, meaning, unit and allowed range, checked in one place."""

from __future__ import annotations

import math
from dataclasses import field
from typing import Any


class ConfigError(ValueError):
    """A scenario value is missing, unknown, of the wrong type or out of range."""


MAX_AGENTS = 16
"""Largest team n: bounds ``agents.count`` and the AUV user names ``auv0``..``auv15``."""


def agent_user(auv: int) -> str:
    """The zenoh user name of AUV ``auv`` (``auv<N>``)."""
    if isinstance(auv, bool) or not isinstance(auv, int) or not 0 <= auv < MAX_AGENTS:
        raise ValueError(f"auv must be an integer in [0, {MAX_AGENTS - 1}], got {auv!r}")
    return f"auv{auv}"


MAX_HORIZON = 8
"""Longest planning horizon H (steps): bounds ``planner.horizon``, the acoustic payload's plan and the telemetry's."""


def param(
    default: Any,
    doc: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    choices: tuple[str, ...] | None = None,
    factory: Any = None,
) -> Any:
    """Declare a config field with its meaning/unit and allowed range."""
    meta = {"doc": doc, "lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open, "choices": choices}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def range_text(meta: dict) -> str:
    lo, hi = meta.get("lo"), meta.get("hi")
    if meta.get("choices"):
        return "one of " + ", ".join(repr(c) for c in meta["choices"])
    left = "(" if meta.get("lo_open") else "["
    right = ")" if meta.get("hi_open") else "]"
    lo_s = "-inf" if lo is None else f"{lo:g}"
    hi_s = "inf" if hi is None else f"{hi:g}"
    if lo is None:
        left = "("
    if hi is None:
        right = ")"
    return f"in {left}{lo_s}, {hi_s}{right}"


def check_range(name: str, value: float, meta: dict) -> None:
    """Raise ConfigError if ``value`` violates the declared range of ``name``."""
    lo, hi = meta.get("lo"), meta.get("hi")
    bad = not math.isfinite(value)
    if lo is not None:
        bad |= value <= lo if meta.get("lo_open") else value < lo
    if hi is not None:
        bad |= value >= hi if meta.get("hi_open") else value > hi
    if bad:
        raise ConfigError(f"{name} must be {range_text(meta)}, got {value!r}")
