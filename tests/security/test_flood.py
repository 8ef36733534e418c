"""A flood on AUV 0's own uplink, by a client holding AUV 0's credentials, against the real channel process.

3,000 frames of 60 KiB (far over the slot budget of 1,680 bits) and 3,020 small frames
of one tick (far more than an AUV sends per slot). Every one beyond what an AUV may send
is rejected and counted by reason, and the channel's resident memory grows by less than
20 MB (the flood that found this, 1,500 frames of 60 KiB, took it from 50 to 187 MB).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from auv_swarm.contract import wire
from auv_swarm.orchestrator.mission import procs

pytestmark = pytest.mark.integration

BIG = 60 * 1024
RSS_BOUND_MB = 20.0


def rss_mb(pid: int) -> float:
    """Resident set size of ``pid`` (MB) from /proc."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise AssertionError(f"no VmRSS for pid {pid}")


def _frame(seq: int, nbytes: int) -> bytes:
    tx = wire.ModemTx(t_s=0.0, source="auv/0", tick=0, auv=0, seq=seq, payload=bytes([seq % 256]) * nbytes)
    return wire.encode(tx)


def test_uplink_flood_is_rejected_counted_and_memory_stays_flat(start_router, spawner, connect) -> None:
    router = start_router(agents=3)
    channel = spawner(procs.python_argv("auv_swarm", "channel", "--router", router.endpoint), "channel")
    procs.wait_for_line(channel, "channel ready", timeout=30.0)
    attacker = connect(router.endpoint, "auv0")
    big = [_frame(i, BIG) for i in range(8)]

    def flood_big(n: int, until_count: int) -> None:
        for i in range(n):
            attacker.publish(wire.modem_tx(0), big[i % len(big)])
        procs.wait_for_line(channel, rf"tx_over_budget on .*; {until_count} so far", timeout=60.0)

    for i in range(20):
        attacker.publish(wire.modem_tx(0), _frame(i, 8))
    attacker.publish(wire.modem_tx(0), big[0])
    procs.wait_for_line(channel, r"tx_over_budget on .*; 1 so far", timeout=30.0)
    before = rss_mb(channel.pid)

    flood_big(1999, 2000)
    for i in range(3000):
        attacker.publish(wire.modem_tx(0), _frame(1000 + i, 8))
    flood_big(1000, 3000)
    after = rss_mb(channel.pid)
    print(f"channel RSS {before:.1f} MB -> {after:.1f} MB under the flood (growth {after - before:.1f} MB)")
    assert after - before < RSS_BOUND_MB

    assert procs.stop(channel) == 0
    counters = ast.literal_eval(procs.read_log(channel).split("channel stopped: ", 1)[1].splitlines()[0])
    assert counters["tx_over_budget"] == 3000
    assert counters["tx_over_rate"] + counters["tx_queue_full"] == 3020 - 16
    assert counters["decode_errors"] == 0
