"""The planner protocol: methods chosen by ``planner.method``, validated, and the default is today's DMPC."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from auv_swarm.agent.methods import make_planner
from auv_swarm.agent.planner import PlanProblem, base_speed, control_set, plan
from auv_swarm.agent.planner.protocol import DmpcPlanner
from auv_swarm.contract import methods
from auv_swarm.contract.config import (
    PLANNER_METHODS,
    ConfigError,
    PlannerConfig,
    Scenario,
    load_scenario,
    scenario_from_dict,
)


def test_the_builtin_names_are_the_registry_s_and_each_builds_its_class() -> None:
    assert PLANNER_METHODS == tuple(methods.BUILTIN["planner"]) == ("dmpc", "dec-mpc", "dpso", "centralised")
    assert PlannerConfig().method == "dmpc"
    for name, ref in methods.BUILTIN["planner"].items():
        if ref is not None:
            planner = make_planner(Scenario().with_keys({"planner.method": name}), 0)
            assert f"{type(planner).__module__}:{type(planner).__qualname__}" == ref


def test_default_scenario_gets_the_dmpc_planner_and_it_plans_like_plan() -> None:
    scenario = Scenario()
    planner = make_planner(scenario, 0)
    assert isinstance(planner, DmpcPlanner)
    pl = scenario.planner
    u_e = base_speed(800.0, pl.d_star_m, 0.5, pl.step_s, scenario.agents.u_max_mps)
    problem = PlanProblem(
        position=np.zeros(2),
        heading=0.3,
        xi=np.array([800.0, 100.0, 0.3, -0.2]),
        P=np.diag([400.0, 400.0, 0.01, 0.01]),
        neighbours=(),
        controls=control_set(pl, u_e, scenario.agents.u_max_mps, scenario.agents.r_max_radps),
        planner=pl,
        channel=scenario.channel,
    )
    got, want = planner.plan(problem), plan(problem)
    np.testing.assert_array_equal(got.indices, want.indices)
    assert got.cost == want.cost


def test_unknown_method_names_the_key_and_the_allowed_names() -> None:
    bad = dataclasses.replace(Scenario(), planner=dataclasses.replace(PlannerConfig(), method="pso"))
    with pytest.raises(ConfigError, match=r"planner\.method must be one of 'dmpc', 'dec-mpc', 'dpso', got 'pso'"):
        make_planner(bad, 0)


def test_scenario_files_reject_an_unknown_method() -> None:
    data = load_scenario("paper-3.2-challenging").to_dict()
    data["planner"]["method"] = "nope"
    with pytest.raises(
        ConfigError, match=r"planner\.method must be one of 'dmpc', 'dec-mpc', 'dpso', 'centralised', got 'nope'"
    ):
        scenario_from_dict(data)
