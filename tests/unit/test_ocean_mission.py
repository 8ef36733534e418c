"""The physical ocean acting on the channel, the bearing sensor, the estimators, the planners, the metrics and
``auv-swarm ocean`` (docs/ocean.md)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import optimize

from auv_swarm.agent.estimator import Bearing
from auv_swarm.agent.estimator.adaptive import AdaptiveWindowEstimator
from auv_swarm.agent.estimator.window import BearingEstimator
from auv_swarm.agent.planner import brute_force, plan
from auv_swarm.agent.planner.reference import same_optimum, sequence_cost
from auv_swarm.channel_sim.model import ChannelModel
from auv_swarm.contract.config import Scenario, builtin_scenarios, load_scenario
from auv_swarm.contract.modem import MODEMS, LinkModel
from auv_swarm.contract.ocean import build_ocean
from auv_swarm.contract.propagation import TLCurve
from auv_swarm.contract.tltable import ocean_for
from auv_swarm.world.model import WorldModel
from tests.unit.planner_problems import problem_sizes, random_problem

PHYSICAL = [n for n in builtin_scenarios() if load_scenario(n).ocean.model == "physical"]


def _physical(**keys) -> Scenario:
    return Scenario().with_keys({"ocean.model": "physical", "channel.pdr": 0.8, **keys})


def test_channel_delivers_by_the_modem_curve_with_pdr_and_counts_reasons() -> None:
    """At a fixed range, the delivered fraction is the curve's delivery for the frame's length times channel.pdr,
    the modem's failures are low_snr and the rest random_loss; the delay is range / the profile's mean speed."""
    s = _physical(**{"ocean.wind_mps": 20.0, "channel.mode": "aloha"})
    ocean = ocean_for(s)
    bits = 8 * 40
    r = optimize.brentq(lambda x: ocean.link.delivery(float(ocean.link.snr_db(x)), bits) - 0.5, 1e3, 1e5)
    p = ocean.link.delivery(float(ocean.link.snr_db(r)), bits)
    assert p == pytest.approx(0.5)
    model = ChannelModel(s.channel, (0, 1), np.random.default_rng(3), 4000, ocean)
    n = 3000
    for k in range(n):
        model.transmit(100.0 * k, 0, k, bytes(40), {0: (0.0, 0.0), 1: (r, 0.0)}, {0, 1})
        model.deliver_until(100.0 * k + 50.0)
    c = model.counters
    assert c["delivered"] / n == pytest.approx(p * 0.8, abs=0.03)
    assert c["dropped_low_snr"] / n == pytest.approx(1 - p, abs=0.03)
    assert c["dropped_random_loss"] + c["dropped_low_snr"] + c["delivered"] == n
    assert model.latencies["max_s"] == pytest.approx(bits / 120.0 + r / ocean.mean_sound_speed_mps)


def test_gilbert_elliott_bursts_on_their_own_stream() -> None:
    s = _physical(
        **{"ocean.burst_p_good_bad": 0.1, "ocean.burst_p_bad_good": 0.4, "channel.pdr": 1.0, "channel.mode": "aloha"}
    )
    ocean = ocean_for(s)
    runs = []
    for burst_seed in (1, 2):
        model = ChannelModel(
            s.channel, (0, 1), np.random.default_rng(3), 4000, ocean, np.random.default_rng(burst_seed)
        )
        for k in range(2000):
            model.transmit(100.0 * k, 0, k, bytes(40), {0: (0.0, 0.0), 1: (500.0, 0.0)}, {0, 1})
            model.deliver_until(100.0 * k + 50.0)
        runs.append(model.counters["dropped_burst_loss"])
    assert all(abs(b / 2000 - 0.2) < 0.04 for b in runs) and runs[0] != runs[1]
    with pytest.raises(ValueError, match="burst_rng"):
        ChannelModel(s.channel, (0, 1), np.random.default_rng(3), 4000, ocean)


def test_world_sensor_detects_near_and_misses_far() -> None:
    s = _physical(
        **{"agents.count": 2, "agents.positions_m": [[0.0, 0.0], [-3000.0, 0.0]], "target.position_m": [200.0, 0.0]}
    )
    world = WorldModel(s, np.random.default_rng(1), ocean=ocean_for(s))
    near, far = [], []
    for _ in range(200):
        out = world.sense()
        near.append(out[0])
        far.append(out[1])
        world.advance()
    assert world.sightings[0][1] > world.sightings[1][1]  # the source's SNR falls with range
    assert sum(b is not None for b in near) == 200
    assert sum(b is not None for b in far) < 10
    errors = np.array([(b - 0.0 + math.pi) % (2 * math.pi) - math.pi for b in near])
    assert np.std(errors) == pytest.approx(world.sightings[0][0], rel=0.25)


def _bearings(truth: np.ndarray, sigmas: list[float], rng: np.random.Generator, n: int = 60) -> list[Bearing]:
    out = []
    for k in range(n):
        t = 10.0 * k
        target = truth[:2] + t * truth[2:]
        for src, (sx, sy) in enumerate(((0.0, -800.0), (600.0, 300.0), (-500.0, 400.0))):
            sigma = sigmas[src]
            b = math.atan2(target[1] - sy, target[0] - sx) + sigma * rng.standard_normal()
            out.append(Bearing(t, (sx, sy), b, src, sigma_rad=sigma))
    return out


@pytest.mark.parametrize("cls", [BearingEstimator, AdaptiveWindowEstimator])
def test_built_in_estimators_weight_each_bearing_by_its_sigma(cls) -> None:
    """One AUV's bearings are 30 times noisier than the others': weighted by sigma the error is about that of the
    two good AUVs alone, and far below the error of the same bearings taken at the common sigma."""
    truth = np.array([100.0, 50.0, 0.3, -0.2])
    cfg = Scenario().estimator
    errs = {"weighted": [], "ignored": []}
    for seed in range(6):
        data = _bearings(truth, [0.002, 0.002, 0.06], np.random.default_rng(seed))
        plain = [dataclasses.replace(b, sigma_rad=None) for b in data]
        for name, batch in (("weighted", data), ("ignored", plain)):
            est = cls(cfg, math.radians(4.5)).update(batch, 590.0)
            assert est.ok
            errs[name].append(math.hypot(*(est.xi[:2] - (truth[:2] + 590.0 * truth[2:]))))
    assert np.mean(errs["weighted"]) < 0.5 * np.mean(errs["ignored"])


def test_noise_free_bearings_with_sigma_recover_the_truth() -> None:
    truth = np.array([100.0, 50.0, 0.3, -0.2])
    data = _bearings(truth, [0.01, 0.02, 0.05], np.random.default_rng(0))
    exact = [
        dataclasses.replace(
            b,
            bearing_rad=math.atan2(
                *(np.array([truth[1], truth[0]]) + b.t_s * truth[[3, 2]] - [b.sensor_xy[1], b.sensor_xy[0]])
            ),
        )
        for b in data
    ]
    est = BearingEstimator(Scenario().estimator, math.radians(4.5)).update(exact, 590.0)
    assert est.ok and np.allclose(est.xi, [truth[0] + 590 * truth[2], truth[1] + 590 * truth[3], *truth[2:]], atol=1e-6)


def _wavy_link(noise_db: float) -> LinkModel:
    """A link whose TL is not monotone in range (a table's caustics): 50 + 15 log10 r - 8 sin(r / 90)."""
    r = np.arange(0.0, 6001.0, 10.0)
    tl = TLCurve(r, 50.0 + 15.0 * np.log10(np.maximum(r, 1.0)) - 8.0 * np.sin(r / 90.0), 10.0)
    return LinkModel(tl, MODEMS["micromodem-rate1"], 186.0, noise_db, 0.0, 1500.0)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(**problem_sizes([1, 3, 5], max_horizon=3, max_neighbours=3), noise=st.sampled_from([60.0, 80.0, 95.0]))
def test_physical_planning_fast_equals_reference_equals_brute_force(
    seed, n_headings, horizon, n_neighbours, noise
) -> None:
    rng = np.random.default_rng(seed)
    problem = random_problem(rng, n_headings=n_headings, horizon=horizon, n_neighbours=n_neighbours, gamma=0.8)
    problem = dataclasses.replace(problem, link=_wavy_link(noise))
    got = plan(problem)
    ref = brute_force(problem)
    assert same_optimum(problem, got, ref)
    cost, _ = sequence_cost(problem, got.indices[None, :])
    assert float(cost[0]) == pytest.approx(got.cost, rel=1e-9)


def test_link_weight_bound_covers_every_farther_range() -> None:
    link = _wavy_link(95.0)
    r = np.linspace(0.0, 8000.0, 4001)
    w = link.weight(r)
    for start in (0.0, 300.0, 1200.0, 5990.0, 7000.0):
        assert float(link.weight_bound(start)) >= w[r >= start].max() - 1e-12


def test_metrics_of_a_physical_and_a_paper_mission() -> None:
    from auv_swarm import run_mission

    physical = run_mission(load_scenario("ocean-storm").replace(kills=()).with_overrides(duration_s=120.0)).metrics
    paper = run_mission(
        load_scenario("paper-3.2-challenging").replace(kills=()).with_overrides(duration_s=60.0)
    ).metrics
    assert physical["links_delivered_fraction"] == physical["channel"]["delivery_ratio"]
    assert 0.0 <= physical["bearing_detection_fraction"] < 0.5 and physical["source_snr_median_db"] < -10.0
    assert paper["bearing_detection_fraction"] == 1.0 and paper["source_snr_median_db"] is None


@pytest.mark.parametrize("name", PHYSICAL)
def test_ocean_verb_writes_the_figures_and_wind_shrinks_detection(name: str, tmp_path: Path, capsys) -> None:
    from auv_swarm.orchestrator.cli.ocean import main

    ranges = {}
    for wind in (0, 20):
        assert main([name, f"ocean.wind_mps={wind}", "--out", str(tmp_path / str(wind)), "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        ranges[wind] = out["detection_range_50_m"]
        assert isinstance(out["link_range_50_m"], float) and 0 < out["link_range_50_m"] <= 100000
        for fig in ("sound_speed", "tl_field", "snr", "probability"):
            assert Path(out["figures"][fig]).stat().st_size > 1000
    assert ranges[20] < ranges[0]


def test_a_physical_scenario_runs_the_same_twice_and_builds_its_ocean_once_per_component() -> None:
    s = load_scenario("ocean-coastal-summer").replace(kills=()).with_overrides(duration_s=200.0)
    from auv_swarm import run_mission
    from auv_swarm.results.metrics import comparable

    a, b = (comparable(run_mission(s).metrics) for _ in range(2))
    assert a == b
    ocean = build_ocean(s.channel, s.sensor, s.ocean, None)
    assert ocean.link.threshold_db == MODEMS["micromodem-rate1"].snr50_db


def test_the_recording_marks_missed_detections_and_scales_link_colours_by_the_modem() -> None:
    from auv_swarm.recorder.style import PHYSICAL_SNR_SPAN_DB, missed_marker, snr_scale

    assert missed_marker((1.0, 2.0), math.nan)["positions"] == [(1.0, 2.0)]
    assert missed_marker((1.0, 2.0), 0.3)["positions"] == [] and missed_marker((1.0, 2.0), None)["positions"] == []
    assert snr_scale(load_scenario("ocean-storm")) == (MODEMS["micromodem-rate1"].snr50_db, PHYSICAL_SNR_SPAN_DB)
    assert snr_scale(Scenario()) == (10.0, 186.0 - 40.0 - 10.0)
