"""A stand-in AUV process for the channel integration test: lockstep modem traffic, no estimator or planner.

On ``Nav(k)`` it waits (bounded) for the ``rx_expected`` packets of tick k, prints
each as ``RX {json}``, publishes one ``ModemTx`` when ``k % period == offset``, then
replies ``Command(k, tx_count)``. Run: ``python stand_in_auv.py --router EP --id N``.
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import threading
from collections import defaultdict

from auv_swarm.bus import credentials, shell, zbus
from auv_swarm.contract import wire


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--router", required=True)
    parser.add_argument("--id", type=int, required=True)
    parser.add_argument("--period", type=int, default=2, help="send one frame every PERIOD ticks")
    parser.add_argument("--offset", type=int, default=0, help="... at ticks k with k % PERIOD == OFFSET")
    parser.add_argument("--bytes", type=int, default=8, help="payload size (bytes)")
    parser.add_argument("--rx-timeout", type=float, default=3.0, help="wall-clock wait for the expected rx (s)")
    credentials.add_password_args(parser)
    args = parser.parse_args(argv)
    me = args.id
    stop = zbus.shutdown_event()
    navs: queue.Queue[wire.Nav] = queue.Queue()
    rx_by_tick: dict[int, list[wire.ModemRx]] = defaultdict(list)
    cond = threading.Condition()

    def on_nav(_key: str, data: bytes) -> None:
        navs.put(wire.decode(data, wire.Nav))

    def on_rx(_key: str, data: bytes) -> None:
        msg = wire.decode(data, wire.ModemRx)
        with cond:
            rx_by_tick[msg.tick].append(msg)
            cond.notify_all()

    seq = 0
    with shell.connect(args, f"auv{me}") as bus:
        bus.subscribe(wire.nav(me), on_nav)
        bus.subscribe(wire.modem_rx(me), on_rx)
        bus.declare_liveliness(wire.liveliness_session(me, bus.session_id))
        print(f"stand-in auv {me} ready", flush=True)
        while not stop.is_set():
            try:
                nav = navs.get(timeout=0.1)
            except queue.Empty:
                continue
            with cond:
                cond.wait_for(lambda n=nav: len(rx_by_tick[n.tick]) >= n.rx_expected, timeout=args.rx_timeout)
                got = rx_by_tick.pop(nav.tick, [])
            if len(got) < nav.rx_expected:
                print(f"MISSING tick {nav.tick}: {len(got)} of {nav.rx_expected} after {args.rx_timeout} s", flush=True)
            for m in got:
                record = {"tick": m.tick, "sender": m.sender, "seq": m.seq, "t_sent": m.t_sent}
                record.update({"t_arrival": m.t_arrival, "snr_db": m.snr_db, "n": len(m.payload)})
                print("RX " + json.dumps(record), flush=True)
            tx_count = 0
            if nav.tick % args.period == args.offset:
                payload = bytes([me, seq % 256]) * (args.bytes // 2)
                tx = wire.ModemTx(tick=nav.tick, auv=me, seq=seq, payload=payload, t_s=nav.t_s, source=f"auv/{me}")
                bus.publish(wire.modem_tx(me), wire.encode(tx))
                seq += 1
                tx_count = 1
            cmd = wire.Command(tick=nav.tick, auv=me, u=0.0, r=0.0, tx_count=tx_count, t_s=nav.t_s, source=f"auv/{me}")
            bus.publish(wire.command(me), wire.encode(cmd))
    return 0


if __name__ == "__main__":
    sys.exit(main())
