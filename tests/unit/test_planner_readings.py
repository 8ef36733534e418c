"""The readings of issue 27 (docs/planner.md): exact search against brute force under each.

``planner.speed_set = "ladder"`` (the default: d*/4, d*/2 and d* legs between u_e and u_max),
``"paper"`` (eq. 46) and ``"dstar"`` (u_d = min(u_max, d*/T_o) added);
``planner.range_constraint = "worst"`` (the default: eq. 50 at the sigma point violating it most)
and ``"mean"``; ``planner.connectivity = "formation" | "topology"`` (eq. 37 read as the pair
distances' deviation from the plan start or from a fixed reference): ``plan()`` must still equal
``brute_force()``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from auv_swarm.agent.planner import Neighbour, PlanProblem, brute_force, control_set, plan, speed_set
from auv_swarm.agent.planner.reference import same_optimum
from auv_swarm.contract import payload
from auv_swarm.contract.config import load_scenario


def _problems(connectivity: str, speeds: str, seed: int, count: int = 5, range_constraint: str = "worst"):
    sc = load_scenario("paper-3.1-scenario3")
    pl = dataclasses.replace(
        sc.planner, connectivity=connectivity, speed_set=speeds, horizon=3, range_constraint=range_constraint
    )
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
    ("connectivity", "speeds", "range_constraint"),
    [
        ("db", "ladder", "worst"),
        ("db", "ladder", "mean"),
        ("db", "paper", "worst"),
        ("db", "dstar", "mean"),
        ("formation", "paper", "mean"),
        ("formation", "ladder", "worst"),
        ("formation", "dstar", "worst"),
        ("topology", "dstar", "worst"),
    ],
)
def test_brute_force_plan_equals_exact_search_under_each_reading(
    connectivity: str, speeds: str, range_constraint: str
) -> None:
    seed = sum(map(ord, connectivity + speeds + range_constraint))
    for problem in _problems(connectivity, speeds, seed=seed, range_constraint=range_constraint):
        assert same_optimum(problem, plan(problem), brute_force(problem))


def test_speed_sets_and_the_payload_speed_index() -> None:
    pl = load_scenario("paper-3.1-scenario1").planner  # d* = 30 m, T_o = 60 s
    assert speed_set(pl, 0.2, 1.0) == (0.0, 0.2, 0.125, 0.25, 0.5, 1.0)
    assert speed_set(dataclasses.replace(pl, speed_set="paper"), 0.2, 1.0) == (0.0, 0.2, 1.0)
    assert speed_set(dataclasses.replace(pl, speed_set="dstar"), 0.2, 1.0) == (0.0, 0.2, 0.5, 1.0)
    # where d* >= u_max T_o (sections 3.2, 3.3) u_d is u_max, and the ladder is the paper's set
    far = load_scenario("paper-3.3-sim1").planner
    assert far.d_star_m >= 2.0 * far.step_s
    assert speed_set(dataclasses.replace(far, speed_set="dstar"), 0.3, 2.0) == (0.0, 0.3, 2.0, 2.0)
    assert speed_set(far, 0.3, 2.0) == (0.0, 0.3, 2.0)
    assert payload.N_SPEEDS == 8 and len(speed_set(pl, 0.2, 1.0)) <= payload.N_SPEEDS
