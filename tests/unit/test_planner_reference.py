"""The fast cost and search against the plain reference of eqs. (34)-(38) and (50), on every generated example."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from auv_swarm.agent.planner import Neighbour, PlanProblem, brute_force, plan
from auv_swarm.agent.planner.context import Context
from auv_swarm.agent.planner.cost import stage_cost
from auv_swarm.agent.planner.reference import own_paths, same_optimum, sequence_cost
from auv_swarm.contract.geometry import least_singular_value
from tests.unit.planner_problems import problem_sizes, random_problem


def _problem(draw_seed: int, *, n_headings: int, horizon: int, n_neighbours: int, **cfg_kw: float) -> PlanProblem:
    return random_problem(
        np.random.default_rng(draw_seed),
        n_headings=n_headings,
        horizon=horizon,
        n_neighbours=n_neighbours,
        range_m=(50.0, 2000.0),
        velocity_sd=0.6,
        position_scale=(1.0, 300.0),
        velocity_scale=(0.01, 1.0),
        noise_db=(40.0, 70.0, 110.0),
        **cfg_kw,
    )


def _fast_sequence_cost(problem: PlanProblem, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fast stage cost of :mod:`agent.planner.cost` summed along the sequences, at the reference's positions."""
    ctx = Context(problem)
    own = own_paths(problem, indices)
    total = np.zeros(own.shape[0])
    viol = np.zeros(own.shape[0])
    for h in range(1, problem.planner.horizon + 1):
        c, v = stage_cost(ctx, h, own[:, h - 1, 0].copy(), own[:, h - 1, 1].copy())
        total += c
        viol += v
    return total, viol


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    **problem_sizes([1, 3, 5, 7], max_horizon=5, max_neighbours=6),
    alpha=st.floats(0.0, 1.0),
    gamma=st.floats(0.0, 1.0),
    terminal=st.sampled_from([0.0, 1.0, 5.0]),
    soft=st.sampled_from([0.0, 10.0, 100.0]),
    w0=st.sampled_from([1.0 / 3.0, 0.0, -0.5, 0.8]),
    leg=st.sampled_from(["first", "straight", "arc", "first-arc", "ends"]),
)
def test_fast_cost_equals_the_reference_cost(
    seed: int,
    n_headings: int,
    horizon: int,
    n_neighbours: int,
    alpha: float,
    gamma: float,
    terminal: float,
    soft: float,
    w0: float,
    leg: str,
) -> None:
    problem = _problem(
        seed,
        n_headings=n_headings,
        horizon=horizon,
        n_neighbours=n_neighbours,
        alpha=alpha,
        gamma=gamma,
        terminal_weight=terminal,
        soft_penalty=soft,
        w0=w0,
        leg_constraint=leg,
    )
    indices = np.random.default_rng(seed).integers(0, problem.controls.size, (64, horizon))
    ref_cost, ref_viol = sequence_cost(problem, indices)
    fast_cost, fast_viol = _fast_sequence_cost(problem, indices)
    np.testing.assert_allclose(fast_cost, ref_cost, rtol=1e-9, atol=0.0)
    np.testing.assert_allclose(fast_viol, ref_viol, rtol=1e-9, atol=1e-9)


def test_reference_cost_is_the_floor_when_a_neighbour_sits_on_the_target() -> None:
    problem = _problem(
        3, n_headings=3, horizon=2, n_neighbours=1, alpha=1.0, gamma=0.0, soft_penalty=0.0, terminal_weight=0.0
    )
    still = np.zeros((2, 2))
    on_target = Neighbour(id=9, position=tuple(problem.xi[:2]), heading=0.0, sequence=still)
    problem = dataclasses.replace(problem, neighbours=(on_target,), xi=np.array([*problem.xi[:2], 0.0, 0.0]))
    problem = dataclasses.replace(problem, P=np.zeros((4, 4)))
    cost, _ = sequence_cost(problem, np.zeros((1, 2), dtype=np.int64))
    assert cost[0] == pytest.approx(2 * 1.0 / 1e-3, rel=1e-12)
    np.testing.assert_allclose(_fast_sequence_cost(problem, np.zeros((1, 2), dtype=np.int64))[0], cost, rtol=1e-9)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    **problem_sizes([1, 2, 3, 5], max_horizon=3, max_neighbours=4),
    d_safe=st.sampled_from([0.0, 100.0, 600.0]),
    leg=st.sampled_from(["first", "straight", "arc", "first-arc", "ends"]),
)
def test_plan_is_a_reference_optimum(
    seed: int, n_headings: int, horizon: int, n_neighbours: int, d_safe: float, leg: str
) -> None:
    problem = _problem(
        seed, n_headings=n_headings, horizon=horizon, n_neighbours=n_neighbours, d_safe_m=d_safe, leg_constraint=leg
    )
    assert same_optimum(problem, plan(problem), brute_force(problem))


def test_least_singular_value_matches_svd_on_random_and_nearly_parallel_bearings() -> None:
    rng = np.random.default_rng(4)
    for n in (2, 3, 4, 7):
        bearings = rng.uniform(-math.pi, math.pi, (100, n))
        bearings[:20] = bearings[:20, :1] + rng.normal(0.0, 1e-6, (20, n))
        got = least_singular_value(bearings)
        for b, s in zip(bearings, got, strict=True):
            phi = np.column_stack([np.sin(b), -np.cos(b)])
            assert s == pytest.approx(np.linalg.svd(phi, compute_uv=False)[-1], rel=1e-7)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    **problem_sizes([1, 2, 3, 5], max_horizon=3, max_neighbours=4),
    leg=st.sampled_from(["first", "straight", "arc", "first-arc", "ends"]),
)
def test_an_infeasible_plan_is_a_reference_optimum(
    seed: int, n_headings: int, horizon: int, n_neighbours: int, leg: str
) -> None:
    """Neighbours close and d_S large, the target near: mostly no sequence keeps d_S, and the plan trades d_S
    against d* metre for metre exactly as the brute force does."""
    problem = random_problem(
        np.random.default_rng(seed),
        n_headings=n_headings,
        horizon=horizon,
        n_neighbours=max(n_neighbours, 1),
        range_m=(20.0, 700.0),
        velocity_sd=0.6,
        position_scale=(1.0, 300.0),
        velocity_scale=(0.01, 1.0),
        spread_m=500.0,
        d_safe_m=600.0,
        leg_constraint=leg,
    )
    assert same_optimum(problem, plan(problem), brute_force(problem))
