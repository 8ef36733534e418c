"""Exact DMPC planner: closed forms, unscented transform, plan == brute force, sequential decision making."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from auv_swarm.agent.planner import (
    LAMBDA_FLOOR,
    SIGMA_FLOOR,
    ControlSet,
    Neighbour,
    PlanProblem,
    base_speed,
    brute_force,
    context,
    control_set,
    cost,
    graph,
    plan,
    sigma_points,
    warm_up,
)
from auv_swarm.agent.planner.reference import make_plan, same_optimum, sequence_cost, sequence_violation
from auv_swarm.contract import acoustics
from auv_swarm.contract.config import ChannelConfig, ConfigError, PlannerConfig
from auv_swarm.contract.geometry import least_singular_value
from tests.unit.planner_problems import problem_sizes, random_problem


def _problem(
    rng: np.random.Generator,
    *,
    n_headings: int = 5,
    horizon: int = 2,
    n_neighbours: int = 2,
    dtheta_max: float = math.pi / 2,
    u_e: float | None = None,
    d_safe: float = 100.0,
    noise_db: float = 40.0,
    spread_m: float = 1500.0,
) -> PlanProblem:
    return random_problem(
        rng,
        n_headings=n_headings,
        horizon=horizon,
        n_neighbours=n_neighbours,
        u_e=u_e,
        spread_m=spread_m,
        noise_db=noise_db,
        dtheta_max_rad=dtheta_max,
        d_safe_m=d_safe,
    )


def _naive_cost(problem: PlanProblem, indices: np.ndarray) -> tuple[float, float]:
    """Cost and safety violation of one sequence, straight from eqs. (22)-(38) and (50) with SVD and eigvalsh."""
    cfg, ch = problem.planner, problem.channel
    T = cfg.step_s
    pts, w = sigma_points(problem.xi, problem.P, cfg.w0)
    table = problem.controls.controls
    x, y = problem.position
    theta = problem.heading
    nb = []
    for n in problem.neighbours:
        nx, ny = n.position
        nt = n.heading
        path = []
        for dth, sp in n.sequence:
            nt += dth
            nx, ny = nx + sp * T * math.cos(nt), ny + sp * T * math.sin(nt)
            path.append((nx, ny))
        nb.append(path)
    total, violation = 0.0, 0.0
    x0, y0 = x, y
    on_leg = cfg.leg_constraint in ("first", "straight")
    margin = 0.0
    for h, u in enumerate(indices, start=1):
        dth, sp = table[u]
        if h == 1 and cfg.leg_constraint == "first" and math.isfinite(problem.controls.r_max):
            margin = sp * dth * dth / (2.0 * problem.controls.r_max)  # how far the flown turn strays
        theta += dth
        x, y = x + sp * T * math.cos(theta), y + sp * T * math.sin(theta)
        agents = np.array([(x, y)] + [p[h - 1] for p in nb])
        ranges_to_points, shorts = [], []
        for point, weight in zip(pts, w, strict=True):
            tgt = point[:2] + h * T * point[2:]
            bearings = np.arctan2(tgt[1] - agents[:, 1], tgt[0] - agents[:, 0])
            phi = np.column_stack([np.sin(bearings), -np.cos(bearings)])
            sig = np.linalg.svd(phi, compute_uv=False)[-1]
            d = math.hypot(tgt[0] - x, tgt[1] - y)
            short = max(0.0, cfg.d_star_m - d)
            if on_leg and h == 1:  # the first leg's dip towards this sigma point, moving from point[:2] to tgt
                short = max(short, _dip((x0, y0), (x, y), point[:2], tgt, cfg.d_star_m + margin))
            shorts.append(short)
            ranges_to_points.append(d)
            stage = cfg.alpha / max(sig, SIGMA_FLOOR) + (1 - cfg.alpha) * d / cfg.d_star_m
            if cfg.range_constraint == "mean":
                stage += cfg.soft_penalty * (short / cfg.d_star_m + max(0.0, d - cfg.d_max_m) / cfg.d_max_m)
            if h == cfg.horizon:
                stage += cfg.terminal_weight * abs(d - cfg.d_star_m) / cfg.d_star_m
            total += weight * stage
        if cfg.range_constraint == "worst":  # eq. (50) at the nearest and the farthest sigma point
            far = max(ranges_to_points)
            total += cfg.soft_penalty * (max(shorts) / cfg.d_star_m + max(0.0, far - cfg.d_max_m) / cfg.d_max_m)
        if len(agents) > 1:
            lam = acoustics.fiedler_value(acoustics.snr_laplacian(agents, ch))
            total += cfg.gamma * (len(agents) - 1) / max(lam, LAMBDA_FLOOR)  # eq. 37: over |N_i|
            for j, n in enumerate(problem.neighbours):
                short = max(0.0, cfg.d_safe_m - math.hypot(agents[j + 1, 0] - x, agents[j + 1, 1] - y))
                if on_leg and h == 1:
                    short = max(short, _dip((x0, y0), (x, y), n.position, nb[j][0], cfg.d_safe_m + margin))
                violation += short
    return total, violation


def _dip(a0, a1, b0, b1, limit: float) -> float:
    """How much closer than min(limit, |a0 - b0|) two points moving linearly a0 -> a1, b0 -> b1 come (m).

    Plainly: the squared distance is a quadratic in the step fraction s; its minimum on [0, 1] is at an
    end or at the vertex.
    """
    rx, ry = a0[0] - b0[0], a0[1] - b0[1]
    vx, vy = (a1[0] - a0[0]) - (b1[0] - b0[0]), (a1[1] - a0[1]) - (b1[1] - b0[1])
    candidates = [0.0, 1.0]
    if vx * vx + vy * vy > 0.0:
        candidates.append(min(1.0, max(0.0, -(rx * vx + ry * vy) / (vx * vx + vy * vy))))
    closest = min(math.hypot(rx + s * vx, ry + s * vy) for s in candidates)
    dip = min(limit, math.hypot(rx, ry)) - closest
    return dip if dip > 1e-9 else 0.0


# ----------------------------------------------------------------------------- geometry closed form


def test_least_singular_value_is_sqrt_three_halves_at_the_fig3_configurations() -> None:
    for offset in (0.0, 0.3, -2.0):
        spread_120 = offset + np.radians([0.0, 120.0, 240.0])
        spread_60 = offset + np.radians([0.0, 60.0, 120.0])
        assert least_singular_value(spread_120) == pytest.approx(math.sqrt(1.5), rel=1e-12)
        assert least_singular_value(spread_60) == pytest.approx(math.sqrt(1.5), rel=1e-12)


def test_least_singular_value_matches_svd_and_is_smaller_elsewhere() -> None:
    rng = np.random.default_rng(3)
    bearings = rng.uniform(-math.pi, math.pi, (200, 3))
    got = least_singular_value(bearings)
    for b, s in zip(bearings, got, strict=True):
        phi = np.column_stack([np.sin(b), -np.cos(b)])
        assert s == pytest.approx(np.linalg.svd(phi, compute_uv=False)[-1], rel=1e-9, abs=1e-12)
    assert np.all(got < math.sqrt(1.5) - 1e-6)


def test_least_singular_value_is_accurate_for_nearly_collinear_bearings() -> None:
    b = np.array([0.3, 0.3 + 1e-9, 0.3 - 2e-9])
    phi = np.column_stack([np.sin(b), -np.cos(b)])
    exact = np.linalg.svd(phi, compute_uv=False)[-1]
    assert least_singular_value(b) == pytest.approx(exact, rel=1e-5)
    assert least_singular_value(np.array([1.0])) == 1.0


# ----------------------------------------------------------------------------- unscented transform


@pytest.mark.parametrize("w0", [1.0 / 3.0, 0.0, -0.5, 0.9])
def test_sigma_points_reproduce_mean_and_covariance(w0: float) -> None:
    rng = np.random.default_rng(5)
    a = rng.normal(size=(4, 4))
    P = a @ a.T + 0.1 * np.eye(4)
    xi = rng.normal(size=4) * 100.0
    pts, w = sigma_points(xi, P, w0)
    assert pts.shape == (9, 4) and w.shape == (9,)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    mean = w @ pts
    dev = pts - mean
    np.testing.assert_allclose(mean, xi, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose((w[:, None] * dev).T @ dev, P, rtol=1e-9, atol=1e-9)


def test_propagating_sigma_points_equals_propagating_mean_and_covariance() -> None:
    rng = np.random.default_rng(6)
    a = rng.normal(size=(4, 4)) * np.array([50.0, 50.0, 0.5, 0.5])[:, None]
    P = a @ a.T
    xi = np.array([300.0, -200.0, 0.7, -0.2])
    T = 130.0 * 3
    F = np.block([[np.eye(2), T * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    pts, w = sigma_points(xi, P, 1.0 / 3.0)
    moved = pts @ F.T
    mean = w @ moved
    dev = moved - mean
    np.testing.assert_allclose(mean, F @ xi, rtol=1e-12, atol=1e-8)
    np.testing.assert_allclose((w[:, None] * dev).T @ dev, F @ P @ F.T, rtol=1e-9, atol=1e-6)


def test_sigma_points_survive_singular_and_indefinite_covariances() -> None:
    xi = np.array([1.0, 2.0, 0.0, 0.0])
    for P in (np.zeros((4, 4)), np.diag([1.0, 1.0, 0.0, 0.0]), np.diag([1.0, -1e-6, 1.0, 1.0])):
        pts, _ = sigma_points(xi, P, 1.0 / 3.0)
        assert np.all(np.isfinite(pts))
    pts, w = sigma_points(xi, np.diag([4.0, 4.0, 0.0, 0.0]), 1.0 / 3.0)
    dev = pts - xi
    np.testing.assert_allclose((w[:, None] * dev).T @ dev, np.diag([4.0, 4.0, 0.0, 0.0]), atol=1e-6)


# ----------------------------------------------------------------------------- exact search


def test_plan_matches_brute_force_and_the_paper_cost_on_a_fixed_instance() -> None:
    problem = _problem(np.random.default_rng(11), n_headings=7, horizon=3, n_neighbours=2)
    fast = plan(problem)
    ref = brute_force(problem)
    assert same_optimum(problem, fast, ref)
    naive, violation = _naive_cost(problem, fast.indices)
    assert fast.cost == pytest.approx(naive, rel=1e-9)
    assert violation == 0.0 and fast.feasible
    assert sum(fast.terms[k] for k in ("geometry", "distance", "connectivity", "penalty", "terminal")) == pytest.approx(
        fast.cost, rel=1e-12
    )
    assert fast.nodes < ref.nodes
    np.testing.assert_allclose(fast.controls, problem.controls.controls[fast.indices])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    **problem_sizes([1, 2, 3, 4, 5], max_horizon=4, max_neighbours=4),
    dtheta_max=st.sampled_from([0.0, math.pi / 2, math.pi / 3, 1.0, math.pi]),
    speed_case=st.sampled_from(["base", "zero", "max"]),
    d_safe=st.sampled_from([0.0, 100.0, 600.0]),
    noise_db=st.sampled_from([40.0, 110.0]),
    weights=st.tuples(
        st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.sampled_from([0.0, 1.0, 5.0]), st.sampled_from([0.0, 10.0, 100.0])
    ),
    w0=st.sampled_from([1.0 / 3.0, 0.0, -0.5, 0.8]),
)
def test_plan_equals_brute_force_on_random_small_instances(
    seed: int,
    n_headings: int,
    horizon: int,
    n_neighbours: int,
    dtheta_max: float,
    speed_case: str,
    d_safe: float,
    noise_db: float,
    weights: tuple[float, float, float, float],
    w0: float,
) -> None:
    u_e = {"base": None, "zero": 0.0, "max": 2.0}[speed_case]
    if horizon == 4 and n_headings > 3:
        horizon = 3
    problem = _problem(
        np.random.default_rng(seed),
        n_headings=n_headings,
        horizon=horizon,
        n_neighbours=n_neighbours,
        dtheta_max=dtheta_max,
        u_e=u_e,
        d_safe=d_safe,
        noise_db=noise_db,
        spread_m=900.0,
    )
    alpha, gamma, terminal, soft = weights
    cfg = dataclasses.replace(
        problem.planner, alpha=alpha, gamma=gamma, terminal_weight=terminal, soft_penalty=soft, w0=w0
    )
    problem = dataclasses.replace(problem, planner=cfg)
    fast = plan(problem)
    ref = brute_force(problem)
    assert same_optimum(problem, fast, ref)
    assert np.isfinite(fast.cost)


@pytest.mark.parametrize("seed", range(6))
def test_plan_equals_brute_force_at_horizon_five(seed: int) -> None:
    # H = 5 prunes with an incumbent at levels H - 2 and H - 1, where the cascade of remaining-step bounds runs
    rng = np.random.default_rng(100 + seed)
    problem = _problem(rng, n_headings=3, horizon=5, n_neighbours=seed % 3, dtheta_max=1.0, spread_m=900.0)
    cfg = dataclasses.replace(problem.planner, alpha=0.3 + 0.1 * seed, terminal_weight=float(seed % 2) * 5.0)
    problem = dataclasses.replace(problem, planner=cfg)
    fast = plan(problem)
    ref = brute_force(problem)
    assert same_optimum(problem, fast, ref)
    assert fast.nodes < ref.nodes


@pytest.mark.parametrize("w0", [0.0, 1.0 / 3.0, 0.8])
def test_centre_bound_of_the_remaining_steps_is_below_the_full_bound(w0: float) -> None:
    rng = np.random.default_rng(5)
    problem = _problem(rng, n_headings=3, horizon=5, n_neighbours=2)
    for alpha, terminal, soft in ((0.5, 1.0, 10.0), (0.9, 0.0, 0.0), (0.0, 5.0, 100.0)):
        cfg = dataclasses.replace(problem.planner, w0=w0, alpha=alpha, terminal_weight=terminal, soft_penalty=soft)
        ctx = context.Context(dataclasses.replace(problem, planner=cfg))
        px, py = rng.uniform(-3000.0, 3000.0, (2, 400))
        for h in range(1, ctx.H):
            full = cost.range_rest(ctx, h, px, py)
            assert np.all(cost.range_rest_centre(ctx, h, px, py) <= full * (1.0 + 1e-12))


def test_ties_pick_the_lexicographically_smallest_sequence() -> None:
    problem = _problem(np.random.default_rng(2), n_headings=3, horizon=3, n_neighbours=1)
    still = ControlSet(dtheta=problem.controls.dtheta, speeds=np.array([0.0, 0.0]))
    frozen = dataclasses.replace(problem, controls=still)
    np.testing.assert_array_equal(plan(frozen).indices, [0, 0, 0])
    np.testing.assert_array_equal(brute_force(frozen).indices, [0, 0, 0])


def test_all_infeasible_falls_back_to_least_violation() -> None:
    rng = np.random.default_rng(4)
    base = _problem(rng, n_headings=3, horizon=2, n_neighbours=0)
    parked = Neighbour(id=7, position=(30.0, -20.0), heading=0.0, sequence=np.zeros((2, 2)))
    cfg = PlannerConfig(horizon=2, n_headings=3, step_s=130.0, d_safe_m=2000.0, d_star_m=500.0, d_max_m=1500.0)
    problem = dataclasses.replace(base, neighbours=(parked,), planner=cfg)
    fast = plan(problem)
    ref = brute_force(problem)
    assert not fast.feasible and not ref.feasible
    assert same_optimum(problem, fast, ref)
    assert fast.terms["safety_violation_m"] == pytest.approx(ref.terms["safety_violation_m"], rel=1e-12)
    assert fast.terms["safety_violation_m"] == pytest.approx(_naive_cost(problem, fast.indices)[1], rel=1e-9)
    # flee at full speed, straight away from the parked neighbour, on both steps
    assert np.all(fast.controls[:, 1] == 2.0)


def test_larger_team_uses_the_eigenvalue_path_and_stays_exact() -> None:
    problem = _problem(np.random.default_rng(8), n_headings=3, horizon=2, n_neighbours=5)
    fast = plan(problem)
    assert same_optimum(problem, fast, brute_force(problem))
    assert fast.cost == pytest.approx(_naive_cost(problem, fast.indices)[0], rel=1e-9)


def test_degenerate_beliefs_give_finite_plans() -> None:
    rng = np.random.default_rng(9)
    base = _problem(rng, n_headings=3, horizon=2, n_neighbours=2)
    on_target = dataclasses.replace(base, xi=np.zeros(4), P=np.zeros((4, 4)))
    singular = dataclasses.replace(base, P=np.ones((4, 4)))
    for problem in (on_target, singular):
        result = plan(problem)
        assert np.isfinite(result.cost)
        assert all(np.isfinite(v) for v in result.terms.values())
        assert same_optimum(problem, result, brute_force(problem))


def test_plan_is_deterministic() -> None:
    problem = _problem(np.random.default_rng(10), n_headings=5, horizon=3)
    a, b = plan(problem), plan(problem)
    np.testing.assert_array_equal(a.indices, b.indices)
    assert a.cost == b.cost


def test_waypoints_follow_the_turn_then_go_step_model() -> None:
    problem = _problem(np.random.default_rng(12), n_headings=5, horizon=3, n_neighbours=1)
    result = plan(problem)
    x, y = problem.position
    theta = problem.heading
    for (dth, sp), wp in zip(result.controls, result.waypoints, strict=True):
        theta += dth
        x, y = x + sp * 130.0 * math.cos(theta), y + sp * 130.0 * math.sin(theta)
        assert wp == pytest.approx((x, y), abs=1e-9)


# ----------------------------------------------------------------------------- merge graph and layout


def _graph_arrays(g) -> list[np.ndarray]:
    out = []
    for f in dataclasses.fields(g):
        v = getattr(g, f.name)
        out.extend(v if isinstance(v, tuple) else (v,))
    return out


def _assert_graph_unchanged_by(monkeypatch: pytest.MonkeyPatch, key, name: str, value) -> None:
    """The merge graph of ``key`` is array for array (values and dtypes) the same with ``planner.name`` patched."""
    graph.merge_graph.cache_clear()
    before = graph.merge_graph(*key)
    monkeypatch.setattr(graph, name, value)
    graph.merge_graph.cache_clear()
    after = graph.merge_graph(*key)
    graph.merge_graph.cache_clear()
    for a, b in zip(_graph_arrays(before), _graph_arrays(after), strict=True):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    "key",
    [((-2, 0, 2), 0, (-1, 1, 2), 3), ((-4, -2, 0, 2, 4), 12, (-1, 1, 1), 3), ((0,), 1, (-1, -1, 2), 2)],
)
def test_merge_graph_row_keys_match_packed_keys(monkeypatch: pytest.MonkeyPatch, key) -> None:
    _assert_graph_unchanged_by(monkeypatch, key, "_PACK_LIMIT", 0)


@pytest.mark.parametrize(
    "key", [((-2, 0, 2), 0, (-1, 1, 2), 3), ((-4, -2, 0, 2, 4), 8, (-1, 1, 1), 3), ((-1, 1), 0, (-1, -1, 2), 4)]
)
def test_merge_graph_matches_enumerated_sequences(key) -> None:
    m, wrap, speed_class, horizon = key
    graph.merge_graph.cache_clear()
    g = graph.merge_graph(*key)
    graph.merge_graph.cache_clear()
    n_speed = len(speed_class)
    frontier = {0: ((), 0)}
    for h in range(1, horizon + 1):
        seen: dict[tuple, int] = {}
        nxt: dict[int, tuple] = {}
        for node, (steps, head) in frontier.items():
            for u in range(len(m) * n_speed):
                a, s = divmod(u, n_speed)
                head2 = (head + m[a]) % wrap if wrap else head + m[a]
                steps2 = tuple(sorted(steps + ((head2, speed_class[s]),))) if speed_class[s] >= 0 else steps
                child = int(g.child[h][node, u])
                pos = child if h == horizon else int(g.state_pos[h][child])
                digits = [int(d) for d in g.pos_digits[h][pos] if d < g.type_g.size]
                assert tuple((int(g.type_g[d]), int(g.type_speed[d])) for d in digits) == steps2
                assert seen.setdefault(steps2 if h == horizon else (steps2, head2), child) == child
                nxt[child] = (steps2, head2)
        assert len(set(seen.values())) == len(seen) == g.child[h].max() + 1
        assert len(seen) == (g.pos_digits[h].shape[0] if h == horizon else g.state_pos[h].size)
        frontier = nxt


def test_warm_up_builds_each_graph_once_per_process() -> None:
    cfg = PlannerConfig(horizon=3, n_headings=5, step_s=130.0)  # d* = 500 m >= u_max T_o = 260 m: the paper's speeds
    graph.merge_graph.cache_clear()
    warm_up(cfg, ChannelConfig(), 2.0, 0.05)
    built = graph.merge_graph.cache_info().currsize
    warm_up(cfg, ChannelConfig(), 2.0, 0.05)
    info = graph.merge_graph.cache_info()
    # u_e = 0, u_e = u_max, u_e distinct
    assert built == 3 and info.currsize == 3 and info.hits == 3
    graph.merge_graph.cache_clear()
    # d* = 100 m: the ladder's 0.19, 0.38 and 0.77 m/s below u_max; u_e = 0, = each of the 4, distinct
    warm_up(dataclasses.replace(cfg, d_star_m=100.0), ChannelConfig(), 2.0, 0.05)
    assert graph.merge_graph.cache_info().currsize == 6


# ----------------------------------------------------------------------------- control set and speeds


def test_base_speed_eq47_is_clipped() -> None:
    assert base_speed(600.0, 500.0, 0.5, 130.0, 2.0) == pytest.approx(100.0 / 130.0 + 0.5)
    assert base_speed(5000.0, 500.0, 0.5, 130.0, 2.0) == 2.0
    assert base_speed(500.0, 500.0, 0.0, 130.0, 2.0) == 0.0


def test_control_set_shape_and_order() -> None:
    cfg = PlannerConfig(n_headings=7, dtheta_max_rad=math.pi / 2, step_s=130.0)
    cs = control_set(dataclasses.replace(cfg, speed_set="paper"), 1.2, 2.0, 0.05)
    np.testing.assert_allclose(cs.dtheta, np.linspace(-math.pi / 2, math.pi / 2, 7))
    np.testing.assert_allclose(cs.speeds, [0.0, 1.2, 2.0])
    assert cs.controls.shape == (21, 2) and cs.size == 21
    np.testing.assert_allclose(cs.controls[3 * 3 + 2], [0.0, 2.0])
    # the default ladder: the paper's speeds where a u_max step (260 m) is at most d* (500 m) ...
    np.testing.assert_allclose(control_set(cfg, 1.2, 2.0, 0.05).speeds, [0.0, 1.2, 2.0])
    # ... and d*/4, d*/2, d* per step below 0.75 u_max where it is longer (d* = 200 m: 1.54 m/s is left out)
    ladder = control_set(dataclasses.replace(cfg, d_star_m=200.0), 1.2, 2.0, 0.05)
    np.testing.assert_allclose(ladder.speeds, [0.0, 1.2, 50.0 / 130.0, 100.0 / 130.0, 2.0])
    assert ladder.size == 35
    np.testing.assert_allclose(ladder.controls[3 * 5 + 4], [0.0, 2.0])
    single = control_set(PlannerConfig(n_headings=1), 1.0, 2.0, 0.05)
    np.testing.assert_array_equal(single.dtheta, [0.0])


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: control_set(PlannerConfig(horizon=0), 1.0, 2.0, 0.05), "planner.horizon"),
        (lambda: control_set(PlannerConfig(n_headings=0), 1.0, 2.0, 0.05), "planner.n_headings"),
        (lambda: control_set(PlannerConfig(), 1.0, 0.0, 0.05), "u_max"),
        (lambda: control_set(PlannerConfig(), 1.0, 2.0, -0.05), "r_max"),
        (lambda: control_set(PlannerConfig(), -0.1, 2.0, 0.05), "u_e"),
        (lambda: control_set(PlannerConfig(), 2.5, 2.0, 0.05), "u_e"),
        (lambda: control_set(PlannerConfig(dtheta_max_rad=1.0, step_s=10.0), 1.0, 2.0, 0.05), "planner.dtheta_max_rad"),
        (lambda: ControlSet(dtheta=np.zeros(0), speeds=np.array([0.0, 1.0])), "dtheta"),
        (lambda: ControlSet(dtheta=np.zeros(1), speeds=np.zeros(0)), "speeds"),
        (lambda: ControlSet(dtheta=np.zeros(1), speeds=np.array([0.0, -1.0])), "speeds"),
        (lambda: ControlSet(dtheta=np.array([-1.0, 0.2, 1.0]), speeds=np.array([1.0])), "dtheta"),
        (lambda: base_speed(100.0, 500.0, 0.0, 130.0, 0.0), "u_max"),
        (lambda: sigma_points(np.zeros(4), np.eye(4), 1.0), "w0"),
        (lambda: sigma_points(np.zeros(3), np.eye(4), 0.3), "xi"),
    ],
)
def test_invalid_parameters_name_the_parameter_and_range(call, name: str) -> None:
    with pytest.raises(ValueError, match=name.replace(".", r"\.")) as err:
        call()
    assert "must" in str(err.value)


def test_config_error_for_horizon_zero_in_a_problem() -> None:
    problem = _problem(np.random.default_rng(1), horizon=1)
    with pytest.raises(ConfigError, match=r"planner\.horizon must be in \[1, 8\]"):
        dataclasses.replace(problem, planner=PlannerConfig(horizon=0))


def test_neighbour_sequence_must_match_the_horizon() -> None:
    problem = _problem(np.random.default_rng(1), horizon=2, n_neighbours=1)
    short = Neighbour(id=1, position=(0.0, 500.0), heading=0.0, sequence=np.zeros((1, 2)))
    with pytest.raises(ValueError, match="planner.horizon"):
        dataclasses.replace(problem, neighbours=(short,))


# ----------------------------------------------------------------------------- constraints along the first leg


def _crossing_problem(leg: str, *, d_star: float = 500.0, target=(30.0, 5000.0)) -> PlanProblem:
    """Own AUV at the origin facing east (one heading, speeds 0 and 1 m/s, T_o = 60 s, d_S = 25 m) and a
    neighbour at (60, 10) m heading west at 0.5 m/s: going east, the two pass 10 m apart, though they end
    31.6 m apart; staying, the neighbour stops 31.6 m away."""
    cfg = dataclasses.replace(
        PlannerConfig(),
        horizon=1,
        step_s=60.0,
        n_headings=1,
        d_safe_m=25.0,
        d_star_m=d_star,
        d_max_m=10_000.0,
        leg_constraint=leg,
        speed_set="paper",
    )
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
        assert _naive_cost(problem, np.array([east]))[1] == pytest.approx(expected, abs=1e-9)
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
    planner = dataclasses.replace(
        PlannerConfig(),
        horizon=1,
        step_s=60.0,
        n_headings=3,
        d_safe_m=25.0,
        d_star_m=30.0,
        speed_set="paper",
        leg_constraint=leg,
    )
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
