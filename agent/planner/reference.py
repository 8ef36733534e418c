"""The planner's cost written plainly from the paper, and the brute-force search that uses it.

This is the readable reference of eqs. (34)-(38) and (50) (with the departures listed in
docs/planner.md). It is written from the equations, not from the fast path of
:mod:`agent.planner.cost`; the property tests compare the two on every generated example, and
:func:`brute_force` uses this cost, so checking ``plan == brute_force`` checks both the search
and the fast cost. Vectorised over a batch of N own positions (sequences), nothing else.

Stage cost at step h = 1..H of the own position p_h (eq. 38), averaged over the sigma points
xi^(l) with their weights omega^(l) (eqs. 30, 32-33), the target at step h being
p^(l) + h T_o v^(l) (eq. 50):

    sum_l omega^(l) [ alpha / max(sigma_min(Phi^(l)), SIGMA_FLOOR)                (eqs. 34-35)
                      + (1 - alpha) d^(l) / d*                                     (eq. 36)
                      + c_s (max(0, d* - d^(l)) / d* + max(0, d^(l) - d_M) / d_M)  (eq. 50, soft)
                      + [h = H] w_T |d^(l) - d*| / d* ]                             (eq. 38, terminal)
    + gamma k / max(lambda_2(L(p_h, q_1,h, ..., q_k,h)), LAMBDA_FLOOR)            (eqs. 26, 37)
      (or, planner.connectivity = "formation", gamma sum_j |d_j,h - d_j,0| / d*)

with d^(l) = ||p^(l) - p_h||, Phi^(l) the bearing matrix of eq. (34) of all agents (own and
neighbours q_j,h) to the sigma point, L the SNR Laplacian of eqs. (22)-(26). A bearing is
undefined when an agent is within ``MIN_BEARING_RANGE_M`` of the sigma point: sigma_min is
then 0. A lone agent has no connectivity term. The safety violation (eq. 50, hard) is
sum_j max(0, d_S - ||p_h - q_j,h||) in metres.

With ``planner.leg_constraint = "straight"`` step 1 is also checked along its leg, the
one the vehicle executes before it plans again: own vehicle, neighbours and sigma points move
linearly from their start positions to their positions after step 1, and with c the closest
approach over that leg and s the distance at its start, d* - d^(l) becomes
max(d* - d^(l), min(d*, s^(l)) - c^(l)) in the penalty and d_S - ||p_1 - q_j,1|| becomes
max(d_S - ||p_1 - q_j,1||, min(d_S, s_j) - c_j) in the violation (a vehicle already inside need
not get closer than it is). ``"first"`` does the same with d_S and d* grown by the margin
u dtheta^2 / (2 r_max) by which the flown leg can stray from the straight one (:func:`turn_margin`); with
``"arc"`` the own vehicle flies that leg as guidance executes it (a turn at r_max at the planned speed,
then straight, :func:`executed_leg`); ``"first-arc"`` (the default) is ``"first"`` and, for d_S, the larger
of its dip and the flown leg's.
"""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.planner.problem import (
    ARC_CHORDS,
    HALF_TURN_TOL_RAD,
    LAMBDA_FLOOR,
    LEG_TOL_M,
    MIN_BEARING_RANGE_M,
    SIGMA_FLOOR,
    TERMS,
    Plan,
    PlanProblem,
    sigma_points,
)
from auv_swarm.contract import acoustics
from auv_swarm.contract.geometry import least_singular_value

_CHUNK = 1 << 15  # positions evaluated at once by brute_force (bounds its memory)


def algebraic_connectivity(positions: np.ndarray, channel: object, link: object | None = None) -> np.ndarray:
    """lambda_2 of the SNR Laplacian of eqs. (22)-(26) for agents at ``positions`` (..., n, 2) m, by eigvalsh;
    ``link`` a physical ocean's link model (None: the paper's budget)."""
    lap = acoustics.snr_laplacian(positions, channel, link)
    return np.linalg.eigvalsh(lap)[..., 1]


def neighbour_paths(problem: PlanProblem) -> np.ndarray:
    """Neighbours' predicted positions (H, k, 2) in m after each step, turn then go."""
    H, T = problem.planner.horizon, problem.planner.step_s
    out = np.zeros((H, len(problem.neighbours), 2))
    for j, nb in enumerate(problem.neighbours):
        x, y = nb.position
        heading = nb.heading
        for h, (dtheta, speed) in enumerate(nb.sequence.tolist()):
            heading += dtheta
            x, y = x + speed * T * math.cos(heading), y + speed * T * math.sin(heading)
            out[h, j] = (x, y)
    return out


def own_paths(problem: PlanProblem, indices: np.ndarray) -> np.ndarray:
    """Own positions (N, H, 2) in m after each step of the control index sequences ``indices`` (N, H)."""
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, problem.planner.horizon)
    table = problem.controls.controls
    T = problem.planner.step_s
    heading = np.full(idx.shape[0], problem.heading)
    x = np.full(idx.shape[0], float(problem.position[0]))
    y = np.full(idx.shape[0], float(problem.position[1]))
    out = np.empty((idx.shape[0], idx.shape[1], 2))
    for h in range(idx.shape[1]):
        dtheta, speed = table[idx[:, h], 0], table[idx[:, h], 1]
        heading = heading + dtheta
        x = x + speed * T * np.cos(heading)
        y = y + speed * T * np.sin(heading)
        out[:, h, 0], out[:, h, 1] = x, y
    return out


def leg_dip(
    start: np.ndarray, end: np.ndarray, other_start: np.ndarray, other_end: np.ndarray, limit: float
) -> np.ndarray:
    """How much closer than min(limit, distance at the start) (m, N,) two points come over one step, moving
    linearly from ``start`` to ``end`` (N, 2) and from ``other_start`` to ``other_end`` (2,): the minimum of
    the quadratic |a + s b|^2 on [0, 1]; 0 below ``LEG_TOL_M`` (rounding)."""
    a = start - other_start
    b = (end - start) - (other_end - other_start)
    bb = np.sum(b * b, axis=-1)
    s = np.clip(-np.sum(a * b, axis=-1) / np.where(bb > 0.0, bb, 1.0), 0.0, 1.0)
    closest = np.linalg.norm(a + s[..., None] * b, axis=-1)
    dip = np.minimum(np.linalg.norm(a, axis=-1), limit) - closest
    return np.where(dip > LEG_TOL_M, dip, 0.0)


def executed_leg(start: tuple[float, float], heading: float, end: tuple[float, float], step_s: float, r_max: float):
    """The first step flown as guidance executes it, to the planned end ``end`` (m): from ``heading`` (rad) the
    vehicle turns towards the planned heading at ``r_max`` (rad/s) at the planned speed, then runs straight
    (eq. 1); a half turn to the right (:data:`HALF_TURN_TOL_RAD`). Nodes [(t s, x m, y m)]: ARC_CHORDS + 1
    equally spaced in turn angle, then the end at ``step_s``."""
    x0, y0 = start
    speed = math.hypot(end[0] - x0, end[1] - y0) / step_s
    planned = math.atan2(end[1] - y0, end[0] - x0)
    turn = (planned - heading + math.pi) % (2.0 * math.pi) - math.pi if speed > 0.0 else 0.0
    if abs(turn) > math.pi - HALF_TURN_TOL_RAD:  # a half turn, +pi or -pi: to the right whichever way it rounded
        turn = -math.pi
    side = -1.0 if turn < 0.0 else 1.0
    turn_s = abs(turn) / r_max
    nodes = []
    for m in range(ARC_CHORDS + 1):
        t = turn_s * m / ARC_CHORDS
        psi = heading + side * r_max * t
        # integral of speed * (cos psi, sin psi) dt from the start, psi turning at side * r_max
        x = x0 + side * speed / r_max * (math.sin(psi) - math.sin(heading))
        y = y0 - side * speed / r_max * (math.cos(psi) - math.cos(heading))
        nodes.append((t, x, y))
    _, x, y = nodes[-1]
    left = step_s - turn_s
    nodes.append((step_s, x + speed * left * math.cos(planned), y + speed * left * math.sin(planned)))
    return nodes


def executed_leg_dip(
    problem: PlanProblem, end: np.ndarray, other_start: np.ndarray, other_end: np.ndarray, limit: float
) -> np.ndarray:
    """:func:`leg_dip` with the own vehicle on its :func:`executed_leg` to each planned end (N, 2), the other
    point moving linearly over the step; per chord both move linearly (the quadratic's minimum again)."""
    start = (float(problem.position[0]), float(problem.position[1]))
    step_s = problem.planner.step_s
    out = np.zeros(end.shape[0])
    for i, (ex, ey) in enumerate(end):
        nodes = executed_leg(start, float(problem.heading), (float(ex), float(ey)), step_s, problem.controls.r_max)
        rel = [np.array([x, y]) - (other_start + (other_end - other_start) * (t / step_s)) for t, x, y in nodes]
        closest = math.inf
        for a, a_next in zip(rel[:-1], rel[1:], strict=True):
            b = a_next - a
            bb = float(b @ b)
            s = min(max(-float(a @ b) / bb, 0.0), 1.0) if bb > 0.0 else 0.0
            closest = min(closest, float(np.linalg.norm(a + s * b)))
        dip = min(float(np.linalg.norm(np.asarray(start) - other_start)), limit) - closest
        out[i] = dip if dip > LEG_TOL_M else 0.0
    return out


def first_leg_dip(
    problem: PlanProblem,
    own: np.ndarray,
    other_start: np.ndarray,
    other_end: np.ndarray,
    limit: float,
    safety: bool = False,
) -> np.ndarray:
    """The first leg's dip (m, N,) for ``planner.leg_constraint``: straight (:func:`leg_dip`), with the limit
    grown by the turn's margin (``"first"``, :func:`turn_margin`), or flown (``"arc"``, :func:`executed_leg_dip`);
    ``"first-arc"`` is ``"first"``, and for d_S (``safety``) the larger of that and the flown leg's dip; the
    margin and the arc need a finite r_max (:class:`~auv_swarm.agent.planner.problem.LegRule`)."""
    rule = problem.leg_rule
    if rule.flown:
        return executed_leg_dip(problem, own, other_start, other_end, limit)
    start = np.broadcast_to(np.asarray(problem.position, dtype=float), own.shape)
    grown = limit
    if rule.turn_margin:
        grown = limit + np.array([turn_margin(problem, (float(x), float(y))) for x, y in own])
    dip = leg_dip(start, own, other_start, other_end, grown)
    if rule.flown_safety and safety:
        dip = np.maximum(dip, executed_leg_dip(problem, own, other_start, other_end, limit))
    return dip


def turn_margin(problem: PlanProblem, end: tuple[float, float]) -> float:
    """How far (m) the flown first leg to the planned end ``end`` can be from the straight one: the vehicle turns
    by dtheta at r_max at the planned speed u, so it strays at most u dtheta^2 / (2 r_max) (docs/planner.md)."""
    x0, y0 = float(problem.position[0]), float(problem.position[1])
    speed = math.hypot(end[0] - x0, end[1] - y0) / problem.planner.step_s
    if speed == 0.0:
        return 0.0
    turn = (math.atan2(end[1] - y0, end[0] - x0) - problem.heading + math.pi) % (2.0 * math.pi) - math.pi
    return speed * turn * turn / (2.0 * problem.controls.r_max)


def stage_terms(problem: PlanProblem, h: int, own: np.ndarray, neighbours_h: np.ndarray) -> dict[str, np.ndarray]:
    """The terms of eq. (38) at step h (1..H) for own positions ``own`` (N, 2), each (N,), and the safety violation.

    ``neighbours_h`` (k, 2) are the neighbours' positions at step h (:func:`neighbour_paths`).
    """
    cfg = problem.planner
    points, weights = sigma_points(problem.xi, problem.P, cfg.w0)
    n_pos = own.shape[0]
    agents = np.concatenate([own[:, None, :], np.broadcast_to(neighbours_h, (n_pos, *neighbours_h.shape))], axis=1)
    terms = {name: np.zeros(n_pos) for name in TERMS}
    worst_short = np.zeros(n_pos)
    worst_over = np.zeros(n_pos)
    floor_m = np.zeros(n_pos)  # inside d* of the nearest sigma point (m): the fallback's second violation
    on_leg = h == 1 and problem.leg_rule.on_leg
    for point, weight in zip(points, weights, strict=True):
        target = point[:2] + h * cfg.step_s * point[2:]
        to_target = target[None, None, :] - agents
        ranges = np.hypot(to_target[..., 0], to_target[..., 1])
        bearings = np.arctan2(to_target[..., 1], to_target[..., 0])
        sigma = least_singular_value(bearings)
        sigma = np.where(np.any(ranges < MIN_BEARING_RANGE_M, axis=1), 0.0, sigma)
        d = ranges[:, 0]
        terms["geometry"] += weight * (cfg.alpha / np.maximum(sigma, SIGMA_FLOOR))
        terms["distance"] += weight * ((1.0 - cfg.alpha) * d / cfg.d_star_m)
        short_m = np.maximum(cfg.d_star_m - d, 0.0)
        if on_leg:  # along the first leg, from the start, where the target is at point[:2]
            short_m = np.maximum(short_m, first_leg_dip(problem, own, point[:2], target, cfg.d_star_m))
        floor_m = np.maximum(floor_m, short_m)
        short = short_m / cfg.d_star_m
        over = np.maximum(d - cfg.d_max_m, 0.0) / cfg.d_max_m
        if cfg.range_constraint == "worst":  # eq. (50) at the sigma point violating it most
            worst_short = np.maximum(worst_short, short)
            worst_over = np.maximum(worst_over, over)
        else:
            terms["penalty"] += weight * (cfg.soft_penalty * (short + over))
        if h == cfg.horizon:
            terms["terminal"] += weight * (cfg.terminal_weight * np.abs(d - cfg.d_star_m) / cfg.d_star_m)
    if cfg.range_constraint == "worst":
        terms["penalty"] = cfg.soft_penalty * (worst_short + worst_over)
    terms["floor_shortfall_m"] = floor_m
    if neighbours_h.shape[0] > 0:
        gaps = np.hypot(*(agents[:, 1:, :] - agents[:, :1, :]).transpose(2, 0, 1))
        if cfg.connectivity in ("formation", "topology"):
            start = np.array([nb.position for nb in problem.neighbours], dtype=float)
            gaps0 = np.hypot(*(start - problem.position[None, :]).T)
            if problem.anchor_m is not None:
                gaps0 = np.array(problem.anchor_m, dtype=float)
            terms["connectivity"] = cfg.gamma * np.sum(np.abs(gaps - gaps0[None, :]), axis=1) / cfg.d_star_m
        else:
            lam = algebraic_connectivity(agents, problem.channel, problem.link)
            # eq. (37): the sum over the |N_i| neighbours of the same graph's 1 / lambda_2
            terms["connectivity"] = cfg.gamma * neighbours_h.shape[0] / np.maximum(lam, LAMBDA_FLOOR)
        short = np.maximum(cfg.d_safe_m - gaps, 0.0)
        if on_leg:
            for j, nb in enumerate(problem.neighbours):
                q0 = np.asarray(nb.position, dtype=float)
                short[:, j] = np.maximum(
                    short[:, j], first_leg_dip(problem, own, q0, neighbours_h[j], cfg.d_safe_m, True)
                )
        terms["safety_violation_m"] = np.sum(short, axis=1)
    else:
        terms["safety_violation_m"] = np.zeros(n_pos)
    return terms


def stage_cost(problem: PlanProblem, h: int, own: np.ndarray, neighbours_h: np.ndarray) -> tuple[np.ndarray, ...]:
    """Stage cost of eq. (38) (N,) at step h for own positions (N, 2), and the safety violation (N,) in m."""
    terms = stage_terms(problem, h, own, neighbours_h)
    cost = terms["geometry"] + terms["distance"] + terms["connectivity"] + terms["penalty"] + terms["terminal"]
    return cost, terms["safety_violation_m"]


def sequence_cost(problem: PlanProblem, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cost of eq. (38) (N,) of the control index sequences ``indices`` (N, H), and their total safety violation (m)."""
    own = own_paths(problem, indices)
    nbs = neighbour_paths(problem)
    total = np.zeros(own.shape[0])
    viol = np.zeros(own.shape[0])
    for h in range(1, problem.planner.horizon + 1):
        cost, v = stage_cost(problem, h, own[:, h - 1], nbs[h - 1])
        total += cost
        viol += v
    return total, viol


def sequence_violation(problem: PlanProblem, indices: np.ndarray) -> float:
    """Total violation (m) of one sequence (H,) that the infeasible case minimises: d_S's plus d*'s shortfall."""
    own = own_paths(problem, np.asarray(indices)[None, :])
    nbs = neighbour_paths(problem)
    total = 0.0
    for h in range(1, problem.planner.horizon + 1):
        terms = stage_terms(problem, h, own[:, h - 1], nbs[h - 1])
        total += float(terms["safety_violation_m"][0] + terms["floor_shortfall_m"][0])
    return total


def make_plan(problem: PlanProblem, indices: np.ndarray, nodes: int) -> Plan:
    """The :class:`Plan` of one index sequence (H,), its cost and terms from this reference."""
    idx = np.asarray(indices, dtype=np.int64).reshape(-1)
    own = own_paths(problem, idx[None, :])[0]
    nbs = neighbour_paths(problem)
    per_step = [stage_terms(problem, h, own[h - 1 : h], nbs[h - 1]) for h in range(1, problem.planner.horizon + 1)]
    terms = {name: float(sum(float(s[name][0]) for s in per_step)) for name in (*TERMS, "safety_violation_m")}
    cost = float(sum(sum(float(s[name][0]) for name in TERMS) for s in per_step))
    return Plan(
        controls=problem.controls.controls[idx],
        indices=idx,
        cost=cost,
        terms=terms,
        feasible=terms["safety_violation_m"] == 0.0,
        waypoints=own,
        nodes=nodes,
    )


def brute_force(problem: PlanProblem) -> Plan:
    """Reference search: every one of the |U|^H sequences, each costed with the reference cost of eq. (38).

    The cost is a sum over the steps of a stage cost that depends only on the own position
    p_h = p_0 + sum_{j <= h} T_o u_j [cos theta_j, sin theta_j], so each distinct position is
    costed once per step and every sequence adds the stage costs of its positions. Turns are
    integer multiples of the grid step of eq. (48), so theta_j = theta_0 + G_j * step with G_j an
    integer; p_h is summed over the (G_j, u_j) of the moving steps in sorted order, so sequences
    with the same steps in another order reach the same float position. Among exactly equal
    costs the lexicographically smallest index sequence wins; when every sequence violates the
    safety distance, the least total violation of d_S and of the range floor d* together (m) wins, then the
    least cost.
    """
    cfg, cs = problem.planner, problem.controls
    H, n_u, n_speed = cfg.horizon, cs.size, cs.speeds.size
    n_head = cs.dtheta.size
    grid_step = float(cs.dtheta[-1]) / (n_head - 1) if n_head > 1 else 0.0
    turn = np.repeat(np.arange(n_head, dtype=np.int32) * 2 - (n_head - 1), n_speed)  # dtheta of control u, grid steps
    speed_of = np.tile(np.arange(n_speed, dtype=np.int32), n_head)
    moving = cs.speeds > 0.0
    nbs = neighbour_paths(problem)
    # per sequence (rows, C order = lexicographic): cumulative turn G, and its moving steps as sorted codes
    g_max = H * (n_head - 1)
    n_codes = (2 * g_max + 1) * n_speed
    if (n_codes + 1) ** H >= 2**63:
        raise ValueError(f"brute_force: {n_u}^{H} sequences are too many to enumerate")
    g = np.zeros(1, dtype=np.int32)
    steps = np.zeros((1, 0), dtype=np.int32)
    total = np.zeros(1)
    viol = np.zeros(1)
    both = np.zeros(1)  # safety violation plus the d* floor's shortfall (m), for the infeasible case
    nodes = 0
    for h in range(1, H + 1):
        g = (g[:, None] + turn[None, :]).reshape(-1)
        code = np.where(moving[speed_of], (g.reshape(-1, n_u) + g_max) * n_speed + speed_of, n_codes).reshape(-1)
        grown = np.empty((g.size, h), dtype=np.int32)
        grown[:, : h - 1] = np.repeat(steps, n_u, axis=0)
        grown[:, h - 1] = code  # n_codes: no motion
        grown.sort(axis=1)
        steps = grown
        key = np.zeros(steps.shape[0], dtype=np.int64)
        for j in range(h):
            key *= n_codes + 1
            key += steps[:, j]
        uniq, first, inverse = np.unique(key, return_index=True, return_inverse=True)
        own = np.tile(np.asarray(problem.position, dtype=float), (uniq.size, 1))
        for j in range(h):
            c = steps[first, j]
            go = c < n_codes
            heading = problem.heading + (c[go] // n_speed - g_max) * grid_step
            dist = cs.speeds[c[go] % n_speed] * cfg.step_s
            own[go, 0] += dist * np.cos(heading)
            own[go, 1] += dist * np.sin(heading)
        cost, v, f = np.empty(uniq.size), np.empty(uniq.size), np.empty(uniq.size)
        for lo in range(0, uniq.size, _CHUNK):
            terms = stage_terms(problem, h, own[lo : lo + _CHUNK], nbs[h - 1])
            cost[lo : lo + _CHUNK] = sum(terms[name] for name in TERMS)
            v[lo : lo + _CHUNK] = terms["safety_violation_m"]
            f[lo : lo + _CHUNK] = terms["floor_shortfall_m"]
        total = np.repeat(total, n_u) + cost[inverse]
        viol = np.repeat(viol, n_u) + v[inverse]
        both = np.repeat(both, n_u) + (v + f)[inverse]
        nodes += g.size
    feasible = viol == 0.0
    if np.any(feasible):
        flat = int(np.argmin(np.where(feasible, total, np.inf)))
    else:  # the least violation of d_S and d* together (m), then the least cost
        flat = int(np.argmin(np.where(both == both.min(), total, np.inf)))
    indices = np.array(np.unravel_index(flat, (n_u,) * H), dtype=np.int64)
    return make_plan(problem, indices, nodes)


def same_optimum(problem: PlanProblem, got: Plan, ref: Plan, rel: float = 1e-9) -> bool:
    """Whether ``got`` is an optimum as good as the reference ``ref`` (e.g. ``brute_force(problem)``).

    The costs agree within ``rel`` (relative), both plans are feasible or neither is, and the
    sequences are the same, unless the reference cost of ``got``'s sequence is within ``rel``
    of ``ref``'s too (two best sequences whose costs differ only by rounding).
    """
    if got.feasible != ref.feasible or abs(got.cost - ref.cost) > rel * max(abs(ref.cost), 1e-300):
        return False
    if np.array_equal(got.indices, ref.indices):
        return True
    cost, viol = sequence_cost(problem, got.indices[None, :])
    if abs(float(viol[0]) - ref.terms["safety_violation_m"]) > rel * max(ref.terms["safety_violation_m"], 1.0):
        if ref.feasible:
            return False
        # infeasible: both minimise d_S's and d*'s violation together, which may split differently
        got_both, ref_both = (sequence_violation(problem, p.indices) for p in (got, ref))
        if abs(got_both - ref_both) > rel * max(ref_both, 1.0):
            return False
    return abs(float(cost[0]) - ref.cost) <= rel * max(abs(ref.cost), 1e-300)
