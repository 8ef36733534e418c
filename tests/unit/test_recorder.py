"""The rerun recorder: entities per AUV, truth positions read back from the .rrd, malformed input counted."""

from __future__ import annotations

import dataclasses
import math
import socket
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.cli import view
from auv_swarm.recorder.core import RerunRecorder
from auv_swarm.recorder.options import RecorderOptions
from auv_swarm.recorder.style import circle, covariance_ellipse, snr_colour
from tests.unit.sinks import Keep

SCENARIO = load_scenario("paper-3.2-challenging").with_overrides(duration_s=120)
N = SCENARIO.agents.count
KILLED = 1
KILL_TICK = 30


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def read_rrd(path: Path) -> dict[str, dict[int, dict[str, object]]]:
    """entity path -> sim time (ns) -> {component column: value} for every temporal row of the recording."""
    out: dict[str, dict[int, dict[str, object]]] = defaultdict(dict)
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if "sim_time" not in batch.schema.names:
            continue
        times = batch.column("sim_time").cast("int64").to_pylist()
        names = [n for n in batch.schema.names if ":" in n]
        values = {n: batch.column(n).to_pylist() for n in names}
        entity = chunk.entity_path.lstrip("/")
        for i, t in enumerate(times):
            row = out[entity].setdefault(t, {})
            for n in names:
                if values[n][i] is not None:
                    row[n] = values[n][i]
    return dict(out)


def synthetic_mission(n_ticks: int = 60) -> list[wire.Message]:
    """What the in-process runner would feed a recorder: a target, N circling AUVs, packets, a kill."""
    msgs: list[wire.Message] = [wire.WorldEvent(t_s=0.0, source="world", kind="start", auv=-1, text="scenario started")]
    rng = np.random.default_rng(7)
    alive = list(range(N))
    for k in range(n_ticks):
        t = 2.0 * k
        target = (-450.0 + 0.3 * t, 105.0 + 0.1 * t, 0.3, 0.1)
        agents = {
            a: (
                target[0] + 500.0 * math.cos(0.01 * t + 2.1 * a),
                target[1] + 500.0 * math.sin(0.01 * t + 2.1 * a),
                0.01 * t + 2.1 * a + math.pi / 2,
            )
            for a in range(N)
        }
        if k == KILL_TICK:
            alive.remove(KILLED)
            msgs.append(wire.WorldEvent(t_s=t, source="world", kind="kill", auv=KILLED, text=f"AUV {KILLED} killed"))
        sender = alive[k % len(alive)]
        for r in alive:
            if r == sender:
                continue
            if (k + r) % 3:
                msgs.append(
                    wire.PacketEvent(
                        t_s=t,
                        source="channel",
                        correlation_id=f"{sender}-{k}",
                        kind="delivered",
                        sender=sender,
                        recipient=r,
                        bits=900,
                        latency_s=0.4,
                        snr_db=30.0 + r,
                        reason=None,
                    )
                )
            else:
                msgs.append(
                    wire.PacketEvent(
                        t_s=t,
                        source="channel",
                        correlation_id=f"{sender}-{k}",
                        kind="dropped",
                        sender=sender,
                        recipient=r,
                        bits=900,
                        latency_s=None,
                        snr_db=25.0,
                        reason="random_loss",
                    )
                )
        msgs.append(wire.Truth(t_s=t, source="world", tick=k, target=target, agents=agents, alive=tuple(alive)))
        for a in alive:
            ok = k >= 3
            planned = k % 10 == 0
            xi = (target[0] + rng.normal(0, 5), target[1] + rng.normal(0, 5), 0.3, 0.1) if ok else (0.0,) * 4
            P = tuple(np.diag([25.0, 16.0, 0.01, 0.01]).ravel()) if ok else (0.0,) * 16
            waypoints = tuple((agents[a][0] + 100.0 * h, agents[a][1]) for h in range(1, 6)) if planned else ()
            msgs.append(wire.Sensor(t_s=t, source="world", tick=k, auv=a, bearing_rad=0.1 * a if a == 0 else None))
            msgs.append(
                wire.Telemetry(
                    t_s=t,
                    source=f"auv/{a}",
                    tick=k,
                    auv=a,
                    estimate_ok=ok,
                    estimate_reason="" if ok else "too few measurements",
                    xi=xi,
                    P=P,
                    plan=tuple((0.1, 2.0) for _ in range(5)) if planned else (),
                    waypoints=waypoints,
                    cost=1.5 if planned else 0.0,
                    terms={"geometry": 0.8, "distance": 0.2, "connectivity": 0.5} if planned else {},
                    plan_wall_ms=3.0 + a if planned else 0.0,
                    n_measurements=k,
                    planned=planned,
                    fiedler=2.0 if planned else 0.0,
                    nav=agents[a],
                )
            )
    t_end = 2.0 * n_ticks
    msgs.append(wire.ChannelStats(t_s=t_end, source="channel", counters={"sent": n_ticks, "delivered": 50}))
    msgs.append(wire.WorldEvent(t_s=t_end, source="world", kind="end", auv=-1, text="mission complete"))
    return msgs


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[wire.Message], RerunRecorder, dict]:
    path = tmp_path_factory.mktemp("rec") / "recording.rrd"
    msgs = synthetic_mission()
    with RerunRecorder(SCENARIO, path, RecorderOptions(flush_every=7)) as recorder:
        for m in msgs:
            recorder.on_message(m)
    return msgs, recorder, read_rrd(path)


def test_every_auv_has_its_entities(recorded) -> None:
    _msgs, recorder, data = recorded
    assert recorder.malformed == 0
    for a in range(N):
        for tail in ("truth", "heading", "trail", "estimate", "estimate/covariance", "plan", "bearing"):
            assert f"world/auv/{a}/{tail}" in data, f"world/auv/{a}/{tail} missing"
        for plot in ("tracking_error", "cost/geometry", "cost/distance", "cost/connectivity", "fiedler", "plan_ms"):
            assert f"plots/{plot}/auv{a}" in data, f"plots/{plot}/auv{a} missing"
    for entity in (
        "world/target/truth",
        "world/target/trail",
        "world/target/d_star",
        "world/packets/delivered",
        "world/packets/dropped",
        "plots/channel/sent",
        "plots/channel/delivered",
        "plots/channel/dropped_random_loss",
        "events",
    ):
        assert entity in data, f"{entity} missing"


def test_truth_positions_equal_the_worlds_for_the_same_ticks(recorded) -> None:
    msgs, _recorder, data = recorded
    truths = [m for m in msgs if isinstance(m, wire.Truth)]
    for tr in truths:
        t = _ns(tr.t_s)
        got = data["world/target/truth"][t]["Points2D:positions"]
        assert got == [list(np.float32(tr.target[:2]))]
        for a, (x, y, _theta) in tr.agents.items():
            got = data[f"world/auv/{a}/truth"][t]["Points2D:positions"]
            assert got == [[np.float32(x), np.float32(y)]], f"AUV {a} at tick {tr.tick}"
    assert len(data["world/auv/0/truth"]) == len(truths)


def test_tracking_error_is_computed_from_the_same_tick(recorded) -> None:
    msgs, _recorder, data = recorded
    truth = {m.tick: m for m in msgs if isinstance(m, wire.Truth)}
    checked = 0
    for m in msgs:
        if isinstance(m, wire.Telemetry) and m.estimate_ok:
            tr = truth[m.tick]
            expected = math.hypot(m.xi[0] - tr.target[0], m.xi[1] - tr.target[1])
            got = data[f"plots/tracking_error/auv{m.auv}"][_ns(m.t_s)]["Scalars:scalars"]
            assert got == pytest.approx([expected], rel=1e-12)
            checked += 1
    assert checked > 100
    killed = data[f"plots/tracking_error/auv{KILLED}"]
    assert max(killed) < _ns(2.0 * KILL_TICK), "no estimate is logged for a dead AUV"


def test_dead_auv_is_drawn_grey_and_events_are_logged(recorded) -> None:
    _msgs, _recorder, data = recorded
    rows = data[f"world/auv/{KILLED}/truth"]
    assert rows[_ns(0.0)]["Points2D:labels"] == [f"AUV {KILLED}"]
    assert rows[_ns(2.0 * KILL_TICK)]["Points2D:labels"] == [f"AUV {KILLED} (dead)"]
    for tail in ("plan", "bearing", "estimate/covariance"):
        assert data[f"world/auv/{KILLED}/{tail}"][_ns(2.0 * KILL_TICK)]["LineStrips2D:strips"] == []
    assert data[f"world/auv/{KILLED}/estimate"][_ns(2.0 * KILL_TICK)]["Points2D:positions"] == []
    texts = [row["TextLog:text"] for row in data["events"].values()]
    flat = [t for row in texts for t in row] if texts and isinstance(texts[0], list) else texts
    assert any("start" in t for t in flat)
    assert any(t.startswith("kill (AUV 1)") for t in flat)
    assert any("end" in t for t in flat)


def test_estimate_is_cleared_while_not_ok_and_the_measured_bearing_is_drawn(recorded) -> None:
    msgs, _recorder, data = recorded
    est = data["world/auv/0/estimate"]
    assert est[_ns(0.0)]["Points2D:positions"] == []
    assert len(est[_ns(10.0)]["Points2D:positions"]) == 1
    tr = next(m for m in msgs if isinstance(m, wire.Truth) and m.tick == 5)
    strip = data["world/auv/0/bearing"][_ns(10.0)]["LineStrips2D:strips"][0]
    start, end = np.array(strip[0]), np.array(strip[1])
    assert start == pytest.approx(np.float32(tr.agents[0][:2]))
    assert math.atan2(end[1] - start[1], end[0] - start[0]) == pytest.approx(0.0, abs=1e-5)
    plan = data["world/auv/0/plan"][_ns(0.0)]["LineStrips2D:strips"][0]
    assert len(plan) == 1 + 5, "the plan starts at the AUV and has one waypoint per horizon step"


def test_recording_holds_a_blueprint(recorded) -> None:
    msgs, recorder, _data = recorded
    reader = RrdReader(recorder.rrd_path)
    assert len(reader.recordings()) == 1
    assert len(reader.blueprints()) >= 1
    assert recorder.received == len(msgs)


def test_malformed_and_unexpected_messages_are_counted_not_fatal(tmp_path: Path) -> None:
    msgs = synthetic_mission(n_ticks=12)
    tele = next(m for m in msgs if isinstance(m, wire.Telemetry) and m.estimate_ok)
    truth = next(m for m in msgs if isinstance(m, wire.Truth))
    bad = [
        None,
        b"\x93\x01\x02",
        "telemetry",
        wire.Clock(t_s=0.0, source="world", tick=0, alive=(0,)),
        dataclasses.replace(tele, auv=N + 3),
        dataclasses.replace(tele, xi=(math.nan, 0.0, 0.0, 0.0)),
        dataclasses.replace(tele, P=(1.0,) * 15),
        dataclasses.replace(tele, waypoints=((0.0, math.inf),)),
        dataclasses.replace(tele, terms={"geometry": math.nan}),
        dataclasses.replace(truth, target=(math.inf, 0.0, 0.0, 0.0)),
        dataclasses.replace(truth, agents={N + 1: (0.0, 0.0, 0.0)}),
        wire.PacketEvent(
            t_s=1.0,
            source="channel",
            correlation_id="x",
            kind="delivered",
            sender=N + 5,
            recipient=0,
            bits=1,
            latency_s=0.1,
            snr_db=20.0,
            reason=None,
        ),
    ]
    path = tmp_path / "recording.rrd"
    with RerunRecorder(SCENARIO, path) as recorder:
        for i, m in enumerate(msgs):
            recorder.on_message(m)
            if i == len(msgs) // 2:
                for b in bad:
                    recorder.on_message(b)
    assert recorder.malformed == len(bad)
    assert recorder.received == len(msgs)
    data = read_rrd(path)
    assert len(data["world/auv/0/truth"]) == 12
    assert all(
        math.isfinite(v[0]) for row in data["plots/tracking_error/auv0"].values() for v in [row["Scalars:scalars"]]
    )
    recorder.on_message(msgs[0])
    assert recorder.malformed == len(bad) + 1, "a message after close is counted, not raised"


def test_telemetry_before_its_truth_is_buffered(tmp_path: Path) -> None:
    msgs = synthetic_mission(n_ticks=10)
    reordered: list[wire.Message] = []
    held: wire.Truth | None = None
    for m in msgs:
        if isinstance(m, wire.Truth):
            held = m
        elif held is not None and isinstance(m, (wire.Telemetry, wire.Sensor)) and m.tick == held.tick:
            reordered.append(m)
        else:
            if held is not None:
                reordered.append(held)
                held = None
            reordered.append(m)
    first_tele = next(i for i, m in enumerate(reordered) if isinstance(m, wire.Telemetry))
    first_truth = next(i for i, m in enumerate(reordered) if isinstance(m, wire.Truth))
    assert first_tele < first_truth
    path = tmp_path / "recording.rrd"
    with RerunRecorder(SCENARIO, path) as recorder:
        for m in reordered:
            recorder.on_message(m)
    assert recorder.malformed == 0
    data = read_rrd(path)
    expected = sum(1 for m in msgs if isinstance(m, wire.Telemetry) and m.auv == 0 and m.estimate_ok)
    assert len(data["plots/tracking_error/auv0"]) == expected


def _every_tracking_error_recorded(tmp_path: Path, msgs: list[wire.Message], order: list[wire.Message]) -> None:
    """Record ``order`` (a permutation of ``msgs``) and check AUV 0 has a tracking-error row per ok estimate."""
    path = tmp_path / "recording.rrd"
    with RerunRecorder(SCENARIO, path) as recorder:
        for m in order:
            recorder.on_message(m)
    assert recorder.malformed == 0
    data = read_rrd(path)
    expected = sum(1 for m in msgs if isinstance(m, wire.Telemetry) and m.auv == 0 and m.estimate_ok)
    assert len(data["plots/tracking_error/auv0"]) == expected


def test_telemetry_many_ticks_behind_the_truth_still_gets_its_truth(tmp_path: Path) -> None:
    msgs = synthetic_mission(n_ticks=40)
    late = [m for m in msgs if not isinstance(m, wire.Telemetry)] + [m for m in msgs if isinstance(m, wire.Telemetry)]
    _every_tracking_error_recorded(tmp_path, msgs, late)


def test_telemetry_many_ticks_ahead_of_the_truth_still_gets_its_truth(tmp_path: Path) -> None:
    """zenoh orders nothing across publishers: a loaded recorder saw one AUV's telemetry 19 ticks ahead."""
    msgs = synthetic_mission(n_ticks=40)
    early = [m for m in msgs if isinstance(m, wire.Telemetry)] + [m for m in msgs if not isinstance(m, wire.Telemetry)]
    _every_tracking_error_recorded(tmp_path, msgs, early)


def test_missing_viewer_at_url_does_not_block(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    msgs = synthetic_mission(n_ticks=20)
    start = time.perf_counter()
    options = RecorderOptions(url=f"rerun+http://127.0.0.1:{port}/proxy")
    recorder = RerunRecorder(SCENARIO, tmp_path / "recording.rrd", options)
    for m in msgs:
        recorder.on_message(m)
    logged = time.perf_counter() - start
    deadline = time.monotonic() + 5.0
    while recorder.live_state == "connecting" and time.monotonic() < deadline:
        time.sleep(0.01)
    start = time.perf_counter()
    recorder.close()
    closed = time.perf_counter() - start
    assert recorder.live_state == "unreachable"
    assert logged < 1.0 and closed < 1.0, f"logging took {logged:.2f} s and close {closed:.2f} s"
    assert len(read_rrd(tmp_path / "recording.rrd")["world/auv/0/truth"]) == 20


def test_rows_are_sent_by_tick_count_or_once_they_have_waited_flush_after_s(tmp_path: Path) -> None:
    truths = [m for m in synthetic_mission() if isinstance(m, wire.Truth)][:20]
    with RerunRecorder(
        SCENARIO, tmp_path / "count.rrd", RecorderOptions(flush_every=7, flush_after_s=3600.0)
    ) as recorder:
        pending = []
        for m in truths:
            recorder.on_message(m)
            pending.append(recorder._ticks_unflushed)
    assert pending == [k % 7 for k in range(1, 21)]
    with RerunRecorder(
        SCENARIO, tmp_path / "wall.rrd", RecorderOptions(flush_every=10**6, flush_after_s=0.0)
    ) as recorder:
        for m in truths:
            recorder.on_message(m)
            assert recorder._ticks_unflushed == 0
    assert len(read_rrd(tmp_path / "wall.rrd")["world/auv/0/truth"]) == 20


def test_bad_parameters_name_the_parameter() -> None:
    for bad in (0, True, 2.0):
        with pytest.raises(ValueError, match="flush_every must be an integer >= 1"):
            RecorderOptions(flush_every=bad)
    with pytest.raises(ValueError, match="viewer_port must be an integer in \\[1, 65535\\]"):
        RecorderOptions(viewer_port=0)
    with pytest.raises(ValueError, match="connect_timeout_s must be > 0 s"):
        RecorderOptions(connect_timeout_s=0.0)
    options = RecorderOptions(flush_after_s=1, live_flush_s=0)
    assert (options.flush_after_s, options.live_flush_s, options.live) == (1.0, 0.0, False)
    assert type(options.flush_after_s) is float and RecorderOptions(url="rerun+http://h:1/proxy").live
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.flush_every = 1  # type: ignore[misc]
    with pytest.raises(ValueError, match="flush_after_s"):
        RecorderOptions(flush_after_s=-1.0)
    with pytest.raises(ValueError, match="live_flush_s"):
        RecorderOptions(live_flush_s=-1.0)
    with pytest.raises(ValueError, match="rerun url"):
        RecorderOptions(url="http://localhost:9876")
    with pytest.raises(ValueError, match="confidence"):
        covariance_ellipse((0.0, 0.0), np.eye(2), confidence=1.0)
    with pytest.raises(ValueError, match="radius_m"):
        circle((0.0, 0.0), -1.0)


def test_covariance_ellipse_lies_on_the_confidence_contour() -> None:
    cov = np.array([[40.0, 12.0], [12.0, 9.0]])
    pts = covariance_ellipse((100.0, -50.0), cov, confidence=0.95, n_points=64)
    d = pts - np.array([100.0, -50.0])
    mahalanobis_sq = np.einsum("ij,jk,ik->i", d, np.linalg.inv(cov), d)
    assert mahalanobis_sq == pytest.approx(np.full(65, -2.0 * math.log(0.05)), rel=1e-9)
    assert pts[0] == pytest.approx(pts[-1])


def test_covariance_ellipse_of_a_degenerate_covariance_is_finite() -> None:
    for cov in (np.zeros((2, 2)), np.array([[4.0, 2.0], [2.0, 1.0]]), np.array([[1.0, 0.0], [0.0, -1e-12]])):
        pts = covariance_ellipse((3.0, 4.0), cov)
        assert np.all(np.isfinite(pts))
    assert covariance_ellipse((3.0, 4.0), np.zeros((2, 2))) == pytest.approx(np.tile([3.0, 4.0], (49, 1)))


def test_snr_colour_goes_from_red_at_threshold_to_green() -> None:
    assert snr_colour(10.0, 10.0, 40.0)[:2] == (255, 0)
    assert snr_colour(30.0, 10.0, 40.0)[:2] == (255, 255)
    assert snr_colour(50.0, 10.0, 40.0)[:2] == (0, 255)
    assert snr_colour(-5.0, 10.0, 40.0) == snr_colour(10.0, 10.0, 40.0)
    assert snr_colour(None, 10.0, 40.0) == snr_colour(math.nan, 10.0, 40.0)
    with pytest.raises(ValueError, match="span_db"):
        snr_colour(20.0, 10.0, 0.0)


def test_view_names_the_missing_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert view.main([str(tmp_path)]) == 2
    assert str(tmp_path / "recording.rrd") in capsys.readouterr().err


def test_inprocess_mission_recording_matches_the_world(tmp_path: Path) -> None:
    from auv_swarm.orchestrator.mission.inprocess import run_inprocess

    scenario = SCENARIO.with_overrides(duration_s=200.0)
    path = tmp_path / "recording.rrd"
    keep = Keep()
    with RerunRecorder(scenario, path) as recorder:
        run_inprocess(scenario, [recorder, keep])
    assert recorder.malformed == 0
    assert recorder.received == len(keep.messages)
    data = read_rrd(path)
    truths = [m for m in keep.messages if isinstance(m, wire.Truth)]
    assert len(truths) == int(scenario.run.duration_s / scenario.run.tick_s) + 1
    for a in range(N):
        for tail in ("truth", "trail", "estimate", "estimate/covariance", "plan", "bearing"):
            assert f"world/auv/{a}/{tail}" in data, f"world/auv/{a}/{tail} missing"
        for plot in ("tracking_error", "cost/geometry", "cost/distance", "cost/connectivity", "fiedler", "plan_ms"):
            assert f"plots/{plot}/auv{a}" in data, f"plots/{plot}/auv{a} missing"
    assert "world/packets/delivered" in data and "plots/channel/sent" in data and "plots/channel_other/ticks" in data
    for tr in truths:
        t = _ns(tr.t_s)
        assert data["world/target/truth"][t]["Points2D:positions"] == [list(np.float32(tr.target[:2]))]
        for a, (x, y, _theta) in tr.agents.items():
            assert data[f"world/auv/{a}/truth"][t]["Points2D:positions"] == [[np.float32(x), np.float32(y)]]
    truth_at = {m.tick: m for m in truths}
    for m in keep.messages:
        if isinstance(m, wire.Telemetry) and m.estimate_ok:
            tr = truth_at[m.tick]
            got = data[f"plots/tracking_error/auv{m.auv}"][_ns(m.t_s)]["Scalars:scalars"][0]
            assert got == pytest.approx(math.hypot(m.xi[0] - tr.target[0], m.xi[1] - tr.target[1]), rel=1e-12)


def _counts_by_truth_tick(msgs: list[wire.Message]) -> dict[str, dict[int, int]]:
    """Brute force: each channel counter's value at every Truth, counted as the recorder counts them (packet
    events in arrival order, reset to the channel's own counters whenever ChannelStats arrive)."""
    counts: dict[str, int] = {}
    out: dict[str, dict[int, int]] = defaultdict(dict)
    for m in msgs:
        if isinstance(m, wire.PacketEvent):
            name = f"dropped_{m.reason}" if m.kind == "dropped" else m.kind
            counts[name] = counts.get(name, 0) + 1
        elif isinstance(m, wire.ChannelStats):
            counts.update({str(k): int(v) for k, v in m.counters.items()})
        elif isinstance(m, wire.Truth):
            for name, value in counts.items():
                out[name][_ns(m.t_s)] = value
    return out


def test_channel_counters_are_logged_on_change_and_read_back_as_the_same_steps(recorded) -> None:
    msgs, _recorder, data = recorded
    expected = _counts_by_truth_tick(msgs)
    n_ticks = sum(isinstance(m, wire.Truth) for m in msgs)
    for name in ("delivered", "dropped_random_loss"):
        rows = data[f"plots/channel/{name}"]
        points = sorted((t, row["Scalars:scalars"][0]) for t, row in rows.items())
        for t, value in expected[name].items():
            step = [v for tp, v in points if tp <= t]
            assert step and step[-1] == value, f"{name} at {t / 1e9} s: {step[-1:]} != {value}"
        assert points[-1][0] >= max(expected[name])  # the plot reaches the last tick
        ticks = sorted(expected[name])
        for (t1, v1), (t2, v2) in zip(points, points[1:], strict=False):
            if v1 != v2 and t2 in ticks and ticks.index(t2) > 0:  # a step: its old value at the tick before
                assert t1 == ticks[ticks.index(t2) - 1], f"{name}: a line from {t1 / 1e9} s to {t2 / 1e9} s"
    assert len(data["plots/channel/dropped_random_loss"]) < n_ticks  # not a row per tick
    stats = [m for m in msgs if isinstance(m, wire.ChannelStats)][-1]  # the channel's own count, at the end
    sent = data["plots/channel/sent"]
    assert sent[max(sent)]["Scalars:scalars"][0] == stats.counters["sent"] and max(sent) == _ns(stats.t_s)


def test_the_live_viewer_gets_rows_every_live_flush_s_the_file_at_its_own_pace(tmp_path: Path) -> None:
    from auv_swarm.orchestrator.mission import procs
    from auv_swarm.recorder import web

    truths = [m for m in synthetic_mission() if isinstance(m, wire.Truth)][:20]
    web_port, grpc_port = procs.free_port(), procs.free_port()
    server = web.start(web_port, grpc_port, tmp_path / "web.log")
    try:
        sent = {}
        for live_flush_s in (3600.0, 0.0):
            path = tmp_path / f"live-{live_flush_s:g}.rrd"
            url = web.proxy_url("127.0.0.1", grpc_port)
            options = RecorderOptions(url=url, flush_after_s=0.0, live_flush_s=live_flush_s)
            recorder = RerunRecorder(SCENARIO, path, options)
            deadline = time.monotonic() + 20.0
            while recorder.live_state == "connecting" and time.monotonic() < deadline:
                time.sleep(0.05)
            assert recorder.live_state == "connected"
            for m in truths:
                recorder.on_message(m)
            during = dict(recorder.chunks_sent)
            recorder.close()
            sent[live_flush_s] = (during, dict(recorder.chunks_sent))
        (during, after) = sent[3600.0]
        assert during["live"] == 0 and during["file"] > 0  # the file every tick, the live viewer not yet
        assert 0 < after["live"] < after["file"]  # everything once, at the end
        (during, after) = sent[0.0]
        assert during["live"] == during["file"] and after["live"] == after["file"]
    finally:
        web.stop(server)
