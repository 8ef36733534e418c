"""The whole swarm in one process: the same cores, the same tick protocol, no zenoh.

Used by ``auv-swarm run --mode inprocess`` for fast batches and by tests. The
sequence of calls is exactly the one the processes exchange over zenoh (see
``orchestrator.lockstep``), so a scenario and seed give the same metrics in
both modes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from agent.core import AgentCore
from auv_core import wire
from auv_core.config import Scenario
from auv_core.payload import slot_budget_bits
from auv_core.rng import stream
from channel_sim.service import ChannelService
from orchestrator.lockstep import WorldService


class Sink(Protocol):
    """Receives what a recorder would hear on the bus (truth, telemetry, channel and world events)."""

    def on_message(self, msg: object) -> None: ...


def max_frame_bits(scenario: Scenario) -> int:
    """The largest modem frame the TDMA slot can carry (the payload budget)."""
    ch = scenario.channel
    return slot_budget_bits(ch.bit_rate_bps, ch.slot_s, ch.guard_s, ch.max_range_m, ch.sound_speed_mps)


def run_inprocess(
    scenario: Scenario,
    sinks: list[Sink],
    progress: Callable[[float, float], None] | None = None,
) -> None:
    """Run the mission tick by tick, feeding every bus message a recorder would see to ``sinks``."""
    world = WorldService(scenario)
    channel = ChannelService(scenario, stream(scenario.run.seed, "channel"), max_frame_bits(scenario))
    agents = {a: AgentCore(a, scenario) for a in world.alive}
    pending_tx: list[wire.ModemTx] = []

    def emit(msg: object) -> None:
        for s in sinks:
            s.on_message(msg)

    emit(wire.WorldEvent(t_s=0.0, source="world", kind="start", auv=-1, text=f"scenario {scenario.name} started"))
    while not world.finished:
        tick_msg = world.channel_tick()
        rx, events, done = channel.on_tick(tick_msg, pending_tx)
        for ev in events:
            emit(ev)
        by_recipient: dict[int, list[wire.ModemRx]] = {}
        for m in rx:
            by_recipient.setdefault(m.auv, []).append(m)
        emit(world.truth())
        inputs = world.agent_inputs(done)
        commands: dict[int, wire.Command] = {}
        pending_tx = []
        for a, inp in inputs.items():
            emit(inp.sensor)
            out = agents[a].on_tick(inp.nav, inp.sensor, by_recipient.get(a, []))
            commands[a] = out.command
            pending_tx.extend(out.tx)
            emit(out.telemetry)
        for ev in world.apply(commands):
            emit(ev)
        if progress is not None:
            progress(world.model.time_s, scenario.run.duration_s)
    emit(wire.ChannelStats(t_s=world.model.time_s, source="channel", counters=channel.counters()))
    emit(wire.WorldEvent(t_s=world.model.time_s, source="world", kind="end", auv=-1, text="mission complete"))
