"""``auv-swarm bench figure6``: its definitions on analytic series, and one tiny run end to end."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from auv_swarm.bench import BENCHES
from auv_swarm.bench.figure6 import (
    LITERAL,
    SCENARIOS,
    closest_pair_m,
    formation_spread,
    formation_wiggle,
    main,
    one_run,
    parse_sets,
    settling_time,
    toml_value,
)


def test_settling_time_is_the_last_exit_from_ten_percent_of_the_final_mean() -> None:
    t = np.arange(0.0, 600.0, 1.0)
    j = np.where(t < 250.0, 3.0, 1.0)
    j[400] = 1.2  # a late excursion beyond +-10 %
    assert settling_time(t, j) == 400.0
    assert settling_time(t, np.ones_like(t)) == 0.0
    assert settling_time(t, np.full_like(t, np.nan)) is None


def test_formation_spread_is_the_mean_pair_distance_std_after_300s() -> None:
    t = np.arange(0.0, 700.0, 1.0)
    pos = np.zeros((3, t.size, 2))
    pos[1, :, 0] = 10.0 + np.where(np.arange(t.size) % 2, 1.0, -1.0)  # pair (0,1): std 1 m
    pos[2, :, 1] = 50.0  # pair (0,2) fixed; pair (1,2): distance varies a little
    pos[:, :300] += 1000.0 * np.random.default_rng(0).random((3, 300, 2))  # before 300 s: ignored
    d12 = np.hypot(pos[1, 300:, 0] - pos[2, 300:, 0], pos[1, 300:, 1] - pos[2, 300:, 1])
    assert formation_spread(t, pos) == pytest.approx((1.0 + 0.0 + float(np.std(d12))) / 3.0)
    assert formation_spread(t[:200], pos[:, :200]) is None


def test_formation_wiggle_is_the_fast_part_of_the_spread() -> None:
    t = np.arange(0.0, 1200.0, 1.0)
    pos = np.zeros((2, t.size, 2))
    pos[1, :, 0] = 30.0 + 0.05 * t  # a slow drift: large spread, no wiggle
    assert formation_spread(t, pos) > 10.0
    assert formation_wiggle(t, pos) == pytest.approx(0.0, abs=1e-9)
    pos[1, :, 0] += np.where(np.arange(t.size) % 2, 1.0, -1.0)  # +-1 m every second on top of it
    assert formation_wiggle(t, pos) == pytest.approx(1.0, abs=0.01)
    assert formation_wiggle(t[:350], pos[:, :350]) is None  # less than one 120 s window after 300 s


def test_closest_pair_is_the_smallest_distance_between_any_two_auvs() -> None:
    pos = np.zeros((3, 4, 2))
    pos[1, :, 0] = [40.0, 30.0, 12.5, 50.0]
    pos[2, :, 1] = [60.0, 60.0, 60.0, 7.0]
    assert closest_pair_m(pos) == pytest.approx(7.0)
    assert closest_pair_m(pos[:1]) is None


def test_registered_and_a_tiny_run_writes_the_figure_and_the_json(tmp_path, capsys) -> None:
    assert "figure6" in BENCHES
    assert main(["--seeds", "1", "--duration", "330", "--out", str(tmp_path / "f6"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (tmp_path / "f6" / "figure6.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "f6" / "figure6.json").read_text()) == out
    fig = out["figures"]
    assert fig["seeds"] == 1 and len(fig["per_seed"]) == 1 and out["seeds"] == "1-1"
    for key, target in fig["targets"].items():
        assert fig[key] in (0, 1) and target == 1
    # scenario 3 under the literal reading beside the built-in's departure, in the JSON
    assert out["scenarios"][-1] == LITERAL and out["literal_keys"]["planner.connectivity"] == "db"
    assert set(fig["literal"]) >= {"item3_seeds_spread_30pct_lower", "item3_seeds_settling_later"}
    seed = fig["per_seed"][0]
    assert seed["s1_max_range_after_300s_m"] > 0.0 and seed["s2_formation_spread_m"] > 0.0
    assert seed["s3lit_formation_spread_m"] > 0.0 and seed["s3lit_tracking_error_m"] > 0.0
    assert 0.0 <= seed["s1_max_no_estimate_fraction_after_300s"] <= 1.0
    pairs = [seed[f"{s}_min_pair_distance_m"] for s in ("s1", "s2", "s3", "s3lit")]
    assert fig["safety_min_pair_distance_m"] == min(pairs) > 0.0
    assert fig["safety_missions_closer_than_d_safe"] == sum(1 for d in pairs if d < 25.0)  # d_S of section 3.1
    ranges = [seed[f"{s}_min_range_after_300s_m"] for s in ("s1", "s2", "s3", "s3lit")]
    assert fig["safety_min_range_after_300s_m"] == min(ranges) > 0.0
    assert seed["s1_min_range_after_300s_m"] <= seed["s1_max_range_after_300s_m"]


def test_bad_seeds_is_one_line() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "bench", "figure6", "--seeds", "0"], capture_output=True, text=True
    )
    assert done.returncode == 2 and "--seeds must be A-B" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("arg", "message"),
    [
        ("planner.leg_constraint=bogus", "planner.leg_constraint must be one of"),
        ("planner.no_such_key=1", "planner.no_such_key"),
        ("no-equals-sign", "--set takes [s1:|s2:|s3:]KEY=VALUE"),
        ("s4:planner.gamma=0.5", "unknown scenario prefix 's4'"),
        ("s3:planner.gamma=7", "planner.gamma"),
    ],
)
def test_bad_set_is_one_line_naming_it(arg: str, message: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "auv_swarm", "bench", "figure6", "--seeds", "1", "--set", arg],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_set_applies_to_every_scenario_and_is_in_the_json(capsys) -> None:
    assert toml_value("0.5") == 0.5 and toml_value('"arc"') == "arc" and toml_value("arc") == "arc"
    assert main(["--seeds", "1", "--duration", "60", "--set", "planner.leg_constraint=arc", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["keys"] == {"planner.leg_constraint": "arc"}
    run = one_run(SCENARIOS[1], 1, 30.0, {"planner.gamma": 0.55})
    assert run["gamma"] == 0.55


def test_a_prefixed_set_is_one_scenarios_own_over_the_common_value(capsys) -> None:
    keys, only = parse_sets(["s3:planner.gamma=0.9", "planner.gamma=0.5", "s1:planner.connectivity=topology"])
    assert keys == {"planner.gamma": 0.5}
    assert only == {SCENARIOS[2]: {"planner.gamma": 0.9}, SCENARIOS[0]: {"planner.connectivity": "topology"}}
    argv = ["--seeds", "2-2", "--duration", "30", "--json"]
    argv += ["--set", "s3:planner.anchor_tau_s=300"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["keys"] == {} and out["scenario_keys"] == {SCENARIOS[2]: {"planner.anchor_tau_s": 300}}
    assert [p["seed"] for p in out["figures"]["per_seed"]] == [2]
    # the literal reading takes scenario 3's keys, then undoes the departure
    assert one_run(LITERAL, 1, 5.0, {"planner.anchor_tau_s": 300})["connectivity"] == "db"
    # the key is scenario 3's alone: in scenarios 1 and 2 it would be refused (db reading)
    assert main(["--seeds", "1", "--set", "planner.anchor_tau_s=120"]) == 2
