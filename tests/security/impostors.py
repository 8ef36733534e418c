"""A second zenoh session logged in with AUV 1's password beside the real swarm (issue 44): the four impostors.

Each impostor connects as ``auv1`` with the stolen password, listens to the clock (which AUV 1 may read) and, from
the first clock of tick ``start_tick`` on, speaks for AUV 1 on one key:

- ``command``: a different command of every tick (turn hard, declare no frame);
- ``frame``: one full-size frame of every tick claiming AUV 1, with the seqs the real AUV would use next;
- ``telemetry``: one telemetry message stamped 250 ticks ahead (it made every real one a replay before);
- ``liveliness``: a token of its own session under AUV 1's name;
- ``stall``: a command of every tick that declares 16 frames, and no frame.

With ``forge`` the impostor stamps its messages with the real AUV 1's session id instead of its own (learnt here
through the recorder's login, which may watch the tokens: the AUV's password alone does not show it).

:func:`attack` runs ``auv-swarm run --credentials`` on a scenario with one impostor beside it and returns what
the run left (metrics, events) and the tick the impostor first spoke at.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import sys
import threading
import time
from pathlib import Path
from typing import Any

from auv_swarm.bus import credentials, zbus
from auv_swarm.contract import wire
from auv_swarm.contract.config import Scenario, dump_toml
from tests.processes import session

SECRET_ENV = ("AUVSWARM_SECRET", credentials.PASSWORD_FILE_ENV, credentials.USERS_FILE_ENV)
ATTACKS = ("command", "frame", "telemetry", "liveliness")
STALL_FRAMES = 16
AHEAD_TICKS = 250


class Impostor:
    """One attack on AUV ``auv``'s keys from the first clock of ``start_tick`` on (see the module docstring)."""

    def __init__(
        self, bus: zbus.ZenohBus, attack: str, auv: int, start_tick: int, frame_bytes: int, stamp: str | None = None
    ) -> None:
        self.bus, self.attack, self.auv, self.start_tick = bus, attack, auv, start_tick
        self.frame_bytes = frame_bytes
        self.first_tick: int | None = None
        self.sent = 0
        self._lock = threading.Lock()
        self._token: Any = None
        self._stamp = (stamp or bus.session_id).encode()
        keys = {
            "command": wire.command(auv),
            "stall": wire.command(auv),
            "frame": wire.modem_tx(auv),
            "telemetry": wire.telemetry(auv),
        }
        self._pub = bus.session.declare_publisher(keys[attack]) if attack in keys else None
        """Declared up front, so that its first message goes out at once (as the AUV's own bus would stamp it)."""

    def on_clock(self, _key: str, data: bytes) -> None:
        clock = wire.decode(data, wire.Clock)
        if clock.tick < self.start_tick:
            return
        with self._lock:
            if self.attack in ("telemetry", "liveliness") and self.first_tick is not None:
                return
            if self.first_tick is None:
                self.first_tick = clock.tick
            self._speak(clock.tick, clock.t_s)
            self.sent += 1

    def _speak(self, k: int, t_s: float) -> None:
        a, src = self.auv, f"auv/{self.auv}"
        if self.attack in ("command", "stall"):
            n = STALL_FRAMES if self.attack == "stall" else 0
            cmd = wire.Command(t_s=t_s, source=src, tick=k, auv=a, u=0.5, r=0.2, tx_count=n)
            self._pub.put(wire.encode(cmd), attachment=self._stamp)
        elif self.attack == "frame":
            tx = wire.ModemTx(t_s=t_s, source=src, tick=k, auv=a, seq=k, payload=b"\x5a" * self.frame_bytes)
            self._pub.put(wire.encode(tx), attachment=self._stamp)
        elif self.attack == "telemetry":
            tel = wire.Telemetry(
                t_s=t_s,
                source=src,
                tick=k + AHEAD_TICKS,
                auv=a,
                estimate_ok=True,
                estimate_reason="",
                xi=(0.0, 0.0, 0.0, 0.0),
                P=(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
                plan=(),
                waypoints=(),
                cost=0.0,
                terms={},
                plan_wall_ms=0.0,
                n_measurements=0,
                planned=False,
                fiedler=0.0,
                nav=(0.0, 0.0, 0.0),
            )
            self._pub.put(wire.encode(tel), attachment=self._stamp)
        else:
            self._token = self.bus.declare_liveliness(wire.liveliness_session(a, self.bus.session_id))


def _endpoint(router_log: Path, proc: Any, wait_s: float = 60.0) -> str:
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline and proc.poll() is None:
        found = re.search(r"router listening on (\S+)", router_log.read_text()) if router_log.exists() else None
        if found:
            return found.group(1)
        time.sleep(0.05)
    raise AssertionError("the router never came up")


def real_session(endpoint: str, creds: Path, auv: int, wait_s: float = 30.0) -> str:
    """The session id of AUV ``auv``'s real process, read from its token through the recorder's login."""
    found: list[str] = []
    with zbus.ZenohBus(endpoint, "recorder", (creds / "recorder.password").read_text().strip()) as spy:
        spy.subscribe_liveliness(
            f"{wire.liveliness(auv)}/*", lambda key, alive: found.append(wire.parse_liveliness(key)[1])
        )
        deadline = time.monotonic() + wait_s
        while not found and time.monotonic() < deadline:
            time.sleep(0.05)
    assert found, f"AUV {auv}'s token never showed"
    return found[0]


def attack(
    tmp: Path,
    scenario: Scenario,
    kind: str | None,
    start_tick: int,
    auv: int = 1,
    speed: float = 0.0,
    forge: bool = False,
) -> dict[str, Any]:
    """Run ``scenario`` as processes (paced at ``speed`` times real time; 0: as fast as they go) with a ``kind``
    impostor on AUV ``auv`` from ``start_tick`` (None: no impostor, the clean run); what it left."""
    scenario = dataclasses.replace(scenario, name=f"impostor-{kind}")
    path = tmp / "scenario.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    creds = tmp / "creds"
    assert credentials.main(["--out", str(creds), "--agents", str(scenario.agents.count)]) == 0
    password = (creds / f"auv{auv}.password").read_text().strip()
    out = tmp / "out"
    argv = [
        sys.executable,
        "-m",
        "auv_swarm",
        "run",
        "--scenario",
        str(path),
        "--out",
        str(out),
        "--speed",
        f"{speed:g}",
    ]
    env = {k: v for k, v in os.environ.items() if k not in SECRET_ENV}
    frame_bytes = max(1, int(scenario.channel.bit_rate_bps * 0.5) // 8)
    wall0 = time.monotonic()
    impostor = None
    with session([*argv, "--credentials", str(creds)], env=env) as proc:
        endpoint = _endpoint(out / "logs" / "router.log", proc)
        stamp = real_session(endpoint, creds, auv) if forge else None
        with zbus.ZenohBus(endpoint, f"auv{auv}", password) as bus:
            if kind is not None:
                impostor = Impostor(bus, kind, auv, start_tick, frame_bytes, stamp)
                bus.subscribe(wire.clock(), impostor.on_clock)
            while proc.poll() is None:
                time.sleep(0.1)
        stdout, stderr = proc.communicate(timeout=300)
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    return {
        "code": proc.returncode,
        "metrics": json.loads((out / "metrics.json").read_text()),
        "events": events,
        "first_tick": None if impostor is None else impostor.first_tick,
        "sent": 0 if impostor is None else impostor.sent,
        "console": stdout + stderr,
        "wall_s": time.monotonic() - wall0,
        "logs": out / "logs",
    }
