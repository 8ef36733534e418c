"""A second client logged in with AUV 1's password beside the real AUV 1 (issue 28, items 1 and 2; issue 44).

In process: AUV 1's shell sends a second, different command for one tick; the world reports it as a
``duplicate_login`` event within the tick, quarantines AUV 1 and metrics.json counts it. As processes:
``auv-swarm run --credentials`` runs the real swarm; a second zenoh session logs in as ``auv1`` and, on every
clock tick, sends AUV 1 a different command of that tick and floods AUV 1's uplink with 60 small frames. The
world reports the second session once and quarantines AUV 1; the channel refuses every frame of the second
session (``tx_foreign_session``) and then every frame of AUV 1 (``tx_quarantined``), and the links on the air
stay bounded. In process, the flood of AUV 1's own shell (no second session to tell it by) is refused whether it
goes out before AUV 1's own frames or after them, and changes nothing for the others.
"""

from __future__ import annotations

import ast
import dataclasses
import json
import os
import re
import sys
import threading
import time

import pytest

from auv_swarm.agent.node import AgentNode
from auv_swarm.bus import credentials, zbus
from auv_swarm.contract import wire
from auv_swarm.contract.config import dump_toml, load_scenario
from auv_swarm.orchestrator.mission.inprocess import run_inprocess
from auv_swarm.results.collect import MessageLog
from auv_swarm.results.metrics import compute_metrics
from tests.processes import session

SECRET_ENV = ("AUVSWARM_SECRET", credentials.PASSWORD_FILE_ENV, credentials.USERS_FILE_ENV)
FLOOD_FRAMES = 60
FLOOD_SEQ0 = 1_000_000_000


def test_in_process_a_second_command_of_one_tick_is_reported_within_the_tick() -> None:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=40.0)

    class TwoLogins(AgentNode):
        def _run(self, msg: wire.Message) -> list[tuple[str, wire.Message]]:
            out = super()._run(msg)
            for key, m in list(out):
                if isinstance(m, wire.Command) and m.tick == 5:
                    out.append((key, dataclasses.replace(m, u=0.0, r=0.05)))
            return out

    log = MessageLog()
    run_inprocess(scenario, [log], agent_node=lambda core: TwoLogins(core) if core.auv == 1 else AgentNode(core))
    events = [e for e in log.world_events if e.kind == "duplicate_login"]
    assert [(e.auv, e.t_s) for e in events] == [(1, 10.0)], "reported at the tick it happened, once"
    assert "tick 5" in events[0].text and "auv1" in events[0].text
    metrics = compute_metrics(log.to_record(scenario, "inprocess", 0.0))
    assert metrics["duplicate_logins"] == 1 and metrics["agents"]["1"]["duplicate_logins"] == 1
    assert metrics["agents"]["0"]["duplicate_logins"] == 0


class Impostor:
    """AUV 1's credentials in a second session: on every clock tick a different command and a frame flood."""

    def __init__(self, bus: zbus.ZenohBus) -> None:
        self.bus = bus
        self.ticks: list[int] = []
        self._lock = threading.Lock()

    def on_clock(self, _key: str, data: bytes) -> None:
        clock = wire.decode(data, wire.Clock)
        k, t = clock.tick, clock.t_s
        with self._lock:
            self.ticks.append(k)
            for i in range(FLOOD_FRAMES):
                tx = wire.ModemTx(
                    t_s=t, source="auv/1", tick=k, auv=1, seq=FLOOD_SEQ0 + k * FLOOD_FRAMES + i, payload=b"\x00" * 9
                )
                self.bus.publish(wire.modem_tx(1), wire.encode(tx))
            cmd = wire.Command(t_s=t, source="auv/1", tick=k, auv=1, u=0.0, r=0.05, tx_count=0)
            self.bus.publish(wire.command(1), wire.encode(cmd))


@pytest.fixture(scope="module")
def impostor_mission(tmp_path_factory) -> dict:
    tmp = tmp_path_factory.mktemp("impostor")
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=120.0, seed=3)
    scenario = dataclasses.replace(scenario, name="impostor", kills=())
    scenario_path = tmp / "scenario.toml"
    scenario_path.write_text(dump_toml(scenario), encoding="utf-8")
    creds = tmp / "creds"
    assert credentials.main(["--out", str(creds), "--agents", str(scenario.agents.count)]) == 0
    password = (creds / "auv1.password").read_text().strip()
    out = tmp / "out"
    argv = [sys.executable, "-m", "auv_swarm", "run", "--scenario", str(scenario_path)]
    env = {k: v for k, v in os.environ.items() if k not in SECRET_ENV}
    impostor: Impostor | None = None
    with session([*argv, "--out", str(out), "--credentials", str(creds)], env=env) as proc:
        router_log = out / "logs" / "router.log"
        deadline = time.monotonic() + 60.0
        endpoint = None
        while endpoint is None and time.monotonic() < deadline and proc.poll() is None:
            found = re.search(r"router listening on (\S+)", router_log.read_text()) if router_log.exists() else None
            endpoint = found.group(1) if found else None
            time.sleep(0.05)
        assert endpoint, "the router never came up"
        with zbus.ZenohBus(endpoint, "auv1", password) as bus:
            impostor = Impostor(bus)
            bus.subscribe(wire.clock(), impostor.on_clock)
            while proc.poll() is None:
                time.sleep(0.2)
        stdout, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 1, stderr[-3000:]
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    return {
        "metrics": json.loads((out / "metrics.json").read_text()),
        "events": events,
        "impostor": impostor,
        "world_log": (out / "logs" / "world.log").read_text(),
        "channel_log": (out / "logs" / "channel.log").read_text(),
        "console": stdout + stderr,
        "tick_s": scenario.run.tick_s,
    }


@pytest.mark.integration
def test_the_duplicate_login_is_reported_once_and_the_auv_quarantined(impostor_mission) -> None:
    m, impostor = impostor_mission["metrics"], impostor_mission["impostor"]
    assert len(impostor.ticks) >= 30, impostor.ticks
    dups = [e for e in impostor_mission["events"] if e["kind"] == "duplicate_login"]
    assert [e["agent"] for e in dups] == [1], dups
    assert dups[0]["t_s"] <= (impostor.ticks[0] + 1) * impostor_mission["tick_s"], (dups, impostor.ticks[:3])
    assert m["duplicate_logins"] == 1 == m["agents"]["1"]["duplicate_logins"] and m["compromised_auvs"] == [1]
    assert m["agents"]["0"]["duplicate_logins"] == m["agents"]["2"]["duplicate_logins"] == 0
    assert m["complete"] is False and m["incomplete_reason"] == "compromised"
    assert m["agents"]["1"]["alive_until_s"] == dups[0]["t_s"]
    assert "a second client is logged in as auv1" in impostor_mission["console"]


@pytest.mark.integration
def test_the_flood_on_the_second_login_is_refused_and_the_air_stays_clear(impostor_mission) -> None:
    m, log = impostor_mission["metrics"], impostor_mission["channel_log"]
    counters = ast.literal_eval(log.split("channel stopped: ", 1)[1].splitlines()[0])
    # every flood frame that reaches the channel is refused: of the second session, of the quarantined AUV, or
    # of a tick already served (late: on a loaded machine many)
    refused = sum(counters[k] for k in ("tx_foreign_session", "tx_quarantined", "tx_late"))
    assert counters["tx_quarantined"] > 0, counters
    assert refused >= 10 * FLOOD_FRAMES, counters
    # what goes on the air is what the AUVs declared: the real frames, at most one per AUV and slot
    slots = int(m["sim_duration_s"] // 14.0) + 1
    assert m["channel"]["sent"] <= slots
    assert m["channel"]["in_flight_at_end"] <= 2 * 16


@pytest.mark.parametrize("order", ["before", "after"])
def test_in_process_an_undeclared_flood_of_one_uplink_leaves_the_others_as_they_were(order: str) -> None:
    from auv_swarm.bench.flood import Flood, compare

    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=100.0, seed=2)
    r = compare(scenario, Flood(auv=1, frames=FLOOD_FRAMES, nbytes=9, order=order))
    assert r["refused"]["tx_undeclared"] > 500 and r["refused"]["tx_queue_full"] > 1000
    assert r["frames_on_air"]["with"] == r["frames_on_air"]["without"]
    assert r["in_flight_at_end"]["with"] == r["in_flight_at_end"]["without"]
    assert all(e["with_m"] == e["without_m"] for e in r["others_error"].values()), r["others_error"]
