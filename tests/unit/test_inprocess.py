"""The in-process swarm: passing message objects over the in-memory bus equals going through the codec."""

from __future__ import annotations

import dataclasses

from auv_swarm.contract import wire
from auv_swarm.contract.config import KillEvent, load_scenario
from auv_swarm.orchestrator.mission.inprocess import run_inprocess
from auv_swarm.results.collect import MessageLog
from auv_swarm.results.metrics import comparable, compute_metrics
from tests.unit.sinks import Keep


def _no_wall_clock(msg: object) -> object:
    """The message with its one wall-clock field (planning time) zeroed."""
    return dataclasses.replace(msg, plan_wall_ms=0.0) if isinstance(msg, wire.Telemetry) else msg


def test_objects_on_the_bus_give_the_same_mission_as_the_msgpack_codec() -> None:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=300.0, seed=3)
    scenario = dataclasses.replace(scenario, kills=(KillEvent(agent=2, time_s=200.0),))
    plain, coded = Keep(), Keep()
    plain_log, coded_log = MessageLog(), MessageLog()
    run_inprocess(scenario, [plain, plain_log])
    run_inprocess(scenario, [coded, coded_log], wire_codec=True)
    assert len(plain.messages) == len(coded.messages) > 3 * 150
    kinds = {type(m).__name__ for m in plain.messages}
    assert {"Truth", "Telemetry", "Sensor", "PacketEvent", "WorldEvent", "ChannelStats"} <= kinds
    for a, b in zip(plain.messages, coded.messages, strict=True):
        assert wire.encode(_no_wall_clock(a)) == wire.encode(_no_wall_clock(b))
    assert any(isinstance(m, wire.WorldEvent) and m.kind == "kill" for m in plain.messages)
    m_plain = compute_metrics(plain_log.to_record(scenario, "inprocess", 0.0))
    m_coded = compute_metrics(coded_log.to_record(scenario, "inprocess", 0.0))
    assert comparable(m_plain) == comparable(m_coded)
