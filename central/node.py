"""Central planner process shell (centralised MPC only): ``auv-swarm central --scenario NAME --router ENDPOINT``.

It ends with the mission (``bus.lifeline``). It listens, outside the acoustic channel, to the world's clock and every AUV's navigation
and bearing, runs :class:`central.core.CentralCore` once it holds a tick's clock and the
navigation and bearing of every AUV the clock lists alive, and sends each AUV its
:class:`contract.wire.CentralPlan`. The AUVs wait for that message before they answer the
tick, so the lockstep stays deterministic. A message that does not decode is counted and
dropped; it never stops the planner. In-process runs use :class:`CentralNode` on the
in-memory bus.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field

from auv_swarm.bus.shell import add_common_args, handle_info_flags, scenario_from_args, serve
from auv_swarm.central.core import CentralCore
from auv_swarm.contract import wire
from auv_swarm.contract.usage import plain_description

USER = "central"


@dataclass
class _Tick:
    alive: tuple[int, ...] | None = None
    t_s: float = 0.0
    navs: dict[int, wire.Nav] = field(default_factory=dict)
    sensors: dict[int, wire.Sensor] = field(default_factory=dict)

    def complete(self) -> bool:
        return self.alive is not None and all(a in self.navs and a in self.sensors for a in self.alive)


class CentralNode:
    """The shell: file messages by tick, run the core on each complete tick, return what to publish."""

    def __init__(self, core: CentralCore) -> None:
        self.core = core
        self.ticks: dict[int, _Tick] = {}
        self.next_tick = 0
        self.decode_errors = 0

    def subscriptions(self) -> list[str]:
        """The clock and every AUV's navigation and bearing."""
        p = wire.PREFIX
        return [wire.clock(), f"{p}/auv/*/nav", f"{p}/auv/*/sensor"]

    def on_message(self, msg: object) -> list[tuple[str, wire.Message]]:
        """File one decoded message; run every tick now complete, in order."""
        tick = getattr(msg, "tick", -1)
        if not isinstance(msg, (wire.Clock, wire.Nav, wire.Sensor)) or tick < self.next_tick:
            return []
        box = self.ticks.setdefault(tick, _Tick())
        if isinstance(msg, wire.Clock):
            box.alive, box.t_s = tuple(msg.alive), msg.t_s
        elif isinstance(msg, wire.Nav):
            box.navs[msg.auv] = msg
        else:
            box.sensors[msg.auv] = msg
        out: list[tuple[str, wire.Message]] = []
        for k in sorted(self.ticks):
            box = self.ticks[k]
            if not box.complete():
                continue
            alive = box.alive or ()
            plans = self.core.on_tick(k, box.t_s, {a: box.navs[a] for a in alive}, {a: box.sensors[a] for a in alive})
            out.extend((wire.central_plan(a), m) for a, m in sorted(plans.items()))
            for old in [t for t in self.ticks if t <= k]:
                del self.ticks[old]
            self.next_tick = k + 1
        return out

    def on_bytes(self, key: str, data: bytes) -> list[tuple[str, bytes]]:
        """:meth:`on_message` for an encoded message; a message that does not decode is counted, never raised."""
        try:
            msg = wire.decode(data)
        except wire.DecodeError as exc:
            self.decode_errors += 1
            if self.decode_errors <= 10 or self.decode_errors % 100 == 0:
                print(f"central: dropped malformed message on {key}: {exc}", file=sys.stderr, flush=True)
            return []
        return [(k, wire.encode(m)) for k, m in self.on_message(msg)]


def main(argv: list[str] | None = None) -> int:
    """``auv-swarm central --scenario NAME --router ENDPOINT``."""
    parser = argparse.ArgumentParser(prog="auv-swarm central", description=plain_description(__doc__))
    add_common_args(parser)
    args = parser.parse_args(argv)
    if handle_info_flags(args, "central", sections=("estimator", "planner")):
        return 0
    scenario = scenario_from_args(args)
    if scenario.planner.method != "centralised":
        print(
            f"error: planner.method must be 'centralised' for the central planner, got {scenario.planner.method!r}",
            file=sys.stderr,
        )
        return 2

    node = CentralNode(CentralCore(scenario))
    return serve(args, USER, USER, wire.liveliness_component(USER), scenario.run.grace_s, node)


if __name__ == "__main__":
    sys.exit(main())
