"""The whole swarm in one process, over an in-memory bus: same cores, same shells' logic, no zenoh.

Used by ``auv-swarm run --mode inprocess`` for fast batches and by tests. The
world drives the lockstep protocol of ``world.service`` on an
``InMemoryBus``; the channel is the channel process's ``ChannelNode`` and each
AUV the AUV process's ``AgentNode``, subscribed to the same keys and exchanging
the same messages as over zenoh, and every consumer admits what it hears through the
same identity and replay check (``contract.identity.Gate``). The bus carries the frozen message objects
themselves: the msgpack codec is lossless (``decode(encode(m)) == m``, checked by
the wire tests and, for a whole mission, by ``wire_codec=True``), so skipping it
changes nothing but the time. The bus is synchronous, so every tick runs in a
fixed order and a scenario and seed give the same metrics as the multi-process
swarm.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

from agent.core import AgentCore
from agent.node import AgentNode
from channel_sim.node import ChannelNode
from contract import wire
from contract.bus import InMemoryBus
from contract.config import Scenario
from contract.identity import Gate
from world.service import WorldService


class Sink(Protocol):
    """Receives what a recorder hears on the bus (truth, sensor, telemetry, channel and world events)."""

    def on_message(self, msg: object) -> None: ...


RECORDER_KEYS = (
    wire.truth(),
    wire.all_telemetry(),
    "auvswarm/auv/*/sensor",
    wire.channel_events(),
    wire.channel_stats(),
    wire.world_events(),
)
"""What a recorder subscribes to."""


def run_inprocess(
    scenario: Scenario,
    sinks: list[Sink],
    progress: Callable[[float, float], None] | None = None,
    wire_codec: bool = False,
) -> None:
    """Run the mission tick by tick, handing every message a recorder would hear to ``sinks``.

    ``wire_codec``: send every message through the msgpack codec, as over zenoh
    (slower; the result is the same).
    """
    bus = InMemoryBus()
    world = WorldService(scenario)
    channel = ChannelNode(bus, scenario, scenario.run.seed, encoded=wire_codec)
    bus.subscribe(wire.all_modem_tx(), channel.on_tx if wire_codec else channel.accept_tx)
    bus.subscribe(wire.channel_tick(), channel.on_tick_message if wire_codec else channel.accept_tick)
    for auv in world.alive:
        node = AgentNode(AgentCore(auv, scenario))

        def deliver(key: str, msg: wire.Message, node: AgentNode = node) -> None:
            for out_key, out in node.on_message(key, msg):
                bus.publish(out_key, out)

        def deliver_bytes(key: str, data: bytes, node: AgentNode = node) -> None:
            for out_key, out in node.on_bytes(key, data):
                bus.publish(out_key, out)

        for key in node.subscriptions():
            bus.subscribe(key, deliver_bytes if wire_codec else deliver)

    world_gate, recorder_gate = Gate("world"), Gate("recorder")

    def received(gate: Gate, key: str, data: object, max_tick: int | None = None) -> wire.Message | None:
        if wire_codec:
            return gate.receive(key, data, max_tick=max_tick)
        return data if gate.admit(key, data, max_tick) else None

    dones: dict[int, wire.ChannelDone] = {}
    commands: dict[int, wire.Command] = {}

    def on_world_input(key: str, data: object) -> None:
        msg = received(world_gate, key, data, max_tick=world.tick)
        if isinstance(msg, wire.ChannelDone):
            dones[msg.tick] = msg
        elif isinstance(msg, wire.Command):
            commands[msg.auv] = msg

    bus.subscribe(wire.channel_done(), on_world_input)
    bus.subscribe(wire.all_commands(), on_world_input)

    def to_sinks(key: str, data: object) -> None:
        msg = received(recorder_gate, key, data)
        if msg is None:
            return
        for sink in sinks:
            sink.on_message(msg)

    for key in RECORDER_KEYS:
        bus.subscribe(key, to_sinks)

    def publish_encoded(key: str, msg: wire.Message) -> None:
        bus.publish(key, wire.encode(msg))

    publish = publish_encoded if wire_codec else bus.publish
    tick_key, clock_key, truth_key, events_key = wire.channel_tick(), wire.clock(), wire.truth(), wire.world_events()
    agent_keys = {a: (wire.sensor(a), wire.nav(a)) for a in world.alive}
    never = threading.Event()
    publish(events_key, wire.WorldEvent(t_s=0.0, source="world", kind="start", auv=-1, text=scenario.name))
    while not world.finished:
        tick = world.tick
        publish(tick_key, world.channel_tick())
        channel.process_next(never, poll_s=0.0)
        done = dones.pop(tick, None)
        publish(clock_key, world.clock())
        publish(truth_key, world.truth())
        commands.clear()
        for a, inp in world.agent_inputs(done).items():
            sensor_key, nav_key = agent_keys[a]
            publish(sensor_key, inp.sensor)
            publish(nav_key, inp.nav)
        for event in world.apply(dict(commands)):
            publish(events_key, event)
        if progress is not None:
            progress(world.model.time_s, scenario.run.duration_s)
    channel.publish_stats()
    end = wire.WorldEvent(t_s=world.model.time_s, source="world", kind="end", auv=-1, text="mission complete")
    publish(events_key, end)
    bus.close()
