"""`auv-swarm run`'s arguments and a mission's two wall spans (issue 46 items 3, 4 and 6): the scenario both ways,
--agents 0 and --speed in process as one line, a kill after the end warned from Python too."""

from __future__ import annotations

import warnings

import pytest

import auv_swarm
from auv_swarm.contract.config import ConfigError, load_scenario
from auv_swarm.orchestrator.cli.run import load_checked, main, parse_args, scenario_name
from auv_swarm.orchestrator.mission.api import MissionWarning


def test_the_scenario_is_positional_or_an_option_and_two_different_ones_are_refused(capsys) -> None:
    assert scenario_name(parse_args(["paper-3.3-sim2"])) == "paper-3.3-sim2"
    assert scenario_name(parse_args(["--scenario", "paper-3.3-sim2"])) == "paper-3.3-sim2"
    assert scenario_name(parse_args(["paper-3.3-sim2", "--scenario", "paper-3.3-sim2"])) == "paper-3.3-sim2"
    assert scenario_name(parse_args([])) == "paper-3.2-challenging"
    assert main(["paper-3.3-sim1", "--scenario", "paper-3.3-sim2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "two scenarios given" in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--agents", "0"], "agents.count must be in [1, 16], got 0"),
        (["--mode", "inprocess", "--speed", "5"], "--speed applies to --mode processes"),
        (["--mode", "inprocess", "--restart", "on-failure"], "--restart applies to --mode processes"),
    ],
)
def test_a_bad_combination_is_one_line_and_nothing_before_it(argv: list[str], message: str, capsys) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "0..-1" not in err


def test_the_mission_wall_is_the_loop_inside_the_run_wall_and_a_late_kill_warns_from_python() -> None:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=20)
    with pytest.warns(MissionWarning, match=r"kills\[0\] \(AUV 1 at 750 s\) is after the mission's end at 20 s"):
        result = auv_swarm.run_mission(scenario)
    m = result.metrics
    assert 0.0 < m["wall_time_s"] <= result.wall_s <= m["run_wall_time_s"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing to warn about: no warning at all
        auv_swarm.run_mission(load_scenario("paper-3.3-sim2").with_overrides(duration_s=10))
    with pytest.raises(ConfigError, match="two scenarios"):
        load_checked(parse_args(["paper-3.3-sim1", "--scenario", "paper-3.3-sim2"]))
