"""Scheduled faults of a scenario (drills): ``[[faults]]`` and the ``[[kills]]`` shorthand, and their checks."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from auv_swarm.contract.params import ConfigError, param


@dataclass(frozen=True)
class KillEvent:
    """Scheduled failure: AUV ``agent`` stops at sim time ``time_s`` (section 3.2)."""

    agent: int = param(0, "AUV id to kill (below agents.count)", lo=0, hi=15)
    time_s: float = param(0.0, "sim time of the failure (s)", lo=0.0)


FAULT_ACTIONS = ("kill", "stop", "restart", "term")
"""``faults[].action``: SIGKILL; SIGSTOP for ``duration_s`` then SIGCONT; SIGKILL then a fresh process after
``down_s``; SIGTERM."""
FAULT_COMPONENTS = ("channel", "router", "world", "recorder")
"""``faults[].target`` besides ``auv:N``: these exist only in processes mode."""


@dataclass(frozen=True)
class Fault:
    """A scheduled fault (drills): at sim time ``at_s``, ``target`` gets ``action``.

    For an AUV (``auv:N``) ``duration_s`` and ``down_s`` are sim seconds (the world keeps ticking without
    it); for the channel, router, world and recorder they are wall seconds (the clock cannot run without
    them). ``[[kills]]`` entries are the shorthand of ``action = "kill"`` on ``auv:N``.
    """

    at_s: float = param(0.0, "sim time of the fault (s)", lo=0.0)
    target: str = param("auv:0", "auv:N (N below agents.count), channel, router, world or recorder")
    action: str = param("kill", "what happens to the target", choices=FAULT_ACTIONS)
    duration_s: float = param(0.0, "stop: how long the target stays stopped (s; sim for AUVs, else wall)", lo=0.0)
    down_s: float = param(0.0, "restart: how long the target stays down (s; sim for AUVs, else wall)", lo=0.0)

    @property
    def auv(self) -> int | None:
        """The AUV id of an ``auv:N`` target, else None."""
        kind, _, num = self.target.partition(":")
        return int(num) if kind == "auv" and num.isdigit() else None

    @property
    def span_s(self) -> float:
        """How long the fault lasts (s); a kill or a term lasts for ever."""
        if self.action == "stop":
            return self.duration_s
        if self.action == "restart":
            return self.down_s
        return math.inf


EXAMPLE_TOML = """\
[[kills]]              # the shorthand of a fault with action = "kill" on auv:N
agent = 1
time_s = 750.0

[[faults]]             # AUV 2 killed at 400 s, a fresh process of it 60 sim s later
at_s = 400.0
target = "auv:2"
action = "restart"
down_s = 60.0

[[faults]]             # the channel stopped (SIGSTOP) at 600 s for 2 wall s (processes mode only)
at_s = 600.0
target = "channel"
action = "stop"
duration_s = 2.0
"""
"""A valid ``[[kills]]`` and ``[[faults]]`` sample (``--example`` and docs/scenarios.md show it; a test loads it)."""


def after_end(s: Any, duration_s: float | None = None, agents: int | None = None) -> list[str]:
    """One line per kill or fault of scenario ``s`` scheduled after the mission's end (sim time greater than
    ``duration_s``, default ``s.run.duration_s``), naming it by its index in ``s``: it never happens. Not an
    error: ``--duration`` shorter than a scenario's schedule is normal. With ``agents``, entries naming an AUV
    beyond the team are left out (dropped, and said so, elsewhere)."""
    end = s.run.duration_s if duration_s is None else duration_s
    team = s.agents.count if agents is None else agents
    when = f"after the mission's end at {end:g} s: it never happens"
    lines = [
        f"kills[{i}] (AUV {k.agent} at {k.time_s:g} s) is {when}"
        for i, k in enumerate(s.kills)
        if k.time_s > end + 1e-9 and k.agent < team
    ]
    lines += [
        f"faults[{i}] ({f.action} {f.target} at {f.at_s:g} s) is {when}"
        for i, f in enumerate(s.faults)
        if f.at_s > end + 1e-9 and (f.auv is None or f.auv < team)
    ]
    return lines


def check_faults(s: Any) -> None:
    """A scenario's faults: targets exist, actions have their durations, and no two faults (or kills) on one target overlap."""
    n = s.agents.count
    spans: dict[str, list[tuple[float, float, str]]] = {}
    for i, k in enumerate(s.kills):
        spans.setdefault(f"auv:{k.agent}", []).append((k.time_s, math.inf, f"kills[{i}]"))
    for i, f in enumerate(s.faults):
        key = f"faults[{i}]"
        if f.target not in FAULT_COMPONENTS and f.auv is None:
            raise ConfigError(
                f"{key}.target must be auv:N (N in [0, {n - 1}]) or one of {', '.join(FAULT_COMPONENTS)}, "
                f"got {f.target!r}"
            )
        if f.auv is not None and not (0 <= f.auv < n and f.target == f"auv:{f.auv}"):
            raise ConfigError(f"{key}.target must name an AUV in auv:0..auv:{n - 1}, got {f.target!r}")
        if f.action == "stop" and not f.duration_s > 0:
            raise ConfigError(f"{key}.duration_s must be > 0 for action 'stop', got {f.duration_s!r}")
        if f.action == "restart" and not f.down_s > 0:
            raise ConfigError(f"{key}.down_s must be > 0 for action 'restart', got {f.down_s!r}")
        if f.target in ("world", "recorder") and f.action == "restart":
            raise ConfigError(
                f"{key}: the {f.target} cannot be restarted (the world holds the clock, the recorder its file); "
                "use kill, stop or term"
            )
        spans.setdefault(f.target, []).append((f.at_s, f.at_s + f.span_s, key))
    for target, items in spans.items():
        items.sort()
        for (_a0, a1, ka), (b0, _b1, kb) in zip(items, items[1:], strict=False):
            if b0 <= a1:
                until = "for ever" if a1 == math.inf else f"until {a1:g} s"
                raise ConfigError(f"{kb} overlaps {ka} on {target}: {ka} lasts {until}, {kb} starts at {b0:g} s")
