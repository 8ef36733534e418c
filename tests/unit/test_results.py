"""Metrics, files and summary of auv_swarm.results on synthetic runs with known answers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from auv_swarm.contract.config import RunConfig, Scenario
from auv_swarm.results.metrics import (
    compute_metrics,
    convergence_time,
    json_safe,
    no_estimate_fraction_after,
    team_error,
    tracking_errors,
)
from auv_swarm.results.record import AgentTick, RunRecord, true_geometry_cost
from auv_swarm.results.report import write_results
from auv_swarm.results.summary import summary_table

DT = 2.0
N_TICKS = 101  # t = 0, 2, ..., 200 s
R = 500.0  # AUV range from the target (m)
OFFSETS = {0: (10.0, 0.0), 1: (0.0, 16.0), 2: (18.0, 24.0)}  # estimate - truth: errors 10, 16, 30 m
ANGLES = {0: 0.0, 1: 2 * math.pi / 3, 2: 4 * math.pi / 3}  # bearings 120 deg apart: optimal geometry
KILL_T = 100.0  # AUV 2 lost here
NO_ESTIMATE_UNTIL = 20.0  # AUV 1 has no estimate before this time
PLAN_WALL_MS = {0: [5.0, 7.0, 9.0], 1: [1.0, 3.0], 2: [100.0]}


def target_at(t: float) -> np.ndarray:
    return np.array([100.0 + 0.5 * t, -50.0 + 0.25 * t, 0.5, 0.25])


def synthetic_record() -> RunRecord:
    """Three AUVs on a circle about a moving target; constant estimate offsets; AUV 2 dies at KILL_T."""
    rec = RunRecord.new(Scenario(name="synthetic"), "inprocess", [0, 1, 2])
    for k in range(N_TICKS):
        t = k * DT
        tgt = target_at(t)
        ticks = {}
        for i, ang in ANGLES.items():
            pos = (tgt[0] + R * math.cos(ang), tgt[1] + R * math.sin(ang))
            alive = not (i == 2 and t >= KILL_T)
            has_est = alive and not (i == 1 and t < NO_ESTIMATE_UNTIL)
            est = (tgt[0] + OFFSETS[i][0], tgt[1] + OFFSETS[i][1]) if has_est else None
            ticks[i] = AgentTick(position=pos, heading=ang + math.pi, estimate=est, alive=alive)
        rec.append_tick(t, tgt, ticks)
        if t == KILL_T:
            rec.mark_killed(2, KILL_T)
    for i, walls in PLAN_WALL_MS.items():
        for j, w in enumerate(walls):
            terms = {"geometry": 0.9 + 0.1 * j, "distance": 1.0, "connectivity": 0.5, "terminal": 0.0, "penalty": 0.0}
            rec.add_plan(i, 10.0 * j + i, w, terms)
    for j, latency in enumerate([1.0, 2.0, 3.0]):
        rec.add_packet({"t_s": 5.0 + j, "kind": "delivered", "sender": 0, "recipient": 1, "latency_s": latency})
    rec.add_packet({"t_s": 4.0, "kind": "dropped", "sender": 0, "recipient": 2, "latency_s": None, "reason": "low_snr"})
    counters = {"sent": 10, "delivered": 15, "deferred": 2, "dropped_random_loss": 4, "dropped_low_snr": 1}
    rec.finish(12.5, counters)
    return rec


@pytest.fixture(scope="module")
def rec() -> RunRecord:
    return synthetic_record()


@pytest.fixture(scope="module")
def metrics(rec: RunRecord) -> dict:
    return compute_metrics(rec)


def expected_errors() -> np.ndarray:
    """Every valid (AUV, tick) error sample, built by counting."""
    times = DT * np.arange(N_TICKS)
    n1 = int(np.sum(times >= NO_ESTIMATE_UNTIL))
    n2 = int(np.sum(times < KILL_T))
    return np.array([10.0] * N_TICKS + [16.0] * n1 + [30.0] * n2)


def test_record_shapes(rec: RunRecord) -> None:
    assert rec.times.shape == (N_TICKS,)
    assert rec.target.shape == (N_TICKS, 4)
    assert rec.geometry_cost.shape == (N_TICKS,)
    for s in rec.agents.values():
        assert s.position.shape == (N_TICKS, 2) and s.estimate.shape == (N_TICKS, 2)
        assert s.heading.shape == s.alive.shape == s.estimate_ok.shape == (N_TICKS,)
    assert np.array_equal(rec.times, DT * np.arange(N_TICKS))
    assert np.isnan(rec.agents[1].estimate[0]).all() and not rec.agents[1].estimate_ok[0]
    assert rec.agents[2].alive_until_s == KILL_T
    assert not rec.agents[2].alive[-1] and not rec.agents[2].estimate_ok[-1]


def test_tracking_error_metrics(metrics: dict) -> None:
    e = expected_errors()
    assert metrics["tracking_error_mean_m"] == pytest.approx(float(np.mean(e)), rel=1e-12)
    assert metrics["tracking_error_std_m"] == pytest.approx(float(np.std(e)), rel=1e-12)
    assert metrics["tracking_error_samples"] == len(e)
    alive_samples = N_TICKS + N_TICKS + int(KILL_T / DT)
    assert metrics["no_estimate_fraction"] == pytest.approx(int(NO_ESTIMATE_UNTIL / DT) / alive_samples)
    assert metrics["agents"]["0"]["tracking_error_mean_m"] == pytest.approx(10.0)
    assert metrics["agents"]["1"]["tracking_error_mean_m"] == pytest.approx(16.0)
    assert metrics["agents"]["2"]["tracking_error_mean_m"] == pytest.approx(30.0)
    assert metrics["agents"]["0"]["tracking_error_std_m"] == pytest.approx(0.0, abs=1e-9)
    assert metrics["agents"]["1"]["no_estimate_fraction"] == pytest.approx(10 / N_TICKS)


def test_convergence_and_steady_error(rec: RunRecord, metrics: dict) -> None:
    # team mean: (10+30)/2 = 20 before 20 s, (10+16+30)/3 = 18.7 until the kill, (10+16)/2 = 13 <= 15 after it.
    team = team_error(
        {i: np.linalg.norm(s.estimate - rec.target[:, :2], axis=1) for i, s in rec.agents.items()}, N_TICKS
    )
    assert team[0] == pytest.approx(20.0) and team[20] == pytest.approx(56.0 / 3) and team[-1] == pytest.approx(13.0)
    assert metrics["convergence_time_s"] == pytest.approx(KILL_T)
    assert metrics["tracking_error_steady_mean_m"] == pytest.approx(13.0)
    assert metrics["convergence_error_m"] == 15.0 and metrics["convergence_hold_s"] == 60.0


def test_fqi_is_one_for_optimal_then_sqrt2_after_the_kill(rec: RunRecord, metrics: dict) -> None:
    # 3 AUVs 120 deg apart: cost sqrt(2/3) = optimum -> ratio 1. After the kill two AUVs 120 deg apart:
    # sigma_min^2 = (2 - 1)/2, cost sqrt(2), optimum sqrt(2/2) = 1 -> ratio sqrt(2).
    n3 = int(KILL_T / DT)
    assert rec.geometry_cost[0] == pytest.approx(math.sqrt(2 / 3), rel=1e-9)
    assert rec.geometry_cost[-1] == pytest.approx(math.sqrt(2), rel=1e-9)
    assert metrics["fqi"] == pytest.approx((n3 * 1.0 + (N_TICKS - n3) * math.sqrt(2)) / N_TICKS, rel=1e-9)
    assert metrics["fqi_degenerate_ticks"] == 0


def test_plan_and_channel_metrics(metrics: dict) -> None:
    walls = [w for ws in PLAN_WALL_MS.values() for w in ws]
    assert metrics["plan_count"] == len(walls) == 6
    assert metrics["plan_time_median_ms"] == pytest.approx(float(np.median(walls)))  # (5 + 7) / 2 = 6
    assert metrics["plan_time_median_ms"] == pytest.approx(6.0)
    assert metrics["plan_time_max_ms"] == 100.0
    assert [metrics["agents"][k]["plans"] for k in "012"] == [3, 2, 1]
    assert metrics["agents"]["0"]["plan_time_median_ms"] == 7.0
    assert metrics["agents"]["2"]["alive_until_s"] == KILL_T and metrics["agents"]["0"]["alive_until_s"] is None
    assert metrics["kills"] == [{"agent": 2, "t_s": KILL_T}]
    ch = metrics["channel"]
    assert ch["sent"] == 10 and ch["delivered"] == 15 and ch["deferred"] == 2
    assert ch["dropped"] == {"low_snr": 1, "random_loss": 4} and ch["dropped_total"] == 5
    assert ch["delivery_ratio"] == pytest.approx(15 / 20)
    assert ch["latency_mean_s"] == pytest.approx(2.0) and ch["latency_max_s"] == 3.0


def test_run_level_fields(metrics: dict) -> None:
    assert metrics["scenario"] == "synthetic" and metrics["seed"] == 1 and metrics["mode"] == "inprocess"
    assert metrics["sim_duration_s"] == pytest.approx(200.0)
    assert metrics["wall_time_s"] == 12.5 and metrics["ticks"] == N_TICKS and metrics["n_agents"] == 3


@pytest.mark.parametrize(
    ("errors", "hold", "expected"),
    [
        # above until 40 s, below after except a spike at 84 s: the first 60 s window clear of it starts at 86 s
        ({"spike": 84.0}, 60.0, 86.0),
        # no spike: converged where the error first drops
        ({}, 60.0, 40.0),
        # a hold longer than what is left after 40 s: never
        ({}, 200.0, None),
        # a gap (no estimate) breaks the window like an excursion does
        ({"gap": 90.0}, 60.0, 92.0),
    ],
)
def test_convergence_definition(errors: dict, hold: float, expected: float | None) -> None:
    t = np.arange(0.0, 202.0, 2.0)
    e = np.where(t < 40.0, 100.0, 5.0)
    if "spike" in errors:
        e[t == errors["spike"]] = 50.0
    if "gap" in errors:
        e[t == errors["gap"]] = np.nan
    assert convergence_time(t, e, 15.0, hold) == expected


def test_convergence_threshold_inclusive_and_window_must_fit() -> None:
    t = np.arange(0.0, 100.0, 1.0)
    assert convergence_time(t, np.full(100, 15.0), 15.0, 60.0) == 0.0
    assert convergence_time(t, np.where(t < 50, 20.0, 1.0), 15.0, 60.0) is None
    assert convergence_time(t, np.full(100, np.nan), 15.0, 0.0) is None
    with pytest.raises(ValueError, match="threshold_m"):
        convergence_time(t, t, 0.0)
    with pytest.raises(ValueError, match="hold_s"):
        convergence_time(t, t, 1.0, -1.0)


def test_true_geometry_cost_closed_forms() -> None:
    tgt = (3.0, -4.0)
    square = [(tgt[0] + 100.0, tgt[1]), (tgt[0], tgt[1] + 250.0)]  # 90 deg apart: sigma_min = 1
    assert true_geometry_cost(tgt, square) == pytest.approx(1.0, rel=1e-12)
    four = [(tgt[0] + 9 * math.cos(a), tgt[1] + 9 * math.sin(a)) for a in np.arange(4) * math.pi / 4]
    assert true_geometry_cost(tgt, four) == pytest.approx(math.sqrt(2 / 4), rel=1e-12)
    assert math.isinf(true_geometry_cost(tgt, [(0.0, 0.0), (6.0, -8.0)]))  # opposite sides: parallel bearings
    assert math.isinf(true_geometry_cost(tgt, [(0.0, 0.0), (-3.0, 4.0)]))  # one ray, same side
    assert math.isnan(true_geometry_cost(tgt, [(0.0, 0.0)]))
    phi = np.array([[math.sin(b), -math.cos(b)] for b in (0.1, 0.3, 2.0)])
    pos = [(tgt[0] - math.cos(b), tgt[1] - math.sin(b)) for b in (0.1, 0.3, 2.0)]
    smin = np.linalg.svd(phi, compute_uv=False)[-1]
    assert true_geometry_cost(tgt, pos) == pytest.approx(1.0 / smin, rel=1e-9)


def test_degenerate_geometry_is_counted_not_averaged() -> None:
    rec = RunRecord.new(Scenario(), "inprocess", [0, 1])
    for k, cost in enumerate([1.0, math.inf, 3.0]):
        ticks = {i: AgentTick((float(i), 0.0), 0.0, (0.0, 0.0)) for i in (0, 1)}
        rec.append_tick(float(k), (0.0, 0.0, 0.0, 0.0), ticks, geometry_cost=cost)
    m = compute_metrics(rec)
    assert m["fqi"] == pytest.approx(2.0) and m["fqi_degenerate_ticks"] == 1


def test_record_rejects_bad_input() -> None:
    rec = RunRecord.new(Scenario(), "inprocess", [0])
    tick = {0: AgentTick((0.0, 0.0), 0.0, None)}
    rec.append_tick(0.0, (0.0, 0.0, 0.0, 0.0), tick)
    with pytest.raises(ValueError, match="t_s must increase"):
        rec.append_tick(0.0, (0.0, 0.0, 0.0, 0.0), tick)
    with pytest.raises(ValueError, match="not in the record"):
        rec.append_tick(1.0, (0.0, 0.0, 0.0, 0.0), {5: tick[0]})
    with pytest.raises(ValueError, match="target must be"):
        rec.append_tick(1.0, (0.0, 0.0), tick)
    with pytest.raises(ValueError, match="agent must be one of"):
        rec.add_plan(3, 0.0, 1.0, {})
    with pytest.raises(ValueError, match="agent_ids must be distinct"):
        RunRecord.new(Scenario(), "inprocess", [0, 0])
    with pytest.raises(ValueError, match="needs t_s and kind"):
        rec.add_packet({"kind": "sent"})


def test_non_finite_estimate_is_not_valid() -> None:
    rec = RunRecord.new(Scenario(), "inprocess", [0, 1])
    rec.append_tick(0.0, (0.0, 0.0, 0.0, 0.0), {0: AgentTick((1.0, 0.0), 0.0, (math.nan, 1.0))})
    assert not rec.agents[0].estimate_ok[0] and np.isnan(rec.agents[1].position[0]).all()
    assert not rec.agents[1].alive[0]
    m = compute_metrics(rec)
    assert m["tracking_error_mean_m"] is None and m["no_estimate_fraction"] == 1.0 and m["fqi"] is None


def test_empty_record_metrics_and_files(tmp_path: Path) -> None:
    rec = RunRecord.new(Scenario(), "inprocess", [0, 1, 2])
    m = write_results(rec, tmp_path)
    assert m["ticks"] == 0 and m["convergence_time_s"] is None and m["plan_time_median_ms"] is None
    assert json.loads((tmp_path / "metrics.json").read_text()) == m
    assert (tmp_path / "events.jsonl").read_text() == ""
    assert "tracking error" in summary_table(m)


def _strict_load(text: str) -> object:
    def refuse(name: str) -> None:
        raise ValueError(f"non-finite constant {name} in JSON")

    return json.loads(text, parse_constant=refuse)


def test_write_results_files(tmp_path: Path) -> None:
    rec = synthetic_record()
    rec.add_event(50.0, "note", value=math.nan, values=np.array([1.0, math.inf]))
    out = tmp_path / "run"
    metrics = write_results(rec, out)
    names = {p.name for p in out.iterdir()}
    assert names == {
        "metrics.json",
        "events.jsonl",
        "trajectories.png",
        "tracking_error.png",
        "costs.png",
        "record.parquet",
        "truth.parquet",
        "bearings.parquet",
        "links.parquet",
    }
    assert _strict_load((out / "metrics.json").read_text()) == metrics
    lines = (out / "events.jsonl").read_text().splitlines()
    events = [_strict_load(line) for line in lines]
    assert len(events) == len(rec.events) == 6 + 4 + 1 + 1
    assert [e["t_s"] for e in events] == sorted(e["t_s"] for e in events)
    kinds = {e["kind"] for e in events}
    assert kinds == {"plan", "kill", "packet_delivered", "packet_dropped", "note"}
    note = next(e for e in events if e["kind"] == "note")
    assert note["value"] is None and note["values"] == [1.0, None]
    for name in ("trajectories.png", "tracking_error.png", "costs.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        assert len(data) > 20_000, name
        img = imread(out / name)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 300
        assert float(np.std(img[..., :3])) > 0.02, name


def test_json_safe() -> None:
    data = {"a": np.float64("nan"), "b": (np.int64(3), np.bool_(True)), 4: [math.inf, -math.inf, 1.5]}
    assert json_safe(data) == {"a": None, "b": [3, True], "4": [None, None, 1.5]}


def test_summary_table(metrics: dict) -> None:
    text = summary_table(metrics)
    assert "synthetic" in text and "seed 1" in text and "inprocess" in text
    assert f"{metrics['tracking_error_mean_m']:.1f} +/- {metrics['tracking_error_std_m']:.1f} m" in text
    assert "ddof 0" in text  # the std convention, where the std is printed
    assert "sim time           200 s; mission wall 12.5 s, run wall -" in text
    assert "100 s" in text  # convergence and AUV 2's loss
    assert "frames: 10 sent, 2 deferred; links (frame to one recipient): 15 delivered, 5 dropped" in text
    assert "(low_snr 1, random_loss 4), 75 % delivered" in text
    rows = [line for line in text.splitlines() if line.strip().split(" ")[0] in {"AUV", "0", "1", "2"}]
    assert len(rows) == 4
    assert len({len(r) for r in rows}) == 1  # right-aligned columns end at the same column
    assert "30.0 m" in rows[3] and "100 s" in rows[3]


def test_custom_convergence_threshold() -> None:
    rec = synthetic_record()
    rec.scenario = Scenario(name="loose", run=RunConfig(convergence_error_m=25.0))
    m = compute_metrics(rec)
    assert m["convergence_time_s"] == 0.0  # team mean 20 and 18.7 are within 25 m from the start
    assert m["tracking_error_steady_mean_m"] == pytest.approx(float(np.mean(expected_errors())))


def test_append_keeps_exact_lengths_and_survives_direct_assignment() -> None:
    rec = RunRecord.new(Scenario(), "inprocess", [0])
    for k in range(40):  # crosses several buffer growths
        rec.append_tick(float(k), (k, 0.0, 0.0, 0.0), {0: AgentTick((0.0, 1.0), 0.0, (k + 3.0, 4.0))})
        assert len(rec.times) == len(rec.agents[0].alive) == k + 1
    assert np.array_equal(rec.times, np.arange(40.0)) and np.allclose(tracking_errors(rec)[0], 5.0)
    rec.times = rec.times + 100.0
    rec.append_tick(140.0, (0.0, 0.0, 0.0, 0.0), {0: AgentTick((0.0, 1.0), 0.0, None)})
    assert rec.times[0] == 100.0 and rec.times[-1] == 140.0 and len(rec.times) == 41


def test_kills_are_listed_in_time_order_not_by_id() -> None:
    """metrics.json's kills: the AUV lost first comes first, whatever its id."""
    rec = RunRecord.new(Scenario(name="two-kills", run=RunConfig(duration_s=20.0)), "inprocess", [0, 1, 2])
    for k in range(11):
        t = k * DT
        ticks = {
            i: AgentTick(position=(100.0 * i, 0.0), heading=0.0, estimate=None, alive=not (i == 2 and t >= 4.0))
            for i in range(3)
        }
        rec.append_tick(t, target_at(t), ticks)
    rec.mark_killed(2, 4.0)
    rec.mark_killed(0, 18.0)
    rec.mark_killed(1, 10.0)
    rec.finish(1.0, {})
    assert compute_metrics(rec)["kills"] == [
        {"agent": 2, "t_s": 4.0},
        {"agent": 1, "t_s": 10.0},
        {"agent": 0, "t_s": 18.0},
    ]


def test_no_estimate_fraction_after_300s(metrics: dict) -> None:
    # the fixture's mission ends at 200 s: no live sample after 300 s
    assert all(a["no_estimate_fraction_after_300s"] is None for a in metrics["agents"].values())
    times = np.arange(0.0, 600.0, 1.0)
    alive = times < 500.0
    ok = ~((times >= 290.0) & (times < 310.0))
    # live samples at t >= 300: 300..499 (200), without an estimate: 300..309 (10)
    assert no_estimate_fraction_after(times, alive, ok, 300.0) == pytest.approx(10 / 200)
    assert no_estimate_fraction_after(times, alive, ok, 550.0) is None
