"""The channel as a real process: router + ``python -m channel_sim`` + two stand-in AUV processes.

The test plays the world: per tick k it publishes ChannelTick(k), waits for
ChannelDone(k), sends Nav(k) with the rx count to each AUV and waits for their
Command(k). The AUVs sit 1500 m apart; TDMA slots of 2 s, one per tick.
"""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import pytest

from auv_swarm.channel_sim.service import ChannelService
from auv_swarm.contract import rng, wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.mission import procs

from .conftest import Inbox

STAND_IN = Path(__file__).with_name("stand_in_auv.py")
"""A test-only AUV, run as a script (the tests folder is not installed)."""

pytestmark = pytest.mark.integration

HERE = Path(__file__).resolve().parent
TICK_S = 2.0
SEED = 7
POSITIONS = {0: (0.0, 0.0), 1: (1500.0, 0.0)}
PAYLOAD_BYTES = 8
SCENARIO = f"""
name = "channel-process-test"
[run]
seed = {SEED}
tick_s = {TICK_S}
tick_timeout_s = 2.0
[agents]
count = 2
positions_m = [[0.0, 0.0], [1500.0, 0.0]]
[channel]
slot_s = 2.0
guard_s = 0.1
max_range_m = 1600.0
bit_rate_bps = 240.0
pdr = 0.65
"""
BIT_RATE_BPS = 240.0  # the slot then holds 200 bits: an AUV's payload header fits (the scenario check)


class World:
    """The test's stand-in for the world process, over a ZenohBus with the "world" credentials."""

    def __init__(self, bus, agents: tuple[int, ...]) -> None:
        self.bus = bus
        self.agents = agents
        self.dones: dict[int, wire.ChannelDone] = {}
        self.commands: dict[tuple[int, int], wire.Command] = {}
        self.stats: list[wire.ChannelStats] = []
        self.alive = Inbox()
        self.tx_counts: dict[int, int] = {}
        self._cond = threading.Condition()
        bus.subscribe(wire.channel_done(), self._on_done)
        bus.subscribe(wire.all_commands(), self._on_command)
        bus.subscribe(wire.channel_stats(), self._on_stats)
        bus.subscribe_liveliness(wire.all_liveliness(), self.alive)

    def _on_done(self, _key: str, data: bytes) -> None:
        msg = wire.decode(data, wire.ChannelDone)
        with self._cond:
            self.dones[msg.tick] = msg
            self._cond.notify_all()

    def _on_command(self, _key: str, data: bytes) -> None:
        msg = wire.decode(data, wire.Command)
        with self._cond:
            self.commands[(msg.tick, msg.auv)] = msg
            self._cond.notify_all()

    def _on_stats(self, _key: str, data: bytes) -> None:
        msg = wire.decode(data, wire.ChannelStats)
        with self._cond:
            self.stats.append(msg)
            self._cond.notify_all()

    def wait_alive(self, key: str, alive: bool = True, timeout: float = 15.0) -> None:
        """Wait until the latest liveliness change seen for ``key`` (or a session's token under it) is ``alive``."""

        def latest(items: list) -> bool:
            states = [state for k, state in items if k == key or k.startswith(f"{key}/")]
            return bool(states) and states[-1] == alive

        assert self.alive.wait_for(latest, timeout), f"{key} never became alive={alive}"

    def wait_stats(self, predicate, timeout: float = 10.0) -> wire.ChannelStats:
        """Wait for a ChannelStats whose counters satisfy ``predicate``; returns it."""
        with self._cond:
            ok = self._cond.wait_for(lambda: any(predicate(s.counters) for s in self.stats), timeout=timeout)
            assert ok, f"no ChannelStats matched; last: {self.stats[-1].counters if self.stats else None}"
            return next(s for s in self.stats if predicate(s.counters))

    def channel_tick(self, k: int) -> wire.ChannelTick:
        return wire.ChannelTick(
            tick=k,
            tx_expected={a: self.tx_counts.get(a, 0) for a in self.agents},
            positions=dict(POSITIONS),
            alive=self.agents,
            t_s=k * TICK_S,
            source="world",
        )

    def step(self, k: int, done_timeout: float = 5.0) -> wire.ChannelDone | None:
        """One lockstep tick; returns the channel's ChannelDone(k), or None if it did not come."""
        self.bus.publish(wire.channel_tick(), wire.encode(self.channel_tick(k)))
        with self._cond:
            self._cond.wait_for(lambda: k in self.dones, timeout=done_timeout)
            done = self.dones.get(k)
        for a in self.agents:
            x, y = POSITIONS[a]
            rx_expected = done.rx_count.get(a, 0) if done else 0
            nav = wire.Nav(
                tick=k,
                auv=a,
                x=x,
                y=y,
                theta=0.0,
                u=0.0,
                r=0.0,
                rx_expected=rx_expected,
                t_s=k * TICK_S,
                source="world",
            )
            self.bus.publish(wire.nav(a), wire.encode(nav))
        with self._cond:
            ok = self._cond.wait_for(lambda: all((k, a) in self.commands for a in self.agents), timeout=10.0)
            assert ok, f"the stand-in AUVs did not answer tick {k}"
            self.tx_counts = {a: self.commands[(k, a)].tx_count for a in self.agents}
        return done


def _received(proc) -> list[dict]:
    return [json.loads(line[3:]) for line in procs.read_log(proc).splitlines() if line.startswith("RX ")]


@pytest.fixture
def swarm(tmp_path, start_router, spawner, connect):
    """Router, channel process, two stand-in AUVs and the test's World, all ready."""
    scenario_path = tmp_path / "scenario.toml"
    scenario_path.write_text(SCENARIO, encoding="utf-8")
    router = start_router(agents=2)
    world = World(connect(router.endpoint, "world"), agents=(0, 1))

    def start_channel():
        proc = spawner(
            procs.python_argv(
                "auv_swarm.channel_sim",
                "--router",
                router.endpoint,
                "--scenario",
                str(scenario_path),
                "--stats-every",
                "5",
            ),
            "channel",
        )
        procs.wait_for_line(proc, r"channel ready on", timeout=20.0)
        world.wait_alive(wire.liveliness_component("channel"))
        return proc

    auvs = []
    for a in (0, 1):
        argv = [sys.executable, str(STAND_IN), "--router", router.endpoint, "--id", str(a)]
        auvs.append(spawner([*argv, "--period", "2", "--offset", str(a), "--bytes", str(PAYLOAD_BYTES)], f"auv{a}"))
    for a, proc in enumerate(auvs):
        procs.wait_for_line(proc, r"stand-in auv \d ready", timeout=20.0)
        world.wait_alive(wire.liveliness(a))
    return {"router": router, "world": world, "auvs": auvs, "start_channel": start_channel, "scenario": scenario_path}


def test_packets_flow_through_the_channel_with_delay_and_loss(swarm) -> None:
    world, auvs = swarm["world"], swarm["auvs"]
    channel = swarm["start_channel"]()
    ticks = 200
    dones = [world.step(k) for k in range(ticks)]
    assert all(d is not None for d in dones)

    # the same inputs through the pure service, in-process, with the same seed: identical rx counts
    scenario = load_scenario(swarm["scenario"])
    service = ChannelService(scenario, rng.stream(SEED, "channel"))
    expected = []
    for k in range(ticks):
        txs = [
            wire.ModemTx(
                tick=k - 1,
                auv=a,
                seq=(k - 1) // 2,
                payload=bytes([a, ((k - 1) // 2) % 256]) * (PAYLOAD_BYTES // 2),
                t_s=(k - 1) * TICK_S,
                source=f"auv/{a}",
            )
            for a in (0, 1)
            if k >= 1 and (k - 1) % 2 == a
        ]
        tick = world.channel_tick(k)
        tick = wire.ChannelTick(
            tick=k,
            tx_expected={a: sum(t.auv == a for t in txs) for a in (0, 1)},
            positions=tick.positions,
            alive=tick.alive,
            t_s=tick.t_s,
            source="world",
        )
        expected.append(service.on_tick(tick, txs)[2].rx_count)
    assert [d.rx_count for d in dones] == expected

    airtime = 8 * PAYLOAD_BYTES / BIT_RATE_BPS
    latency = airtime + 1500.0 / 1500.0
    received = {a: _received(proc) for a, proc in enumerate(auvs)}
    sent_frames = {a: ticks // 2 - (1 if a == 1 else 0) for a in (0, 1)}
    for a in (0, 1):
        other = 1 - a
        assert all(r["sender"] == other for r in received[a])
        assert all(abs(r["t_arrival"] - r["t_sent"] - latency) < 1e-9 for r in received[a])
        assert all(r["tick"] * TICK_S >= r["t_arrival"] > (r["tick"] - 1) * TICK_S for r in received[a])
        assert len(received[a]) == sum(d.rx_count[a] for d in dones)
    delivered = len(received[0]) + len(received[1])
    pdr = delivered / (sent_frames[0] + sent_frames[1])
    assert abs(pdr - 0.65) < 0.12, pdr
    assert procs.stop(channel) == 0
    assert "channel stopped" in procs.read_log(channel)
    world.wait_stats(lambda c: c["delivered"] == delivered and c["ticks"] == ticks)


def test_channel_restart_and_malformed_input(swarm, connect) -> None:
    world, auvs = swarm["world"], swarm["auvs"]
    channel = swarm["start_channel"]()
    for k in range(10):
        assert world.step(k) is not None

    forger = connect(swarm["router"].endpoint, "auv0")
    for junk in (b"", b"\xc1", b"not msgpack at all", wire.encode(world.channel_tick(3)), bytes(range(256))):
        forger.publish(wire.modem_tx(0), junk)
    for k in range(10, 20):
        assert world.step(k) is not None
    assert channel.poll() is None

    before = [len(_received(p)) for p in auvs]
    assert procs.stop(channel) == 0
    world.wait_stats(lambda c: c["decode_errors"] == 5 and c["ticks"] == 20)
    world.wait_alive(wire.liveliness_component("channel"), alive=False)
    for k in range(20, 24):
        assert world.step(k, done_timeout=0.5) is None
    assert [len(_received(p)) for p in auvs] == before

    channel = swarm["start_channel"]()
    dones = [world.step(k) for k in range(24, 60)]
    assert all(d is not None for d in dones)
    assert sum(len(_received(p)) for p in auvs) > sum(before)
    assert all(p.poll() is None for p in auvs)
    assert procs.stop(channel) == 0
