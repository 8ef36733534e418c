"""Manoeuvring source models (world/manoeuvre.py), their scenario keys, and the built-in scenarios that use them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from auv_swarm.contract.config import ConfigError, TargetConfig, builtin_scenarios, load_scenario, scenario_from_dict
from auv_swarm.world.model import TargetTrajectory


def path(cfg: TargetConfig, seed: int = 1, duration: float = 1500.0):
    t = np.arange(0.0, duration + 1e-9, 0.5)
    return t, *TargetTrajectory(cfg, np.random.default_rng(seed), duration).state(t)


@pytest.mark.parametrize(
    "cfg",
    [
        TargetConfig(model="waypoints", waypoints_m=((300.0, 0.0), (300.0, 80.0), (-300.0, 80.0)), speed_mps=1.5),
        TargetConfig(model="stop_and_go", speed_mps=1.0, go_s=100.0, stop_s=40.0, stop_turn_rad=2.0),
        TargetConfig(model="constant_turn", speed_mps=1.2, turn_rate_radps=0.03),
        TargetConfig(model="random_turn", speed_mps=1.2, turn_radius_m=30.0, manoeuvre_interval_s=60.0),
    ],
    ids=lambda c: c.model,
)
def test_paths_are_continuous_and_velocity_is_the_derivative(cfg):
    t, p, v = path(cfg)
    speed = np.hypot(v[:, 0], v[:, 1])
    assert np.all(speed <= max(cfg.speed_mps, 1.5) + 1e-9)
    step = np.hypot(*np.diff(p, axis=0).T)
    assert np.all(step <= 0.5 * speed.max() + 1e-6)  # no jump
    mid = (p[2:] - p[:-2]) / 1.0  # central difference over 2 x 0.5 s
    smooth = (speed[:-2] == speed[1:-1]) & (speed[1:-1] == speed[2:])  # away from speed switches
    assert np.allclose(mid[smooth], v[1:-1][smooth], atol=0.01)


def test_constant_turn_is_a_circle_of_radius_v_over_w():
    t, p, _ = path(TargetConfig(model="constant_turn", speed_mps=1.0, turn_rate_radps=0.02), duration=600.0)
    centre = np.array([0.0, 50.0])  # heading 0, counter-clockwise turn: centre 50 m to the left
    np.testing.assert_allclose(np.hypot(*(p - centre).T), 50.0, atol=1e-9)


def test_waypoints_are_visited_within_the_turn_radius_then_the_source_holds_its_course():
    cfg = TargetConfig(
        model="waypoints", waypoints_m=((400.0, 0.0), (400.0, 100.0)), leg_speeds_mps=(1.0, 1.5), turn_radius_m=20.0
    )
    t, p, v = path(cfg)
    for wp in cfg.waypoints_m:
        assert np.min(np.hypot(*(p - np.array(wp)).T)) <= 20.0 + 1.0
    assert math.isclose(np.hypot(*v[-1]), 1.5)
    assert math.isclose(np.hypot(*v[100]), 1.0)


def test_stop_and_go_stops_and_turns():
    cfg = TargetConfig(model="stop_and_go", speed_mps=1.0, go_s=100.0, stop_s=50.0, stop_turn_rad=math.pi / 2)
    t, p, v = path(cfg, duration=400.0)
    speed = np.hypot(*v.T)
    assert np.all(speed[(t > 101) & (t < 149)] == 0.0)
    np.testing.assert_allclose(p[t == 100.0][0], [100.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(v[t == 160.0][0], [0.0, 1.0], atol=1e-9)


def test_random_turn_is_seeded():
    cfg = TargetConfig(model="random_turn", speed_mps=1.0, manoeuvre_interval_s=50.0)
    a, b, c = (path(cfg, seed)[1] for seed in (3, 3, 4))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


@pytest.mark.parametrize(
    "target, match",
    [
        ({"model": "waypoints"}, "target.waypoints_m must hold at least one"),
        ({"model": "waypoints", "waypoints_m": [[1.0, 2.0]], "leg_speeds_mps": [1.0, 2.0]}, "target.leg_speeds_mps"),
        ({"model": "waypoints", "waypoints_m": [[1.0, 2.0]], "leg_speeds_mps": [99.0]}, r"leg_speeds_mps\[0\]"),
        ({"model": "zigzag"}, "target.model must be one of"),
        ({"turn_radius_m": 0.5}, "target.turn_radius_m must be"),
        ({"turn_rate_radps": 3.0}, "target.turn_rate_radps must be"),
    ],
)
def test_bad_manoeuvre_keys_name_the_key(target, match):
    with pytest.raises(ConfigError, match=match):
        scenario_from_dict({"target": target})


def test_manoeuvre_builtins_exist_and_load():
    names = [n for n in builtin_scenarios() if n.startswith("manoeuvre-")]
    assert {"manoeuvre-uturn", "manoeuvre-zigzag", "manoeuvre-stop-go"} <= set(names)
    for name in names:
        s = load_scenario(name)
        assert 3 <= s.agents.count <= 4 and 0.5 <= s.channel.pdr <= 0.65
        assert s.target.model in ("waypoints", "stop_and_go", "constant_turn", "random_turn")


def test_bench_manoeuvre_takes_a_user_toml(tmp_path, capsys):
    """``--scenarios`` takes TOML paths as its help says (a user's variant of a built-in, here a lossless link)."""
    import json

    from auv_swarm.bench import manoeuvre

    text = (Path(__file__).parents[2] / "contract" / "scenarios" / "manoeuvre-uturn.toml").read_text(encoding="utf-8")
    text = text.replace("duration_s = 1500.0", "duration_s = 300.0").replace("pdr = 0.55", "pdr = 1.0")
    mine = tmp_path / "lossless.toml"
    mine.write_text(text, encoding="utf-8")
    assert (
        manoeuvre.main(["--seeds", "1", "--methods", "wls-cv", "--workers", "1", "--json", "--scenarios", str(mine)])
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    row = result["scenarios"][str(mine)]["wls-cv"]
    assert row["runs"] == 1 and row["tracking_error_mean_m"] > 0.0
    assert f"{mine}  wls-cv" in manoeuvre._table(result)  # a long path keeps its column apart
