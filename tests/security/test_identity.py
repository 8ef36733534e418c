"""Identity from the key, replays, and the agent's use of the channel-stamped sender (pure, no processes)."""

from __future__ import annotations

import dataclasses

import pytest

from auv_swarm.agent.core import AgentCore
from auv_swarm.bus.identity import REASONS, Gate, check_source, origin
from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.contract.payload import AcousticPayload, encode_payload


def _cmd(auv: int = 0, tick: int = 5, source: str | None = None) -> wire.Command:
    return wire.Command(t_s=2.0 * tick, source=source or f"auv/{auv}", tick=tick, auv=auv, u=1.0, r=0.0, tx_count=0)


def _tx(auv: int = 0, tick: int = 5, seq: int = 1) -> wire.ModemTx:
    return wire.ModemTx(t_s=2.0 * tick, source=f"auv/{auv}", tick=tick, auv=auv, seq=seq, payload=b"\x01\x02")


def test_every_key_of_the_contract_has_one_origin() -> None:
    assert origin(wire.command(3)).source == "auv/3" and origin(wire.command(3)).auv == 3
    assert origin(wire.modem_rx(3)).source == "channel" and origin(wire.modem_rx(3)).message is wire.ModemRx
    assert origin(wire.nav(3)).source == "world"
    assert origin(wire.clock()).source == "world" and origin(wire.clock()).auv is None
    assert origin(wire.channel_done()).source == "channel"
    for key in ("auvswarm/auv/3/other", "elsewhere/world/clock", "auvswarm/auv/03/cmd", "auvswarm/auv/3/cmd/x"):
        assert origin(key) is None, key


@pytest.mark.parametrize(
    ("key", "msg", "reason"),
    [
        (wire.command(0), _cmd(auv=1, source="auv/0"), "forged_auv"),
        (wire.command(0), _cmd(auv=1), "forged_source"),
        (wire.command(0), _cmd(auv=0, source="world"), "forged_source"),
        (wire.telemetry(0), _cmd(auv=0), "wrong_type"),
        (wire.modem_tx(0), _tx(auv=1), "forged_source"),
        ("auvswarm/auv/0/elsewhere", _cmd(), "unknown_key"),
        (wire.command(0), _cmd(), None),
        (wire.modem_tx(2), _tx(auv=2), None),
    ],
)
def test_check_source_names_why_a_body_does_not_match_its_key(key, msg, reason) -> None:
    assert check_source(key, msg) == reason


def test_gate_drops_counts_and_logs_once_per_sender_and_reason() -> None:
    lines: list[str] = []
    gate = Gate("world", log=lines.append)
    for _ in range(5):
        assert not gate.admit(wire.command(0), _cmd(auv=1, source="auv/0"))
    assert not gate.admit(wire.command(0), _cmd(auv=2, source="auv/0"))
    assert gate.receive(wire.command(0), b"\x93junk") is None
    assert gate.counts["forged_auv"] == 6 and gate.counts["decode_error"] == 1 and gate.dropped() == 7
    assert len(lines) == 2 and "forged_auv" in lines[0] and "auv/0" in lines[0]


def test_older_ticks_and_duplicates_are_replays_a_restart_is_not() -> None:
    gate = Gate("channel", log=lambda _line: None)
    key = wire.modem_tx(0)
    assert gate.admit(key, _tx(tick=5, seq=1))
    assert gate.admit(key, _tx(tick=5, seq=2))
    assert not gate.admit(key, _tx(tick=5, seq=1))
    assert not gate.admit(key, _tx(tick=4, seq=9))
    assert gate.counts["replay"] == 2
    assert gate.admit(key, _tx(tick=6, seq=1)), "a restarted AUV counts seq from 1 again, at a newer tick"
    assert gate.admit(wire.modem_tx(1), _tx(auv=1, tick=3)), "each key has its own newest tick"
    cmd_key = wire.command(0)
    assert gate.admit(cmd_key, _cmd(tick=7)) and not gate.admit(cmd_key, dataclasses.replace(_cmd(tick=7), u=2.0))
    gate.forget()
    assert gate.admit(key, _tx(tick=0, seq=1)), "after a world restart ticks start again"


def test_two_different_messages_of_one_tick_are_a_duplicate_login_an_exact_copy_a_replay() -> None:
    seen: list[tuple[str, wire.Message]] = []
    lines: list[str] = []
    gate = Gate("world", log=lines.append, on_duplicate=lambda key, msg: seen.append((key, msg)))
    key = wire.command(1)
    real, impostor = _cmd(auv=1, tick=7), dataclasses.replace(_cmd(auv=1, tick=7), u=2.0)
    assert gate.admit(key, impostor), "whichever arrives first is taken"
    assert not gate.admit(key, real) and not gate.admit(key, real)
    assert not gate.admit(key, impostor), "an exact copy of the taken one is a replay"
    assert gate.counts["duplicate_login"] == 2 and gate.counts["replay"] == 1
    assert seen == [(key, real), (key, real)]
    assert len([line for line in lines if "duplicate_login" in line]) == 1, "one line per sender"
    nan = wire.Telemetry(
        t_s=14.0, source="auv/1", tick=7, auv=1, estimate_ok=False, estimate_reason="x", xi=(float("nan"),) * 4,
        P=(1.0,) * 16, plan=(), waypoints=(), cost=0.0, terms={}, plan_wall_ms=0.0, n_measurements=0,
        planned=False, fiedler=0.0, nav=(0.0, 0.0, 0.0),
    )  # fmt: skip
    assert gate.admit(wire.telemetry(1), nan) and not gate.admit(wire.telemetry(1), dataclasses.replace(nan))
    assert gate.counts["duplicate_login"] == 2, "a NaN field equals itself: a copy, not a second login"
    frame = wire.modem_tx(1)
    assert gate.admit(frame, _tx(auv=1, tick=7, seq=3)) and gate.admit(frame, _tx(auv=1, tick=7, seq=4))
    assert not gate.admit(frame, dataclasses.replace(_tx(auv=1, tick=7, seq=3), payload=b"\x09"))
    assert gate.counts["duplicate_login"] == 3 and seen[-1][0] == frame
    assert not gate.admit(key, dataclasses.replace(real, tick=6)), "an older tick is a replay"
    assert gate.counts["duplicate_login"] == 3


def test_a_future_tick_is_dropped_before_it_can_make_genuine_messages_look_replayed() -> None:
    gate = Gate("world", log=lambda _line: None)
    assert not gate.admit(wire.command(0), _cmd(tick=50), max_tick=10)
    assert gate.counts["future"] == 1
    assert gate.admit(wire.command(0), _cmd(tick=10), max_tick=10)


def test_a_flood_of_distinct_frames_in_one_tick_is_bounded() -> None:
    gate = Gate("channel", log=lambda _line: None)
    accepted = sum(gate.admit(wire.modem_tx(0), _tx(tick=1, seq=s)) for s in range(1000))
    assert accepted == 16 and gate.counts["over_rate"] == 1000 - 16


def test_world_and_channel_messages_are_not_replay_checked() -> None:
    gate = Gate("auv 0", log=lambda _line: None)
    nav = wire.Nav(t_s=0.0, source="world", tick=3, auv=0, x=0, y=0, theta=0, u=0, r=0, rx_expected=0)
    assert gate.admit(wire.nav(0), nav) and gate.admit(wire.nav(0), nav)
    assert not gate.admit(wire.nav(1), nav) and gate.counts["forged_auv"] == 1
    assert set(gate.counts) == set(REASONS)


def test_agent_uses_the_channel_stamped_sender_not_the_payloads() -> None:
    scenario = load_scenario("paper-3.2-challenging")
    core = AgentCore(2, scenario)
    n_headings = scenario.planner.n_headings

    def frame(claimed: int, stamped: int) -> wire.ModemRx:
        p = AcousticPayload(
            sender=claimed, t_s=10.0, x=123.0, y=456.0, theta=0.5, u_e=1.0, plan=(), round=0, bearings=()
        )
        data, _ = encode_payload(p, core.budget_bits, n_headings)
        return wire.ModemRx(
            t_s=12.0, source="channel", tick=6, auv=2, sender=stamped, seq=1, payload=data,
            t_sent=10.0, t_arrival=11.0, snr_db=30.0,
        )  # fmt: skip

    core._ingest([frame(claimed=1, stamped=0)], 12.0)
    assert 1 not in core.neighbours and 0 not in core.neighbours
    assert core.stats.payload_sender_mismatch == 1
    core._ingest([frame(claimed=0, stamped=0)], 12.0)
    assert set(core.neighbours) == {0} and core.neighbours[0].position.tolist() == [123.0, 456.0]
