"""Heading-hold guidance: bounded commands, turns in place at zero surge, and whole plans executed open loop
through the world's eq. (1) land where the planner's step model says, within the bound of docs/planner.md."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auv_swarm.agent.guidance import guidance, step_position_bound, wrap_pi
from auv_swarm.agent.planner import plan
from auv_swarm.agent.planner.context import Context
from auv_swarm.agent.planner.cost import closest_on_executed_leg, executed_leg
from auv_swarm.world.model import vehicle_step
from tests.unit.planner_problems import random_problem

U_MAX = 2.0
R_MAX = 0.05


@settings(max_examples=300, deadline=None)
@given(
    x=st.floats(-5e3, 5e3),
    y=st.floats(-5e3, 5e3),
    theta=st.floats(-20.0, 20.0),
    heading=st.floats(-20.0, 20.0),
    speed=st.floats(-1.0, 5.0),
    dt=st.floats(0.01, 10.0),
)
def test_commands_stay_within_bounds(x, y, theta, heading, speed, dt) -> None:
    u, r = guidance((x, y, theta), heading, speed, U_MAX, R_MAX, dt)
    assert 0.0 <= u <= min(U_MAX, max(speed, 0.0))
    assert -R_MAX <= r <= R_MAX
    assert math.isfinite(u) and math.isfinite(r)


def test_zero_speed_turns_in_place_onto_the_heading() -> None:
    state = np.array([5.0, -3.0, 0.0])
    for _ in range(40):
        u, r = guidance(state, math.pi / 2, 0.0, U_MAX, R_MAX, 1.0)
        assert u == 0.0
        state = vehicle_step(state, u, r, 1.0, U_MAX, R_MAX)
    assert state[:2].tolist() == [5.0, -3.0]
    assert abs(wrap_pi(state[2] - math.pi / 2)) < 1e-12


def test_turns_at_r_max_and_lands_on_the_heading_in_one_tick() -> None:
    assert guidance((0.0, 0.0, 0.0), -1.0, 1.0, U_MAX, R_MAX, 1.0) == (1.0, -R_MAX)
    u, r = guidance((0.0, 0.0, 0.0), 0.01, 1.0, U_MAX, R_MAX, 2.0)
    assert u == 1.0 and r == pytest.approx(0.005, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), horizon=st.integers(1, 4), dt=st.sampled_from([0.5, 1.0, 2.0, 6.5]))
def test_whole_plans_run_open_loop_end_each_step_on_the_planned_heading_within_the_bound(seed, horizon, dt) -> None:
    rng = np.random.default_rng(seed)
    problem = random_problem(rng, n_headings=5, horizon=horizon, n_neighbours=1)
    result = plan(problem)
    step_s = problem.planner.step_s
    ticks = round(step_s / dt)
    state = np.array([*problem.position, problem.heading], dtype=float)
    heading = problem.heading
    bound = 0.0
    for h, (dtheta, speed) in enumerate(result.controls.tolist()):
        heading += dtheta
        for _ in range(ticks):
            u, r = guidance(state, heading, speed, U_MAX, R_MAX, dt)
            state = vehicle_step(state, u, r, dt, U_MAX, R_MAX)
        bound += step_position_bound(dtheta, speed, R_MAX, dt)
        assert abs(wrap_pi(state[2] - heading)) < 1e-9
        gap = float(np.hypot(*(state[:2] - result.waypoints[h])))
        assert gap <= bound + 1e-6, (h, gap, bound)


def test_the_bound_is_tight_to_within_the_tick_term_for_a_quarter_turn() -> None:
    # continuous turn at r_max while running at u: the exact gap is (u / r) sqrt(2 - 2 cos a + a^2 - 2 a sin a)
    a, u = math.pi / 2, 1.0
    exact = (u / R_MAX) * math.sqrt(2 - 2 * math.cos(a) + a * a - 2 * a * math.sin(a))
    bound = step_position_bound(a, u, R_MAX, 1.0)
    assert exact <= bound <= 1.1 * exact


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"u_max": 0.0}, "u_max"), ({"r_max": -1.0}, "r_max"), ({"dt_s": math.inf}, "dt_s")],
)
def test_invalid_parameters_name_the_parameter(kwargs: dict, name: str) -> None:
    args = {"u_max": U_MAX, "r_max": R_MAX, "dt_s": 1.0, **kwargs}
    with pytest.raises(ValueError, match=f"{name} must be in"):
        guidance((0.0, 0.0, 0.0), 1.0, 1.0, **args)
    with pytest.raises(ValueError, match="state"):
        guidance((0.0, math.nan, 0.0), 1.0, 1.0, U_MAX, R_MAX, 1.0)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_headings=st.sampled_from([3, 5, 7]))
def test_the_arc_first_leg_is_the_leg_the_vehicle_flies(seed, n_headings) -> None:
    """``planner.leg_constraint = "arc"``: the planner's executed first leg (a turn at r_max, then straight) and its
    closest approach to a neighbour's leg match the vehicle of eq. (1) flown by guidance in 0.05 s ticks."""
    rng = np.random.default_rng(seed)
    problem = random_problem(rng, n_headings=n_headings, horizon=1, n_neighbours=1, leg_constraint="arc")
    ctx = Context(problem)
    step_s, dt = problem.planner.step_s, 0.05
    nb = problem.neighbours[0]
    q0 = np.array(nb.position)
    q1 = q0 + nb.sequence[0][1] * step_s * np.array(
        [math.cos(nb.heading + nb.sequence[0][0]), math.sin(nb.heading + nb.sequence[0][0])]
    )
    for dtheta, speed in problem.controls.controls[rng.choice(problem.controls.size, 3, replace=False)]:
        heading = problem.heading + dtheta
        end = problem.position + speed * step_s * np.array([math.cos(heading), math.sin(heading)])
        t, xs, ys = executed_leg(ctx, np.array([end[0]]), np.array([end[1]]))
        closest = closest_on_executed_leg(ctx, q0[:1], q0[1:], q1[:1], q1[1:], np.array([end[0]]), np.array([end[1]]))
        state = np.array([*problem.position, problem.heading], dtype=float)
        flown = [math.dist(state[:2], q0)]
        for k in range(1, round(step_s / dt) + 1):
            u, r = guidance(state, heading, speed, U_MAX, R_MAX, dt)
            state = vehicle_step(state, u, r, dt, U_MAX, R_MAX)
            flown.append(math.dist(state[:2], q0 + (q1 - q0) * (k * dt / step_s)))
        assert math.dist(state[:2], (xs[-1, 0], ys[-1, 0])) <= speed * R_MAX * dt * dt + 1e-6
        # sampled every dt at relative speed <= 2 U_MAX, and chords within 2 cm of the arc
        assert abs(min(flown) - float(closest[0, 0])) <= 2 * U_MAX * dt / 2 + 0.02, (dtheta, speed)
