"""The one registry of method names (contract/methods.py) and the factories by reference (agent/plugins.py): built-ins,
registrations (a top-level factory by reference, a lambda or closure here only), names handed down to a child,
installed plug-ins read without being imported, and a plug-in that raises or returns a bad plan is a failed mission."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from auv_swarm.agent import methods as planners
from auv_swarm.agent import plugins
from auv_swarm.agent.planner.protocol import DmpcPlanner
from auv_swarm.contract import methods
from auv_swarm.contract.config import ConfigError, Scenario, describe, load_scenario
from auv_swarm.contract.methods import MethodError
from auv_swarm.orchestrator.mission.api import check_runnable, run_mission


class Stay(DmpcPlanner):
    """The DMPC under another name: a top-level class, so it has a reference."""


class Raises(DmpcPlanner):
    def plan(self, problem):
        raise ZeroDivisionError("no plan\ntoday")


class OffGrid(DmpcPlanner):
    def plan(self, problem):
        good = super().plan(problem)
        return type(good)(**{**good.__dict__, "indices": good.indices + problem.controls.size})


@pytest.fixture
def registry():
    """Forget every planner a test registers."""
    before = set(methods.names("planner"))
    yield
    for name in set(methods.names("planner")) - before:
        plugins.forget("planner", name)


def _short(method: str, seconds: float = 60.0) -> Scenario:
    """A short mission of ``method`` (without the built-in kill at 750 s, which a short mission never reaches)."""
    scenario = load_scenario("paper-3.2-challenging").with_keys({"planner.method": method, "run.duration_s": seconds})
    return dataclasses.replace(scenario, kills=())


def test_a_top_level_factory_is_registered_by_reference_and_again_is_no_change(registry) -> None:
    planners.register("stay", Stay)
    m = methods.lookup("planner", "stay")
    assert (m.origin, m.ref) == ("registered", "tests.unit.test_methods:Stay")
    planners.register("stay", Stay)  # the same reference: no change
    with pytest.raises(ValueError, match="registered already"):
        planners.register("stay", Raises)
    for taken in ("dmpc", "centralised", ""):
        with pytest.raises(ValueError):
            planners.register(taken, Stay)
    assert methods.child_env() == {methods.METHODS_ENV: json.dumps({"planner": {"stay": m.ref}})}
    assert methods.names("planner")[:5] == ("dmpc", "dec-mpc", "dpso", "centralised", "stay")
    assert "'stay'" not in {k: r for k, r, _ in describe()}["planner.method"]  # the reference names built-ins only


def test_a_lambda_or_a_closure_runs_here_only_and_is_refused_with_one_line_elsewhere(registry) -> None:
    planners.register("here", lambda scenario, auv: DmpcPlanner(scenario, auv))
    assert methods.lookup("planner", "here").ref is None and methods.child_env() == {}
    check_runnable(_short("here"), "inprocess")
    with pytest.raises(ConfigError, match=r"planner method 'here' is a lambda \(.*\), which another process cannot"):
        check_runnable(_short("here"), "processes")

    def closure():
        class Local(DmpcPlanner):
            pass

        return Local

    assert plugins.reference(closure())[0] is None and "a closure" in plugins.reference(closure())[1]


def test_a_script_is_loaded_by_path_without_its_main_block(tmp_path: Path) -> None:
    script = tmp_path / "mine.py"
    script.write_text(
        "from auv_swarm.agent.planner.protocol import DmpcPlanner\n"
        "class Mine(DmpcPlanner):\n    pass\n"
        "if __name__ == '__main__':\n    raise SystemExit('the main block ran')\n",
        encoding="utf-8",
    )
    mine = plugins.load(f"{script}:Mine")
    assert mine.__qualname__ == "Mine" and plugins.reference(mine) == (f"{script.resolve()}:Mine", f"Mine of {script}")
    assert plugins.load(f"{script}:Mine") is mine  # loaded once
    with pytest.raises(AttributeError):
        plugins.load(f"{script}:Yours")


def test_names_handed_down_in_the_environment_are_known_and_built(monkeypatch) -> None:
    monkeypatch.setenv(methods.METHODS_ENV, json.dumps({"planner": {"stay": "tests.unit.test_methods:Stay"}}))
    assert methods.lookup("planner", "stay").origin == "registered" and "stay" in methods.names("planner")
    planner = planners.make_planner(_short("stay"), 1)
    assert isinstance(planner, plugins.GuardedPlanner) and isinstance(planner.planner, Stay)
    monkeypatch.delenv(methods.METHODS_ENV)
    plugins.forget("planner", "stay")
    with pytest.raises(ConfigError, match=r"planner\.method must be one of 'dmpc', 'dec-mpc', 'dpso', .*got 'stay'"):
        _short("stay")


def test_an_installed_plugin_is_read_from_its_entry_point_without_being_imported(tmp_path: Path, monkeypatch) -> None:
    info = tmp_path / "my_planners-2.5.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-planners\nVersion: 2.5\n", encoding="utf-8")
    (info / "entry_points.txt").write_text(
        "[auv_swarm.planners]\nsteady = my_planners:Steady\ndmpc = my_planners:Steady\n", encoding="utf-8"
    )
    (tmp_path / "my_planners.py").write_text(
        "from auv_swarm.agent.planner.protocol import DmpcPlanner\nclass Steady(DmpcPlanner):\n    pass\n",
        encoding="utf-8",
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    methods.entry_points.cache_clear()
    try:
        m = methods.lookup("planner", "steady")
        assert (m.origin, m.ref, m.distribution, m.version) == (
            "entry point",
            "my_planners:Steady",
            "my-planners",
            "2.5",
        )
        assert methods.lookup("planner", "dmpc").origin == "built-in"  # a built-in's name stays the built-in's
        assert "my_planners" not in sys.modules
        result = run_mission(_short("steady", 30.0))
        assert result.metrics["complete"] and result.metrics["plugins"] == [m.record()]
        assert result.metrics["plugins"][0]["version"] == "2.5"
    finally:
        methods.entry_points.cache_clear()
        plugins.forget("planner", "steady")
        sys.modules.pop("my_planners", None)


def test_a_plugin_that_raises_is_a_failed_mission_with_its_message(registry) -> None:
    planners.register("raises", Raises)
    result = run_mission(_short("raises", 120.0))
    m = result.metrics
    assert (m["complete"], m["incomplete_reason"], m["exit_code"], result.exit_code) == (False, "method_error", 1, 1)
    assert m["error"] == "AUV 0: planner 'raises' raised ZeroDivisionError: no plan today"
    assert m["plugins"] == [methods.lookup("planner", "raises").record()] and 0 < m["ticks"] < 61
    assert run_mission(_short("dmpc", 30.0)).metrics["error"] is None


def test_a_plan_the_agent_cannot_send_is_a_method_error(registry) -> None:
    planners.register("off-grid", OffGrid)
    m = run_mission(_short("off-grid", 120.0)).metrics
    assert m["incomplete_reason"] == "method_error"
    assert m["error"].startswith("AUV 0: planner 'off-grid' returned an unusable plan: indices must be in [0, ")


def test_a_factory_that_raises_when_built_names_the_auv() -> None:
    def broken(scenario, auv):
        raise KeyError("horizon")

    plugins.register("planner", "broken", broken)
    try:
        with pytest.raises(MethodError, match=r"^AUV 2: planner 'broken' raised KeyError: 'horizon' when built$"):
            planners.make_planner(_short("broken"), 2)
    finally:
        plugins.forget("planner", "broken")


def test_a_reference_that_does_not_load_is_one_line(monkeypatch) -> None:
    monkeypatch.setenv(methods.METHODS_ENV, json.dumps({"estimator": {"gone": "no_such_module:Est"}}))
    scenario = load_scenario("paper-3.2-challenging").with_keys({"estimator.method": "gone"})
    with pytest.raises(ConfigError, match=r"^estimator 'gone': cannot load no_such_module:Est \(ModuleNotFoundError"):
        check_runnable(scenario)


def test_the_method_error_line_of_an_agent_log() -> None:
    log = "auv 1 ready\nerror: method_error: AUV 1: planner 'x' raised E: a\nauv 1: stopping\n"
    assert methods.method_error_line(log) == "AUV 1: planner 'x' raised E: a"
    assert methods.method_error_line("error: router unreachable\n") is None


def test_a_sweep_refuses_a_method_no_worker_can_import(registry) -> None:
    from auv_swarm.orchestrator.sweep.engine import EngineError, check_workers
    from auv_swarm.orchestrator.sweep.grid import Axis, Grid

    planners.register("here", lambda scenario, auv: DmpcPlanner(scenario, auv))
    grid = Grid(["paper-3.2-challenging"], [Axis("planner.method", ("dmpc", "here"))], [1], 30.0)
    with pytest.raises(EngineError, match="planner method 'here' is a lambda"):
        check_workers(None, grid.missions(grid.check()), {})  # refused before any worker is asked
    check_workers(None, grid.missions(grid.check())[:1], {})  # built-ins only: nothing to ask


def test_guarded_planner_forwards_attributes_and_checks_shapes() -> None:
    planner = plugins.GuardedPlanner(Stay(Scenario(), 0), "planner 'stay'")
    assert planner.shares_plans is True
    bad = type("P", (), {"controls": np.zeros((2, 2)), "indices": np.zeros(2, int), "waypoints": 0, "terms": {}})()
    problem = type("Q", (), {"planner": Scenario().planner, "controls": type("C", (), {"size": 3})()})()
    assert plugins.plan_problem(bad, problem).startswith("controls must be finite, of shape (5, 2)")
