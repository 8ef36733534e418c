"""The whole swarm in one process, over an in-memory bus: same cores, same shells' logic, no zenoh.

Used by ``auv-swarm run --mode inprocess`` for fast batches, by tests and, one TDMA slot at a time, by the
PettingZoo environment (:class:`InProcessMission` is the swarm as an object stepped tick by tick). The
world runs the tick loop of ``world.lockstep`` (the one the world process runs) on an
``InMemoryBus``; the channel is the channel process's ``ChannelNode`` and each
AUV the AUV process's ``AgentNode``, subscribed to the same keys and exchanging
the same messages as over zenoh, and every consumer admits what it hears through the
same identity and replay check (``bus.identity.Gate``). The bus carries the frozen message objects
themselves: the msgpack codec is lossless (``decode(encode(m)) == m``, checked by
the wire tests and, for a whole mission, by ``wire_codec=True``), so skipping it
changes nothing but the time. The bus is synchronous, so every tick runs in a
fixed order and a scenario and seed give the same metrics as the multi-process
swarm.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from auv_swarm.agent.core import AgentCore
from auv_swarm.agent.node import AgentNode
from auv_swarm.bus.bus import InMemoryBus
from auv_swarm.bus.identity import Gate
from auv_swarm.channel_sim.node import ChannelNode
from auv_swarm.contract import wire
from auv_swarm.contract.config import Scenario
from auv_swarm.orchestrator.mission.listen import Sink
from auv_swarm.world.lockstep import Lockstep
from auv_swarm.world.service import WorldService

RECORDER_KEYS = (
    wire.truth(),
    wire.all_telemetry(),
    wire.all_sensors(),
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
    agent_node: Callable[[AgentCore], AgentNode] = AgentNode,
    channel_node: type[ChannelNode] = ChannelNode,
    frame_sinks: list[Sink] | None = None,
) -> None:
    """Run the mission tick by tick, handing every message a recorder would hear to ``sinks``.

    ``wire_codec``: send every message through the msgpack codec, as over zenoh
    (slower; the result is the same). ``agent_node`` and ``channel_node`` build the AUV and channel
    shells (a bench wraps them: ``bench.flood`` makes one AUV flood its uplink and times the channel).
    ``frame_sinks`` also receive every frame the channel delivers (``ModemRx``): the results writer reads the
    bearings they carry, as the processes-mode orchestrator does (``listen.RESULT_KEYS``).
    """
    mission = InProcessMission(scenario, sinks, wire_codec, agent_node, channel_node, frame_sinks)
    while not mission.finished:
        mission.step()
        if progress is not None:
            progress(mission.world.model.time_s, scenario.run.duration_s)
    mission.close()


class InProcessMission:
    """One mission's swarm over an in-memory bus, built and started, run one lockstep tick per :meth:`step`.

    :func:`run_inprocess` steps it to the end; the PettingZoo environment (``orchestrator.mission.env``)
    steps it a TDMA slot at a time. Between two steps every message of the tick has been delivered (the bus
    is synchronous), so ``world``, ``nodes`` (AUV id -> its ``AgentNode``, whose ``core`` is the AUV's
    ``AgentCore``) and ``lockstep`` can be read. :meth:`close` ends the mission as the world does (the
    channel's counters, the ``end`` event).
    """

    def __init__(
        self,
        scenario: Scenario,
        sinks: list[Sink],
        wire_codec: bool = False,
        agent_node: Callable[[AgentCore], AgentNode] = AgentNode,
        channel_node: type[ChannelNode] = ChannelNode,
        frame_sinks: list[Sink] | None = None,
    ) -> None:
        """The arguments of :func:`run_inprocess` (``frame_sinks``: sinks of every delivered frame too)."""
        self.scenario = scenario
        self.sinks = sinks
        self.wire_codec = wire_codec
        self.agent_node = agent_node
        self.bus = bus = InMemoryBus()
        self.world = world = WorldService(scenario)
        self.channel = channel = channel_node(bus, scenario, scenario.run.seed, encoded=wire_codec)
        bus.subscribe(wire.all_modem_tx(), channel.on_tx if wire_codec else channel.accept_tx)
        bus.subscribe(wire.channel_tick(), channel.on_tick_message if wire_codec else channel.accept_tick)
        if scenario.planner.method == "centralised":
            _add_central(bus, scenario, wire_codec)
        self.nodes = {auv: agent_node(AgentCore(auv, scenario)) for auv in world.alive}
        for auv in world.alive:
            for key in self.nodes[auv].subscriptions():
                bus.subscribe(key, self._deliverer(auv))
        self.world_gate = Gate("world", on_duplicate=lambda key, msg: self.lockstep.on_duplicate(key, msg))
        self.recorder_gate = Gate("recorder")
        self.lockstep = lockstep = Lockstep(world, scenario.run.tick_timeout_s)
        bus.subscribe(wire.channel_done(), self._to_world)
        bus.subscribe(wire.all_commands(), self._to_world)
        for key in RECORDER_KEYS:
            bus.subscribe(key, self._to_sinks)
        if frame_sinks:
            _feed_frames(bus, frame_sinks, lambda key, data: self._received(self.recorder_gate, key, data))
        self.io = BusIO(bus, channel, wire_codec, on_event=self._restarted)
        for key in lockstep.expected_tokens():
            lockstep.on_liveliness(key, True)
        lockstep.start(self.io, 0.0)

    @property
    def finished(self) -> bool:
        """True once the mission's last tick has run."""
        return self.lockstep.finished

    def step(self) -> None:
        """Run one lockstep tick (``world.lockstep``): sense, channel, every AUV's core, integrate."""
        self.lockstep.step(self.io)

    def close(self) -> None:
        """End the mission: the channel's counters and the world's ``end`` event to the sinks; the bus closed."""
        self.channel.publish_stats()
        self.io.publish(wire.world_events(), self.lockstep.end_event())
        self.bus.close()

    def _deliverer(self, auv: int) -> Callable[[str, object], None]:
        """What the bus calls with a message for AUV ``auv``: its node's answers are published."""
        if self.wire_codec:

            def deliver_bytes(key: str, data: bytes) -> None:
                for out_key, out in self.nodes[auv].on_bytes(key, data):
                    self.bus.publish(out_key, out)

            return deliver_bytes

        def deliver(key: str, msg: wire.Message) -> None:
            for out_key, out in self.nodes[auv].on_message(key, msg):
                self.bus.publish(out_key, out)

        return deliver

    def _restarted(self, event: wire.WorldEvent) -> None:
        """A killed AUV's process is gone at once (its token vanishes) and, if it is restarted, its fresh
        process is up at once (a new token); a restarted AUV is a new node with an empty memory (same id, same
        slot)."""
        if event.kind == "kill":
            self.lockstep.on_liveliness(wire.liveliness(event.auv), False)
            self.lockstep.on_liveliness(wire.liveliness(event.auv), True)
        elif event.kind == "rejoin":
            self.nodes[event.auv] = self.agent_node(AgentCore(event.auv, self.scenario))

    def _received(self, gate: Gate, key: str, data: object, max_tick: int | None = None) -> wire.Message | None:
        if self.wire_codec:
            return gate.receive(key, data, max_tick=max_tick)
        return data if gate.admit(key, data, max_tick) else None

    def _to_world(self, key: str, data: object) -> None:
        msg = self._received(self.world_gate, key, data, max_tick=self.world.tick)
        if msg is not None:
            self.lockstep.on_message(msg)

    def _to_sinks(self, key: str, data: object) -> None:
        msg = self._received(self.recorder_gate, key, data)
        if msg is None:
            return
        for sink in self.sinks:
            sink.on_message(msg)


def _feed_frames(bus: InMemoryBus, sinks: list[Sink], admit: Callable[[str, object], object | None]) -> None:
    """Hand every frame the channel delivers (``ModemRx``) that ``admit`` lets through to ``sinks``."""

    def deliver(key: str, data: object) -> None:
        msg = admit(key, data)
        for sink in sinks if msg is not None else ():
            sink.on_message(msg)

    bus.subscribe(wire.all_modem_rx(), deliver)


def _add_central(bus: InMemoryBus, scenario: Scenario, wire_codec: bool) -> None:
    """The central planner of the centralised MPC, subscribed like the ``central`` process."""
    from auv_swarm.central.core import CentralCore
    from auv_swarm.central.node import CentralNode

    node = CentralNode(CentralCore(scenario))

    def deliver(_key: str, msg: wire.Message) -> None:
        for out_key, out in node.on_message(msg):
            bus.publish(out_key, out)

    def deliver_bytes(key: str, data: bytes) -> None:
        for out_key, out in node.on_bytes(key, data):
            bus.publish(out_key, out)

    for key in node.subscriptions():
        bus.subscribe(key, deliver_bytes if wire_codec else deliver)


class BusIO:
    """:class:`world.lockstep.LockstepIO` over the synchronous in-memory bus: every answer is in when the
    channel has run, so a wait never waits."""

    def __init__(
        self,
        bus: InMemoryBus,
        channel: ChannelNode,
        wire_codec: bool,
        on_event: Callable[[wire.WorldEvent], None] | None = None,
    ) -> None:
        self.bus = bus
        self.channel = channel
        self.wire_codec = wire_codec
        self.on_event = on_event
        self._never = threading.Event()

    def publish(self, key: str, msg: wire.Message) -> None:
        if self.on_event is not None and isinstance(msg, wire.WorldEvent):
            self.on_event(msg)
        self.bus.publish(key, wire.encode(msg) if self.wire_codec else msg)

    def wait(self, until: Callable[[], bool], timeout_s: float) -> bool:
        if not until():
            self.channel.process_next(self._never, poll_s=0.0)
        return until()

    def stopping(self) -> bool:
        return False

    def note(self, text: str) -> None:
        """Diagnostics are not printed in process (nothing can hang or die here)."""
