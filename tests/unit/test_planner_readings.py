"""The opt-in readings of issue 27's research (docs/planner.md, candidates): exact search against brute force.

``planner.speed_set = "dstar"`` (eq. 46 with u_d = min(u_max, d*/T_o) added) and
``planner.connectivity = "formation" | "topology"`` (eq. 37 read as the pair distances' deviation
from the plan start or from a fixed reference): ``plan()`` must still equal ``brute_force()``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from auv_swarm.agent.planner import Neighbour, PlanProblem, brute_force, control_set, plan, speed_set
from auv_swarm.agent.planner.reference import same_optimum
from auv_swarm.contract import payload
from auv_swarm.contract.config import load_scenario


def _problems(connectivity: str, speeds: str, seed: int, count: int = 5):
    sc = load_scenario("paper-3.1-scenario3")
    pl = dataclasses.replace(sc.planner, connectivity=connectivity, speed_set=speeds, horizon=3)
    rng = np.random.default_rng(seed)
    for _ in range(count):
        nbs = tuple(
            Neighbour(
                id=j + 1,
                position=rng.uniform(-40.0, 40.0, 2),
                heading=rng.uniform(-3.0, 3.0),
                sequence=np.column_stack([rng.choice([-0.5, 0.0, 0.5], 3), rng.uniform(0.0, 1.0, 3)]),
            )
            for j in range(2)
        )
        anchor = tuple(rng.uniform(20.0, 60.0, 2)) if connectivity == "topology" else None
        yield PlanProblem(
            position=rng.uniform(-40.0, 40.0, 2),
            heading=float(rng.uniform(-3.0, 3.0)),
            xi=np.array([0.0, -10.0, 0.1, 0.1]),
            P=np.eye(4) * rng.uniform(0.1, 5.0),
            neighbours=nbs,
            controls=control_set(pl, float(rng.uniform(0.0, 1.0)), 1.0, 0.05),
            planner=pl,
            channel=sc.channel,
            anchor_m=anchor,
        )


@pytest.mark.parametrize(
    ("connectivity", "speeds"),
    [("db", "dstar"), ("formation", "paper"), ("formation", "dstar"), ("topology", "dstar")],
)
def test_brute_force_plan_equals_exact_search_under_each_reading(connectivity: str, speeds: str) -> None:
    for problem in _problems(connectivity, speeds, seed=sum(map(ord, connectivity + speeds))):
        assert same_optimum(problem, plan(problem), brute_force(problem))


def test_speed_sets_and_the_payload_speed_index() -> None:
    pl = load_scenario("paper-3.1-scenario1").planner
    assert speed_set(pl, 0.2, 1.0) == (0.0, 0.2, 1.0)
    assert speed_set(dataclasses.replace(pl, speed_set="dstar"), 0.2, 1.0) == (0.0, 0.2, 0.5, 1.0)
    # where d* >= u_max T_o (sections 3.2, 3.3) u_d is u_max
    far = load_scenario("paper-3.3-sim1").planner
    assert speed_set(dataclasses.replace(far, speed_set="dstar"), 0.3, 2.0) == (0.0, 0.3, 2.0, 2.0)
    assert payload.N_SPEEDS == 4
