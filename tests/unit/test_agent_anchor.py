"""The ``"topology"`` reading's reference pair distance (eq. 37, docs/planner.md): kept for good with
``planner.anchor_tau_s = 0``, followed as a moving average ``a + min(1, dt / tau) (d - a)`` with tau > 0."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auv_swarm.agent.core import AgentCore, NeighbourTrack, follow_anchor
from auv_swarm.agent.estimator import Estimate
from auv_swarm.contract.config import ConfigError, Scenario, load_scenario


def test_follow_anchor_analytic() -> None:
    assert follow_anchor(40.0, 50.0, 60.0, 0.0) == 40.0  # tau 0: for good
    assert follow_anchor(40.0, 50.0, 30.0, 120.0) == pytest.approx(42.5)  # a quarter of the way
    assert follow_anchor(40.0, 50.0, 500.0, 120.0) == 50.0  # dt >= tau: the measured distance
    assert follow_anchor(40.0, 50.0, -5.0, 120.0) == 40.0  # a clock step back moves nothing


def _anchors_seen(tau_s: float, distances: list[tuple[float, float]], monkeypatch) -> list[float]:
    """Plan at each (t_s, neighbour distance) and return the anchor the planner was given each time."""
    scenario = load_scenario("paper-3.1-scenario3").with_keys(
        {"planner.connectivity": "topology", "planner.anchor_tau_s": tau_s}
    )
    core = AgentCore(0, scenario)
    seen: list[float] = []
    real_plan = core.planner.plan

    def spy(problem):
        seen.append(problem.anchor_m[0])
        return real_plan(problem)

    monkeypatch.setattr(core.planner, "plan", spy)
    est = Estimate(True, "", 0.0, np.array([-30.0, -100.0, 0.0, 0.0]), np.eye(4), 10, 0, 1.0)
    for t_s, d in distances:
        core.neighbours[1] = NeighbourTrack(
            auv=1,
            t_s=t_s,
            position=np.array([d, 0.0]),
            heading=0.0,
            controls=np.zeros((0, 2)),
            u_e=0.0,
            round=0,
            last_heard_s=t_s,
        )
        core._plan(t_s, np.array([0.0, 0.0]), math.pi / 2, est)
    return seen


def test_the_agent_keeps_the_first_pair_distance_for_good_by_default(monkeypatch) -> None:
    assert Scenario().planner.anchor_tau_s == 0.0
    # the built-in scenario 3's documented departure (issue 46): the topology reading, a drifting anchor
    built_in = load_scenario("paper-3.1-scenario3").planner
    assert (built_in.connectivity, built_in.anchor_tau_s) == ("topology", 120.0)
    assert load_scenario("paper-3.1-scenario2").planner.connectivity == "db"
    assert _anchors_seen(0.0, [(0.0, 40.0), (60.0, 50.0), (600.0, 70.0)], monkeypatch) == [40.0, 40.0, 40.0]


def test_the_agent_follows_the_pair_distance_with_a_time_constant(monkeypatch) -> None:
    seen = _anchors_seen(120.0, [(0.0, 40.0), (60.0, 50.0), (90.0, 50.0), (400.0, 70.0)], monkeypatch)
    assert seen == pytest.approx([40.0, 45.0, 46.25, 70.0])


def test_a_negative_time_constant_is_refused() -> None:
    with pytest.raises(ConfigError, match="anchor_tau_s"):
        load_scenario("paper-3.1-scenario3").with_keys({"planner.anchor_tau_s": -1.0})


def test_a_time_constant_without_the_topology_reading_is_refused_in_either_key_order() -> None:
    base = load_scenario("paper-3.1-scenario2")
    with pytest.raises(ConfigError, match="anchor_tau_s applies to planner.connectivity = 'topology' only"):
        base.with_keys({"planner.anchor_tau_s": 120.0})
    for keys in (
        {"planner.anchor_tau_s": 120.0, "planner.connectivity": "topology"},
        {"planner.connectivity": "topology", "planner.anchor_tau_s": 120.0},
    ):
        assert base.with_keys(keys).planner.anchor_tau_s == 120.0
