"""Dead reckoning (world/navigation.py, docs/navigation.md): error growth with distance, fixes, the compass bias,
what the world sends the AUVs, the navigation metrics, and bad navigation keys."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from auv_swarm.contract import wire
from auv_swarm.contract.config import (
    AgentsConfig,
    ConfigError,
    NavigationConfig,
    RunConfig,
    Scenario,
    SensorConfig,
    TargetConfig,
    load_scenario,
)
from auv_swarm.results.metrics import compute_metrics
from auv_swarm.results.record import AgentTick, RunRecord
from auv_swarm.world.navigation import DeadReckoning
from auv_swarm.world.service import WorldService

SEEDS = range(1, 201)
DRIFT = 0.02
FIX_SIGMA_M = 5.0


def straight_run(nav: DeadReckoning, distance_m: float, heading_rad: float, steps: int = 50) -> None:
    """Move AUV 0 straight over ``distance_m`` in ``steps`` equal ticks."""
    step = distance_m / steps * np.array([[math.cos(heading_rad), math.sin(heading_rad)]])
    for _ in range(steps):
        nav.move([0], step)


def radial_rms(errors: list[np.ndarray]) -> float:
    return math.sqrt(float(np.mean([e @ e for e in errors])))


def test_radial_rms_after_a_straight_leg_is_drift_fraction_times_distance_and_grows_linearly() -> None:
    cfg = NavigationConfig(drift_fraction=DRIFT)
    at_500, at_2000 = [], []
    for seed in SEEDS:
        nav = DeadReckoning(cfg, (0,), np.random.default_rng(seed))
        heading = 0.37 * seed  # any direction: the body-frame error does not depend on it
        straight_run(nav, 500.0, heading)
        at_500.append(nav.error[0].copy())
        straight_run(nav, 1500.0, heading)
        at_2000.append(nav.error[0].copy())
    assert radial_rms(at_500) == pytest.approx(DRIFT * 500.0, rel=0.10)
    assert radial_rms(at_2000) == pytest.approx(DRIFT * 2000.0, rel=0.10)
    # one bias per leg: the error is proportional to the distance along a straight leg, seed by seed
    np.testing.assert_allclose(np.array(at_2000), 4.0 * np.array(at_500), rtol=1e-9, atol=1e-9)


def test_a_fix_brings_the_radial_rms_error_to_the_fix_sigma_and_the_drift_starts_again() -> None:
    cfg = NavigationConfig(drift_fraction=DRIFT, fix_period_s=600.0, fix_sigma_m=FIX_SIGMA_M)
    before, after, later = [], [], []
    for seed in SEEDS:
        nav = DeadReckoning(cfg, (0,), np.random.default_rng(seed))
        straight_run(nav, 2000.0, 1.0)
        before.append(nav.error[0].copy())
        assert not nav.fix_due(599.0) and nav.fix_due(600.0)
        nav.fix()
        assert not nav.fix_due(1199.0) and nav.fix_due(1200.0)
        after.append(nav.error[0].copy())
        straight_run(nav, 1000.0, 1.0)
        later.append(nav.error[0].copy())
    assert radial_rms(before) == pytest.approx(DRIFT * 2000.0, rel=0.10)
    assert radial_rms(after) == pytest.approx(FIX_SIGMA_M, rel=0.10)
    assert radial_rms(later) == pytest.approx(math.hypot(FIX_SIGMA_M, DRIFT * 1000.0), rel=0.10)


def test_a_compass_bias_turns_the_dead_reckoned_track_and_the_bearings() -> None:
    bias = math.radians(3.0)
    nav = DeadReckoning(NavigationConfig(heading_bias_deg=3.0), (0, 1), np.random.default_rng(1))
    straight_run(nav, 1000.0, 0.0)
    # believed displacement = exp(i b) * true displacement: the error is (exp(i b) - 1) * 1000 m along +x
    np.testing.assert_allclose(nav.error[0], [1000.0 * (math.cos(bias) - 1.0), 1000.0 * math.sin(bias)], atol=1e-9)
    np.testing.assert_array_equal(nav.error[1], [0.0, 0.0])
    pose = nav.believed(0, (10.0, 20.0, math.pi - 0.01))
    assert pose[2] == pytest.approx(-math.pi - 0.01 + bias)
    assert nav.bearing(0.5) == pytest.approx(0.5 + bias)


def one_auv(**nav: float) -> Scenario:
    """One AUV at the origin heading +x, a static source 3 km north-east, 1200 s."""
    return Scenario(
        run=RunConfig(duration_s=1200.0, seed=5),
        target=TargetConfig(model="static", position_m=(3000.0, 3000.0)),
        agents=AgentsConfig(count=1, positions_m=((0.0, 0.0),)),
        sensor=SensorConfig(sigma_m_deg=4.5),
        navigation=NavigationConfig(**nav),
    )


def drive(service: WorldService, ticks: int, u: float = 2.0) -> list[tuple[wire.Nav, wire.Sensor, wire.Truth]]:
    """Run ``ticks`` ticks with AUV 0 going straight at ``u``; the Nav, Sensor and Truth of every tick."""
    out = []
    for _ in range(ticks):
        truth = service.truth()
        inputs = service.agent_inputs(None)[0]
        out.append((inputs.nav, inputs.sensor, truth))
        cmd = wire.Command(t_s=truth.t_s, source="auv/0", tick=truth.tick, auv=0, u=u, r=0.0, tx_count=0)
        service.apply({0: cmd})
    return out


def test_perfect_navigation_is_the_default_draws_nothing_and_sends_the_truth() -> None:
    assert Scenario().navigation.perfect and load_scenario("paper-3.3-sim2").navigation.perfect
    assert NavigationConfig(fix_period_s=600.0).perfect  # exact fixes keep a perfect navigation perfect
    assert not NavigationConfig(fix_period_s=600.0, fix_sigma_m=1.0).perfect
    service = WorldService(one_auv())
    assert service.model.navigation is None
    for nav, _sensor, truth in drive(service, 20):
        assert (nav.x, nav.y, nav.theta) == truth.agents[0]


def test_the_world_sends_the_believed_pose_and_turned_bearings_and_leaves_the_truth_alone() -> None:
    plain = drive(WorldService(one_auv()), 400)
    biased = WorldService(one_auv(drift_fraction=DRIFT, heading_bias_deg=2.0, fix_period_s=600.0, fix_sigma_m=5.0))
    model = biased.model
    rows = drive(biased, 400)
    for (_nav0, sensor0, truth0), (nav, sensor, truth) in zip(plain, rows, strict=True):
        assert truth == truth0  # the true motion, the source and the sensor's stream do not move
        if sensor0.bearing_rad is not None:
            assert sensor.bearing_rad == pytest.approx(sensor0.bearing_rad + math.radians(2.0))
        assert nav.theta == pytest.approx(truth.agents[0][2] + math.radians(2.0))
    err = np.array([complex(nav.x - tr.agents[0][0], nav.y - tr.agents[0][1]) for nav, _s, tr in rows])
    pos = np.array([complex(*tr.agents[0][:2]) for _n, _s, tr in rows])
    assert err[0] == 0.0 and abs(err[299]) > 0.0  # the AUV starts where it believes it is; then the error grows
    # before the fix at 600 s (tick 300): one gain g0 on the straight leg, error = (g0 - 1)(p - p0)
    np.testing.assert_allclose(err[1:300] / (pos[1:300] - pos[0]), err[299] / (pos[299] - pos[0]), rtol=1e-9)
    assert model.navigation is not None and model.navigation.fixes == 1  # one fix in 800 s
    # from the fix on: a fresh error, then the fresh gain g1 on the displacement since the fix
    g1 = model.navigation.gain(0)
    np.testing.assert_allclose(err[300:] - err[300], (g1 - 1.0) * (pos[300:] - pos[300]), atol=1e-9)
    assert abs((err[299] - err[300]) - (g1 - 1.0) * (pos[299] - pos[300])) > 1e-3  # the fix moved the error


def test_navigation_metrics_are_believed_against_true_position_over_live_samples() -> None:
    rec = RunRecord.new(Scenario(), "inprocess", (0, 1))
    for k in range(4):
        ticks = {
            0: AgentTick((0.0, 0.0), 0.0, None, believed=(3.0 * k, 4.0 * k)),
            1: AgentTick((1.0, 1.0), 0.0, None, believed=None if k == 3 else (1.0, 1.0)),
        }
        rec.append_tick(2.0 * k, (0.0, 0.0, 0.0, 0.0), ticks)
    m = compute_metrics(rec)
    assert m["nav_error_max_m"] == pytest.approx(15.0)
    assert m["nav_error_mean_m"] == pytest.approx((0.0 + 5.0 + 10.0 + 15.0 + 0.0 * 3) / 7)
    empty = RunRecord.new(Scenario(), "inprocess", (0,))
    empty.append_tick(0.0, (0.0, 0.0, 0.0, 0.0), {0: AgentTick((0.0, 0.0), 0.0, None)})
    assert compute_metrics(empty)["nav_error_mean_m"] == 0.0  # perfect navigation: 0.0, not null
    drifting = RunRecord.new(Scenario(navigation=NavigationConfig(drift_fraction=0.01)), "inprocess", (0,))
    drifting.append_tick(0.0, (0.0, 0.0, 0.0, 0.0), {0: AgentTick((0.0, 0.0), 0.0, None)})
    assert compute_metrics(drifting)["nav_error_mean_m"] is None  # no believed position heard: undefined


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ({"navigation.drift_fraction": -0.01}, "navigation.drift_fraction must be in [0, 1], got -0.01"),
        ({"navigation.fix_sigma_m": 5.0}, "navigation.fix_sigma_m = 5 m needs navigation.fix_period_s > 0"),
        ({"navigation.heading_bias_deg": 100.0}, "navigation.heading_bias_deg must be in [-90, 90]"),
        ({"navigation.fix_period_s": -1.0}, "navigation.fix_period_s must be in [0, 1e+07]"),
    ],
)
def test_bad_navigation_keys_name_the_key_and_the_range(keys: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]").replace("+", r"\+")):
        load_scenario("paper-3.3-sim2").with_keys(keys)


def test_the_recording_shows_the_believed_position_beside_the_truth_under_imperfect_navigation(tmp_path) -> None:
    from auv_swarm.recorder.core import RerunRecorder
    from tests.unit.test_recorder import SCENARIO, read_rrd, synthetic_mission

    offset = (30.0, -40.0)
    msgs = [
        dataclasses.replace(m, nav=(m.nav[0] + offset[0], m.nav[1] + offset[1], m.nav[2]))
        if isinstance(m, wire.Telemetry)
        else m
        for m in synthetic_mission(20)
    ]
    drifting = SCENARIO.with_keys({"navigation.drift_fraction": 0.01})
    data = {}
    for name, scenario in (("perfect", SCENARIO), ("drifting", drifting)):
        with RerunRecorder(scenario, tmp_path / f"{name}.rrd") as recorder:
            for m in msgs:
                recorder.on_message(m)
        assert recorder.malformed == 0
        data[name] = read_rrd(tmp_path / f"{name}.rrd")
    assert not any("believed" in e or "nav_error" in e for e in data["perfect"])
    rec = data["drifting"]
    for m in msgs:
        if isinstance(m, wire.Telemetry):
            t = int(round(m.t_s * 1e9))
            believed = rec[f"world/auv/{m.auv}/believed"][t]["Points2D:positions"][0]
            assert believed == pytest.approx([m.nav[0], m.nav[1]], abs=1e-3)
            assert rec[f"plots/nav_error/auv{m.auv}"][t]["Scalars:scalars"][0] == pytest.approx(50.0)
            if m.waypoints:  # the plan starts where the AUV believes it is
                assert rec[f"world/auv/{m.auv}/plan"][t]["LineStrips2D:strips"][0][0] == pytest.approx(believed)
