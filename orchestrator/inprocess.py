"""The whole swarm in one process, over an in-memory bus: same cores, same shells' logic, no zenoh.

Used by ``auv-swarm run --mode inprocess`` for fast batches and by tests. The
world drives the lockstep protocol of ``world.service`` on an
``InMemoryBus``; the channel is the channel process's ``ChannelNode`` and each
AUV the AUV process's ``AgentNode``, subscribed to the same keys and exchanging
the same messages as over zenoh. The bus carries the frozen message objects
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
    if scenario.planner.method == "centralised":
        _add_central(bus, scenario, wire_codec)
    for auv in world.alive:
        node = AgentNode(AgentCore(auv, scenario))

        def deliver(_key: str, msg: wire.Message, node: AgentNode = node) -> None:
            for out_key, out in node.on_message(msg):
                bus.publish(out_key, out)

        def deliver_bytes(key: str, data: bytes, node: AgentNode = node) -> None:
            for out_key, out in node.on_bytes(key, data):
                bus.publish(out_key, out)

        for key in node.subscriptions():
            bus.subscribe(key, deliver_bytes if wire_codec else deliver)

    def received(data: object, expected: type | None = None) -> object:
        return wire.decode(data, expected) if wire_codec else data

    dones: dict[int, wire.ChannelDone] = {}
    commands: dict[int, wire.Command] = {}
    bus.subscribe(wire.channel_done(), lambda _k, m: _file(dones, received(m, wire.ChannelDone)))
    bus.subscribe(wire.all_commands(), lambda _k, m: _file_command(commands, received(m, wire.Command)))

    def to_sinks(_key: str, data: object) -> None:
        msg = received(data)
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


def _add_central(bus: InMemoryBus, scenario: Scenario, wire_codec: bool) -> None:
    """The central planner of the centralised MPC, subscribed like the ``central`` process."""
    from central.core import CentralCore
    from central.node import CentralNode

    node = CentralNode(CentralCore(scenario))

    def deliver(_key: str, msg: wire.Message) -> None:
        for out_key, out in node.on_message(msg):
            bus.publish(out_key, out)

    def deliver_bytes(key: str, data: bytes) -> None:
        for out_key, out in node.on_bytes(key, data):
            bus.publish(out_key, out)

    for key in node.subscriptions():
        bus.subscribe(key, deliver_bytes if wire_codec else deliver)


def _file(dones: dict[int, wire.ChannelDone], msg: wire.ChannelDone) -> None:
    dones[msg.tick] = msg


def _file_command(commands: dict[int, wire.Command], msg: wire.Command) -> None:
    commands[msg.auv] = msg
