"""A whole mission with an extra attacking client that holds AUV 0's legitimate credentials.

``auv-swarm run --credentials DIR`` runs the real swarm (router, world, channel, AUVs,
recorder, orchestrator as separate processes on loopback). A second zenoh session
logs in as ``auv0`` with ``DIR/auv0.password`` and, on every clock tick, publishes on
AUV 0's own keys: bodies that claim AUV 1 (a command that would move it, telemetry
that would overwrite its rows, a modem frame in its name) and replays of AUV 0's old
ticks. It also tries AUV 1's keys directly. Every AUV's metrics must equal those of the
same mission without the attacker, and every forged or replayed message must be counted.
The attacker stamps its messages with the real AUV 0's session id (read through the recorder's login, as one
that learnt it on the host it stole the password from), so it is not caught as a second session (issue 44,
``test_stolen_login.py``): this mission tests the identity and replay checks beneath that.

While the mission runs, the environment and command line of every child of
``auv-swarm run`` are read from /proc: none may hold any process's password.
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
from pathlib import Path

import pytest

from auv_swarm.bus import credentials, zbus
from auv_swarm.contract import wire
from auv_swarm.contract.config import dump_toml, load_scenario
from auv_swarm.contract.payload import AcousticPayload, encode_payload
from auv_swarm.orchestrator.mission.api import run_mission
from auv_swarm.results.metrics import comparable
from tests.processes import session
from tests.security.impostors import real_session

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
SECRET_ENV = ("AUVSWARM_SECRET", credentials.PASSWORD_FILE_ENV, credentials.USERS_FILE_ENV)


class Attacker:
    """AUV 0's credentials in a second session: forged bodies and replays on every clock tick."""

    def __init__(self, bus: zbus.ZenohBus, n_headings: int, stamp: str) -> None:
        self.bus = bus
        self.n_headings = n_headings
        self.stamp = stamp.encode()
        self._pubs: dict[str, object] = {}
        self.sent: dict[str, int] = {}
        self.ticks = 0
        self._lock = threading.Lock()

    def _put(self, what: str, key: str, msg: wire.Message) -> None:
        pub = self._pubs.get(key)
        if pub is None:
            pub = self._pubs[key] = self.bus.session.declare_publisher(key)
        pub.put(wire.encode(msg), attachment=self.stamp)
        self.sent[what] = self.sent.get(what, 0) + 1

    def on_clock(self, _key: str, data: bytes) -> None:
        clock = wire.decode(data, wire.Clock)
        k, t = clock.tick, clock.t_s
        with self._lock:
            self.ticks += 1
            me, victim = "auv/0", 1
            # 1: a command for AUV 1, sent on AUV 0's key (body id and body source forged)
            cmd = wire.Command(t_s=t, source=me, tick=k, auv=victim, u=2.0, r=0.05, tx_count=0)
            self._put("command_forged_auv", wire.command(0), cmd)
            self._put("command_forged_source", wire.command(0), dataclasses.replace(cmd, source="auv/1"))
            # 2: a modem frame in AUV 1's name, with a payload claiming AUV 1
            payload, _ = encode_payload(
                AcousticPayload(sender=victim, t_s=t, x=0.0, y=0.0, theta=0.0, u_e=1.0, plan=(), round=0, bearings=()),
                1600,
                self.n_headings,
            )
            tx = wire.ModemTx(t_s=t, source=me, tick=k, auv=victim, seq=k, payload=payload)
            self._put("tx_forged_auv", wire.modem_tx(0), tx)
            # 3: telemetry for AUV 1 with a false estimate
            tm = wire.Telemetry(
                t_s=t, source=me, tick=k, auv=victim, estimate_ok=True, estimate_reason="forged",
                xi=(1e4, 1e4, 0.0, 0.0), P=(1.0,) * 16, plan=(), waypoints=(), cost=0.0, terms={},
                plan_wall_ms=0.0, n_measurements=1, planned=False, fiedler=0.0, nav=(0.0, 0.0, 0.0),
            )  # fmt: skip
            self._put("telemetry_forged_auv", wire.telemetry(0), tm)
            # replays: AUV 0's own messages of a tick long processed
            if k >= 6:
                old = k - 5
                self._put("command_replay", wire.command(0), dataclasses.replace(cmd, auv=0, tick=old, u=0.0))
                self._put("telemetry_replay", wire.telemetry(0), dataclasses.replace(tm, auv=0, tick=old))
                self._put("tx_replay", wire.modem_tx(0), dataclasses.replace(tx, auv=0, tick=old, seq=1))
            # another AUV's keys outright (the router denies them)
            self.bus.publish(wire.command(victim), wire.encode(dataclasses.replace(cmd, source="auv/1")))
            self.bus.publish(wire.telemetry(victim), wire.encode(dataclasses.replace(tm, source="auv/1")))


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text(encoding="ascii", errors="replace")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            out.append(int(entry.name))
    return out


def _exposed(pid: int) -> dict[str, bytes]:
    try:
        return {name: (Path(f"/proc/{pid}") / name).read_bytes() for name in ("environ", "cmdline")}
    except OSError:
        return {}


@pytest.fixture(scope="module")
def attacked_mission(tmp_path_factory) -> dict:
    tmp = tmp_path_factory.mktemp("attacked")
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=140.0, seed=7)
    scenario = dataclasses.replace(scenario, name="attacked", kills=())
    scenario_path = tmp / "scenario.toml"
    scenario_path.write_text(dump_toml(scenario), encoding="utf-8")
    creds = tmp / "creds"
    assert credentials.main(["--out", str(creds), "--agents", str(scenario.agents.count)]) == 0
    passwords = {p.stem: p.read_text().strip() for p in creds.glob("*.password")}
    out = tmp / "out"
    argv = [sys.executable, "-m", "auv_swarm", "run", "--quiet", "--scenario", str(scenario_path)]
    env = {k: v for k, v in os.environ.items() if k not in SECRET_ENV}
    exposed: dict[int, dict[str, bytes]] = {}
    attacker: Attacker | None = None
    with session([*argv, "--out", str(out), "--credentials", str(creds)], env=env) as proc:
        router_log = out / "logs" / "router.log"
        deadline = time.monotonic() + 60.0
        endpoint = None
        while endpoint is None and time.monotonic() < deadline and proc.poll() is None:
            found = re.search(r"router listening on (\S+)", router_log.read_text()) if router_log.exists() else None
            endpoint = found.group(1) if found else None
            time.sleep(0.05)
        assert endpoint, "the router never came up"
        stamp = real_session(endpoint, creds, 0)
        with zbus.ZenohBus(endpoint, "auv0", passwords["auv0"]) as bus:
            attacker = Attacker(bus, scenario.planner.n_headings, stamp)
            bus.subscribe(wire.clock(), attacker.on_clock)
            while proc.poll() is None:
                for child in _children(proc.pid):
                    exposed.setdefault(child, _exposed(child))
                time.sleep(0.2)
        stdout, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 0, stderr[-3000:]
    baseline = run_mission(scenario).metrics
    channel_log = (out / "logs" / "channel.log").read_text()
    counters = ast.literal_eval(channel_log.split("channel stopped: ", 1)[1].splitlines()[0])
    return {
        "metrics": json.loads((out / "metrics.json").read_text()),
        "baseline": baseline,
        "attacker": attacker,
        "exposed": exposed,
        "passwords": passwords,
        "channel": counters,
        "world_log": (out / "logs" / "world.log").read_text(),
        "recorder_log": (out / "logs" / "recorder.log").read_text(),
        "stderr": stderr,
    }


def test_the_attacker_was_active_all_mission(attacked_mission) -> None:
    attacker = attacked_mission["attacker"]
    assert attacker.ticks >= 60, attacker.ticks
    assert attacker.sent["command_forged_auv"] >= 60 and attacker.sent["tx_replay"] >= 50


def test_every_auvs_metrics_equal_the_run_without_the_attacker(attacked_mission) -> None:
    assert comparable(attacked_mission["metrics"]) == comparable(attacked_mission["baseline"])


def test_forged_commands_are_dropped_and_counted_by_the_world(attacked_mission) -> None:
    world_log = attacked_mission["world_log"]
    assert "dropped a message on auvswarm/auv/0/cmd (forged_source" in world_log
    assert "(replay: Command of tick" in world_log


def test_forged_and_replayed_frames_are_dropped_and_counted_by_the_channel(attacked_mission) -> None:
    c, sent = attacked_mission["channel"], attacked_mission["attacker"].sent
    assert c["tx_forged_auv"] == sent["tx_forged_auv"]
    assert c["tx_replay"] + c["tx_late"] == sent["tx_replay"]
    assert c["tx_late"] > 0, "a frame of a tick the channel already took is late (the channel keeps no replay books)"


def test_forged_telemetry_is_dropped_by_the_orchestrator_and_the_recorder(attacked_mission) -> None:
    assert "orchestrator: dropped a message on auvswarm/auv/0/telemetry (forged_auv" in attacked_mission["stderr"]
    assert "orchestrator: dropped a message on auvswarm/auv/0/telemetry (replay" in attacked_mission["stderr"]
    assert "recorder: dropped a message on auvswarm/auv/0/telemetry (forged_auv" in attacked_mission["recorder_log"]


def test_no_child_holds_a_credential_in_its_environment_or_command_line(attacked_mission) -> None:
    exposed, passwords = attacked_mission["exposed"], attacked_mission["passwords"]
    assert len(exposed) >= 7, "router, channel, 3 AUVs, recorder and world should all have been seen"
    for pid, files in exposed.items():
        for name, data in files.items():
            for user, password in passwords.items():
                assert password.encode() not in data, f"pid {pid} {name} holds {user}'s password"
            for var in SECRET_ENV:
                assert var.encode() not in data, f"pid {pid} {name} names {var}"
