"""The planner's constraints along the first leg (``planner.leg_constraint``): closest approach, turn margin, the
leg as flown."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from auv_swarm.agent.planner import (
    Neighbour,
    PlanProblem,
    brute_force,
    context,
    control_set,
    cost,
    plan,
)
from auv_swarm.agent.planner.reference import make_plan, sequence_cost, sequence_violation
from auv_swarm.contract.config import ChannelConfig, PlannerConfig
from tests.unit.planner_naive import naive_cost
from tests.unit.planner_problems import random_problem

# ----------------------------------------------------------------------------- constraints along the first leg


def _one_step(leg: str, **keys: object) -> PlannerConfig:
    """One 60 s step, d_S = 25 m, the paper's speed set, ``planner.leg_constraint = leg`` and ``keys``."""
    return dataclasses.replace(
        PlannerConfig(), horizon=1, step_s=60.0, d_safe_m=25.0, speed_set="paper", leg_constraint=leg, **keys
    )


def _crossing_problem(leg: str, *, d_star: float = 500.0, target=(30.0, 5000.0)) -> PlanProblem:
    """Own AUV at the origin facing east (one heading, speeds 0 and 1 m/s, T_o = 60 s, d_S = 25 m) and a
    neighbour at (60, 10) m heading west at 0.5 m/s: going east, the two pass 10 m apart, though they end
    31.6 m apart; staying, the neighbour stops 31.6 m away."""
    cfg = _one_step(leg, n_headings=1, d_star_m=d_star, d_max_m=10_000.0)
    controls = control_set(cfg, 1.0, 1.0, 0.05)
    west = Neighbour(id=1, position=(60.0, 10.0), heading=math.pi, sequence=np.array([[0.0, 0.5]]))
    return PlanProblem(
        position=np.zeros(2),
        heading=0.0,
        xi=np.array([*target, 0.0, 0.0]),
        P=np.eye(4) * 1e-6,
        neighbours=(west,),
        controls=controls,
        planner=cfg,
        channel=ChannelConfig(),
    )


def test_first_leg_counts_the_closest_approach_to_a_neighbour() -> None:
    east = int(np.flatnonzero(_crossing_problem("first").controls.controls[:, 1] == 1.0)[0])
    for leg, expected in (("first", 15.0), ("ends", 0.0)):  # d_S - 10 m at closest; 60.8 m, then 31.6 m apart
        problem = _crossing_problem(leg)
        _, viol = sequence_cost(problem, np.array([[east]]))
        assert viol[0] == pytest.approx(expected, abs=1e-9)
        assert naive_cost(problem, np.array([east]))[1] == pytest.approx(expected, abs=1e-9)
    chosen = plan(_crossing_problem("first"))
    assert chosen.feasible and chosen.controls[0, 1] == 0.0  # it waits rather than cross 10 m from the neighbour


def test_first_leg_counts_the_closest_approach_to_the_target() -> None:
    # target 30 m east of the start, d* = 20 m: the 60 m leg east ends 30 m beyond it but passes through it
    east = int(np.flatnonzero(_crossing_problem("first").controls.controls[:, 1] == 1.0)[0])
    penalties = {}
    for leg in ("first", "ends"):
        problem = _crossing_problem(leg, d_star=20.0, target=(30.0, 0.0))
        problem = dataclasses.replace(problem, neighbours=())
        penalties[leg] = make_plan(problem, np.array([east]), 0).terms["penalty"]
    soft = PlannerConfig().soft_penalty
    assert penalties["ends"] == pytest.approx(0.0, abs=1e-9)
    assert penalties["first"] == pytest.approx(soft * 20.0 / 20.0, rel=1e-6)  # min(d*, 30 m) - 0 m, over d*


def test_already_inside_the_safety_distance_only_getting_closer_counts() -> None:
    problem = _crossing_problem("first")
    still = Neighbour(id=1, position=(0.0, 20.0), heading=0.0, sequence=np.array([[0.0, 0.0]]))
    problem = dataclasses.replace(problem, neighbours=(still,))
    east = int(np.flatnonzero(problem.controls.controls[:, 1] == 1.0)[0])
    stay = int(np.flatnonzero(problem.controls.controls[:, 1] == 0.0)[0])
    # 20 m apart at the start: staying is the old end-of-step violation (5 m) and no dip; going east moves away
    assert sequence_cost(problem, np.array([[stay]]))[1][0] == pytest.approx(5.0, abs=1e-9)
    assert sequence_cost(problem, np.array([[east]]))[1][0] == pytest.approx(0.0, abs=1e-9)


def test_when_d_safe_cannot_be_met_the_plan_trades_it_against_d_star_metre_for_metre() -> None:
    # own AUV at the origin facing east (stay, or 60 m east); a still neighbour at (20, -5) m; the target at
    # (-10, 0) m with d* = 30 m. Staying: 4.38 m inside d_S, 20 m inside d*. East: passes the neighbour 5 m away
    # (15.62 m inside d_S), moving away from the target. Least d_S violation alone would stay, 20 m inside d*.
    problem = _crossing_problem("first", d_star=30.0, target=(-10.0, 0.0))
    still = Neighbour(id=1, position=(20.0, -5.0), heading=0.0, sequence=np.array([[0.0, 0.0]]))
    problem = dataclasses.replace(problem, neighbours=(still,), P=np.eye(4) * 1e-14)  # sigma points on the target
    east = int(np.flatnonzero(problem.controls.controls[:, 1] == 1.0)[0])
    stay = int(np.flatnonzero(problem.controls.controls[:, 1] == 0.0)[0])
    s = math.hypot(20.0, 5.0)
    assert sequence_cost(problem, np.array([[stay]]))[1][0] == pytest.approx(25.0 - s, abs=1e-9)
    assert sequence_cost(problem, np.array([[east]]))[1][0] == pytest.approx(s - 5.0, abs=1e-9)
    assert sequence_violation(problem, np.array([stay])) == pytest.approx(25.0 - s + 20.0, abs=1e-3)
    assert sequence_violation(problem, np.array([east])) == pytest.approx(s - 5.0, abs=1e-3)
    for chosen in (plan(problem), brute_force(problem)):
        assert not chosen.feasible and chosen.indices.tolist() == [east]


def _quarter_turn_violation(heading: float, neighbour: tuple[float, float], end: tuple[float, float], leg: str):
    """Safety violation (m) of the right quarter turn at 1 m/s (one 60 s step, r_max 0.05 rad/s, d_S 25 m) from
    the origin facing ``heading``, a still neighbour at ``neighbour``: (reference, fast path at ``end``)."""
    planner = _one_step(leg, n_headings=3, d_star_m=30.0)
    problem = PlanProblem(
        position=np.zeros(2),
        heading=heading,
        xi=np.array([0.0, -3000.0, 0.0, 0.0]),
        P=np.eye(4) * 1e-6,
        neighbours=(Neighbour(id=1, position=neighbour, heading=0.0, sequence=np.array([[0.0, 0.0]])),),
        controls=control_set(planner, 1.0, 1.0, 0.05),
        planner=planner,
        channel=ChannelConfig(),
    )
    right = int(np.flatnonzero((problem.controls.controls[:, 0] < 0) & (problem.controls.controls[:, 1] == 1.0))[0])
    reference = sequence_cost(problem, np.array([[right]]))[1][0]
    _, fast = cost.stage_cost(context.Context(problem), 1, np.array([end[0]]), np.array([end[1]]))
    return reference, fast[0]


def test_the_turn_margin_and_the_arc_see_the_turn_the_straight_leg_does_not() -> None:
    # facing north at the origin, the control (-pi/2, 1 m/s) is planned as 60 m east; flown, it turns at
    # 0.05 rad/s on a 20 m radius through (20, 20) m, then runs east. A still neighbour at (20, 40) m is 40 m
    # from the planned leg but 20 m from the flown one: 5 m inside d_S = 25 m. "first" grows d_S by the turn's
    # margin instead, so the straight leg must keep min(44.7 m now, 25 m + margin) from it.
    margin = 1.0 * (math.pi / 2) ** 2 / (2 * 0.05)  # 24.67 m: u dtheta^2 / (2 r_max)
    s = math.hypot(20.0, 40.0)  # 44.7 m now, 40 m at the straight leg's closest
    for leg, expected in (
        ("straight", 0.0),
        ("first", min(s, 25.0 + margin) - 40.0),
        ("arc", 5.0),
        ("first-arc", 5.0),  # the larger of "first"'s 4.7 m and the flown leg's 5 m
    ):
        reference, fast = _quarter_turn_violation(math.pi / 2, (20.0, 40.0), (60.0, 0.0), leg)
        assert reference == pytest.approx(expected, abs=1e-3), leg
        assert fast == pytest.approx(expected, abs=1e-3), leg


def test_first_arc_is_first_and_for_d_safe_also_the_flown_leg() -> None:
    # "first-arc" composes the checks: its safety violation is the larger of "first"'s and "arc"'s, its d*
    # shortfall "first"'s, for every candidate end of step 1 (sources and neighbours close enough to bite)
    differs = {"safety": 0, "floor": 0}
    for seed in range(24):
        rng = np.random.default_rng(seed)
        base = random_problem(
            rng, n_headings=5, horizon=1, n_neighbours=3, range_m=(300.0, 700.0), spread_m=400.0, d_safe_m=150.0
        )
        got = {}
        for leg in ("first", "arc", "first-arc"):
            problem = dataclasses.replace(base, planner=dataclasses.replace(base.planner, leg_constraint=leg))
            ctx = context.Context(problem)
            dtheta, speed = problem.controls.controls[:, 0], problem.controls.controls[:, 1]
            ex = problem.position[0] + problem.planner.step_s * speed * np.cos(problem.heading + dtheta)
            ey = problem.position[1] + problem.planner.step_s * speed * np.sin(problem.heading + dtheta)
            got[leg] = (cost.neighbour_ranges(ctx, 1, ex, ey)[1], cost.floor_shortfall(ctx, 1, ex, ey))
        # per neighbour the larger dip, summed over the neighbours: at least either sum, at most both
        assert np.all(got["first-arc"][0] >= np.maximum(got["first"][0], got["arc"][0]) - 1e-9)
        assert np.all(got["first-arc"][0] <= got["first"][0] + got["arc"][0] + 1e-9)
        np.testing.assert_allclose(got["first-arc"][1], got["first"][1], rtol=1e-12, atol=1e-12)
        differs["safety"] += int(not np.allclose(got["arc"][0], got["first"][0]))
        differs["floor"] += int(not np.allclose(got["arc"][1], got["first"][1]))
    assert differs["safety"] > 0 and differs["floor"] > 0, differs  # the two checks do differ on these problems


def test_first_arc_sees_the_turn_that_swings_toward_a_neighbour_first_does_not() -> None:
    # facing west at the origin, the control (-pi/2, 1 m/s) is planned as 60 m north; flown, it turns right at
    # 0.05 rad/s on a 20 m circle about (0, 20) m. A still neighbour at (-20, 0) m is 20 m away now (inside
    # d_S = 25 m) and the straight leg only moves away from it: "first" asks it not to come closer on that leg
    # (0 m). The flown turn passes 20 sqrt(2) - 20 = 8.28 m from it, 11.72 m closer than now: "arc" and
    # "first-arc" count that.
    swing = 20.0 - (20.0 * math.sqrt(2.0) - 20.0)
    for leg, expected in (("straight", 0.0), ("first", 0.0), ("arc", swing), ("first-arc", swing)):
        reference, fast = _quarter_turn_violation(math.pi, (-20.0, 0.0), (0.0, 60.0), leg)
        # the flown turn is ARC_CHORDS chords, each within 2.4 cm of the circle at 1 m/s
        assert reference == pytest.approx(expected, abs=0.03), leg
        assert fast == pytest.approx(expected, abs=0.03), leg


@pytest.mark.parametrize("seed", range(2))
def test_a_half_turn_is_flown_to_the_right_whichever_way_it_rounded(seed: int) -> None:
    # dtheta = +pi and -pi reach the same heading: their planned ends differ by rounding only, and so must their
    # flown legs (to the right, -pi), in the reference and in the fast path, whatever the start heading
    rng = np.random.default_rng(seed)
    base = random_problem(rng, n_headings=3, horizon=1, n_neighbours=2, dtheta_max_rad=math.pi, d_safe_m=600.0)
    table = base.controls.controls
    half = [int(i) for i in np.flatnonzero((np.abs(table[:, 0]) == math.pi) & (table[:, 1] > 0.0))]
    assert len(half) == 4  # two moving speeds, each at -pi and +pi
    for heading0 in rng.uniform(-math.pi, math.pi, 12):
        problem = dataclasses.replace(base, heading=heading0)
        ctx = context.Context(problem)
        heading = heading0 + table[half, 0]
        ex = problem.planner.step_s * table[half, 1] * np.cos(heading)  # from the origin
        ey = problem.planner.step_s * table[half, 1] * np.sin(heading)
        assert np.all(cost._first_turn(ctx, ex, ey)[2] == -math.pi)
        left = context.Context(dataclasses.replace(problem, heading=heading0 + 1e-3))  # a real left turn stays left
        assert np.all(cost._first_turn(left, ex, ey)[2] > 0.0)
        fast = cost.stage_cost(ctx, 1, ex, ey)[1]
        ref = sequence_cost(problem, np.array(half)[:, None])[1]
        for a, b in ((0, 2), (1, 3)):  # -pi and +pi at the same speed
            assert fast[a] == pytest.approx(fast[b], abs=1e-6) and ref[a] == pytest.approx(ref[b], abs=1e-6)
        np.testing.assert_allclose(fast, ref, atol=1e-6)
