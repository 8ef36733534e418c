"""Fast evaluation of the stage cost of eq. (38) for batches of own positions, and the search's lower bounds.

The same cost as :mod:`agent.planner.reference` (the property tests compare them on every
generated example), arranged for the branch and bound: per step h, per sigma point, per
candidate position, with the parts that do not depend on the own position precomputed in
:class:`agent.planner.context.Context`.
"""

from __future__ import annotations

import numpy as np

from auv_swarm.agent.planner.context import Context, fiedler, link_weight, link_weight_bound
from auv_swarm.agent.planner.problem import (
    ARC_CHORDS,
    HALF_TURN_TOL_RAD,
    LAMBDA_FLOOR,
    LEG_TOL_M,
    MIN_BEARING_RANGE_M,
    SIGMA_FLOOR,
    TERMS,
)

_R2_MIN = MIN_BEARING_RANGE_M**2

# ----------------------------------------------------------------------------- stage cost
# Layout: one step h (an int) at a time; arrays (L, N) hold a value per sigma point (rows) and
# candidate own position (columns), arrays (k, N) one per neighbour and position.


def _wsum(ctx: Context, per_sigma: np.ndarray) -> np.ndarray:
    """UT-weighted sum over the sigma points (eq. 30) of an (L, N) array: (N,)."""
    return ctx.w @ per_sigma


def _target_ranges(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Own range (L, N) in m to every sigma point at step h."""
    dx = px[None, :] - ctx.tx[h][:, None]
    dy = py[None, :] - ctx.ty[h][:, None]
    return np.sqrt(dx * dx + dy * dy)


def leg_closest(ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
    """Closest approach min over s in [0, 1] of |a + s b| (m), element-wise (broadcast); |a| exactly when s = 0.

    Two points moving linearly over one step (the step model of eqs. 46-49 for the own vehicle,
    a neighbour and a sigma point of the target) are ``a`` apart at its start and ``a + b`` at its end.
    """
    bb = bx * bx + by * by
    s = np.clip(-(ax * bx + ay * by) / np.where(bb > 0.0, bb, 1.0), 0.0, 1.0)
    return np.hypot(ax + s * bx, ay + s * by)


def _first_leg(ctx: Context, h: int) -> bool:
    """Whether step h's constraints are also checked along its leg (``planner.leg_constraint`` not "ends", h = 1)."""
    return h == 1 and ctx.leg.on_leg


def _leg_dip(
    ctx: Context,
    x0: np.ndarray,
    y0: np.ndarray,
    x1: np.ndarray,
    y1: np.ndarray,
    limit: float,
    px: np.ndarray,
    py: np.ndarray,
    safety: bool = False,
) -> np.ndarray:
    """How much closer than min(limit, its distance now) the own vehicle comes to each of m points on the
    first leg (m, N), in m: the points move linearly from (x0, y0) to (x1, y1) (m,), the vehicle from
    ``ctx.p0`` to (px, py) (N,), straight or (``ctx.leg.flown``) as :func:`executed_leg` flies it; with
    ``ctx.leg.turn_margin`` the limit grows by :func:`turn_margin`; for d_S (``safety``) with ``ctx.leg.flown_safety``,
    the larger of that and the flown leg's dip. 0 below ``LEG_TOL_M`` (rounding)."""
    ax = (ctx.p0[0] - x0)[:, None]
    ay = (ctx.p0[1] - y0)[:, None]
    now = np.hypot(ax, ay)
    if ctx.leg.flown:
        closest = closest_on_executed_leg(ctx, x0, y0, x1, y1, px, py)
    else:
        bx = (px - ctx.p0[0])[None, :] - (x1 - x0)[:, None]
        by = (py - ctx.p0[1])[None, :] - (y1 - y0)[:, None]
        closest = leg_closest(ax, ay, bx, by)
    grown = limit + turn_margin(ctx, px, py)[None, :] if ctx.leg.turn_margin else limit
    dip = np.minimum(now, grown) - closest
    if safety and ctx.leg.flown_safety:
        dip = np.maximum(dip, np.minimum(now, limit) - closest_on_executed_leg(ctx, x0, y0, x1, y1, px, py))
    return np.where(dip > LEG_TOL_M, dip, 0.0)


def _first_turn(ctx: Context, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, ...]:
    """The first control that reaches (px, py) (N,) from ``ctx.p0``: speed u (m/s), planned heading chi and the
    turn to it from ``ctx.theta0`` in [-pi, pi) (rad; 0 at u = 0; a half turn is -pi, :data:`HALF_TURN_TOL_RAD`)."""
    dx, dy = px - ctx.p0[0], py - ctx.p0[1]
    u = np.hypot(dx, dy) / ctx.T
    chi = np.arctan2(dy, dx)
    turn = np.where(u > 0.0, np.mod(chi - ctx.theta0 + np.pi, 2.0 * np.pi) - np.pi, 0.0)
    return u, chi, np.where(np.abs(turn) > np.pi - HALF_TURN_TOL_RAD, -np.pi, turn)


def turn_margin(ctx: Context, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """How far (m, N,) the flown first leg can stray from the planned one (``planner.leg_constraint = "first"``):
    u dtheta^2 / (2 r_max), the bound of ``guidance.step_position_bound`` without its tick term (docs/planner.md)."""
    u, _, turn = _first_turn(ctx, px, py)
    return u * turn * turn / (2.0 * ctx.r_max)


def executed_leg(ctx: Context, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, ...]:
    """The first step as the vehicle flies it to the planned end (px, py) (N,) (``planner.leg_constraint = "arc"``):
    it turns from ``ctx.theta0`` towards the planned heading at r_max, at the planned speed, then runs straight
    (guidance, eq. 1). Returns node times (S, N) in s and positions x, y (S, N) in m, S = ARC_CHORDS + 2:
    the turn's ARC_CHORDS chords, then the straight part to t = T_o."""
    u, chi, turn = _first_turn(ctx, px, py)
    side = np.where(turn < 0.0, -1.0, 1.0)
    tau = np.abs(turn) / ctx.r_max
    frac = np.linspace(0.0, 1.0, ARC_CHORDS + 1)[:, None]
    t_turn = frac * tau[None, :]
    psi = ctx.theta0 + side * ctx.r_max * t_turn
    radius = side * u / ctx.r_max
    xs = ctx.p0[0] + radius * (np.sin(psi) - np.sin(ctx.theta0))
    ys = ctx.p0[1] - radius * (np.cos(psi) - np.cos(ctx.theta0))
    rest = ctx.T - tau
    x_end = xs[-1] + u * rest * np.cos(chi)
    y_end = ys[-1] + u * rest * np.sin(chi)
    t = np.vstack([t_turn, np.full((1, px.size), ctx.T)])
    return t, np.vstack([xs, x_end[None, :]]), np.vstack([ys, y_end[None, :]])


def closest_on_executed_leg(
    ctx: Context, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray, px: np.ndarray, py: np.ndarray
) -> np.ndarray:
    """Closest approach (m, N) in m of the executed first leg (:func:`executed_leg`) to m points moving linearly
    from (x0, y0) to (x1, y1) over the step: per chord both move linearly, so :func:`leg_closest` is exact."""
    t, xs, ys = executed_leg(ctx, px, py)
    f = (t / ctx.T)[:, None, :]
    rx = xs[:, None, :] - (x0[None, :, None] + (x1 - x0)[None, :, None] * f)
    ry = ys[:, None, :] - (y0[None, :, None] + (y1 - y0)[None, :, None] * f)
    return np.min(leg_closest(rx[:-1], ry[:-1], rx[1:] - rx[:-1], ry[1:] - ry[:-1]), axis=0)


def _short_of_dstar_on_leg(ctx: Context, px: np.ndarray, py: np.ndarray, r: np.ndarray) -> np.ndarray:
    """How far (m) the own vehicle is inside d* of each sigma point (L, N) on the first step: at its end and
    along its leg, where a vehicle already inside d* at the start need not get closer than it is:
    max(0, d* - d_end, min(d*, d_start) - d_closest)."""
    d_star = ctx.cfg.d_star_m
    dip = _leg_dip(ctx, ctx.tx[0], ctx.ty[0], ctx.tx[1], ctx.ty[1], d_star, px, py)
    return np.maximum(np.maximum(d_star - r, 0.0), dip)


# The range-cost family: every range term of eq. (38) at ranges r (m), per element. The search's
# bounds (below) evaluate the same functions at clipped ranges.


def _distance_cost(ctx: Context, r: np.ndarray) -> np.ndarray:
    """Distance term of eq. (36), weighted: (1 - alpha) r / d*."""
    return r * ctx.c_dist


def _penalty_cost(ctx: Context, r: np.ndarray, short: np.ndarray | None = None) -> np.ndarray:
    """Soft range constraint of eq. (50): c_s (max(0, d* - r) / d* + max(0, r - d_M) / d_M); ``short`` (m)
    replaces max(0, d* - r) where the first leg counts too."""
    cfg = ctx.cfg
    if short is None:
        short = np.maximum(cfg.d_star_m - r, 0.0)
    return cfg.soft_penalty * (short * ctx.inv_ds + np.maximum(r - cfg.d_max_m, 0.0) * ctx.inv_dm)


def _soft_range_cost(ctx: Context, r: np.ndarray) -> np.ndarray:
    """Distance (eq. 36) plus the soft range penalty (eq. 50)."""
    return _distance_cost(ctx, r) + _penalty_cost(ctx, r)


def _terminal_cost(ctx: Context, r: np.ndarray) -> np.ndarray:
    """Terminal term of eq. (38), normalised and weighted: w_T |r - d*| / d*, per element."""
    return np.abs(r - ctx.cfg.d_star_m) * ctx.c_term


def _range_cost(ctx: Context, r: np.ndarray, last: bool) -> np.ndarray:
    """The range terms at ranges ``r`` (m): :func:`_soft_range_cost`, plus :func:`_terminal_cost` at step H."""
    v = _soft_range_cost(ctx, r)
    return v + _terminal_cost(ctx, r) if last else v


def floor_shortfall(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """How far (m, N,) the own position at step h is inside d* of the nearest sigma point (eq. 50's range floor),
    along the first leg too where it is checked; what the infeasible fallback of the search adds to the safety
    violation, so that d_S and d* are traded metre for metre when d_S cannot be met."""
    r = _target_ranges(ctx, h, px, py)
    if _first_leg(ctx, h):
        return np.max(_short_of_dstar_on_leg(ctx, px, py, r), axis=0)
    return np.maximum(ctx.cfg.d_star_m - np.min(r, axis=0), 0.0)


def _worst_penalty(ctx: Context, r: np.ndarray, short: np.ndarray | None = None) -> np.ndarray:
    """Soft range constraint of eq. (50) at the sigma point that violates it most (N,), ``range_constraint = "worst"``.

    The nearest sigma point decides the d* edge and the farthest the d_M edge: d* <= d <= d_M must
    hold for every point of the belief, not only on its weighted mean. With non-negative weights
    this is at least the weighted mean of the penalty, so the search's bounds (below, on the
    weighted mean) stay lower bounds. ``short`` (L, N, m) replaces max(0, d* - r) where the first leg
    counts too.
    """
    cfg = ctx.cfg
    if short is None:
        near = np.maximum(cfg.d_star_m - np.min(r, axis=0), 0.0) * ctx.inv_ds
    else:
        near = np.max(short, axis=0) * ctx.inv_ds
    over = np.maximum(np.max(r, axis=0) - cfg.d_max_m, 0.0) * ctx.inv_dm
    return cfg.soft_penalty * (near + over)


def range_part(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Distance + soft penalty + terminal cost (N,) at step h, UT-weighted (eq. 30) but for a ``"worst"`` penalty."""
    if _first_leg(ctx, h):
        dist, pen, term = _range_terms(ctx, h, px, py)
        return (dist + pen) + term
    r = _target_ranges(ctx, h, px, py)
    if not ctx.worst:
        return _wsum(ctx, _range_cost(ctx, r, h == ctx.H))
    v = _distance_cost(ctx, r)
    if h == ctx.H:
        v = v + _terminal_cost(ctx, r)
    return _wsum(ctx, v) + _worst_penalty(ctx, r)


def _range_terms(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, ...]:
    """Distance (eq. 36), soft range penalty (eq. 50) and terminal (eq. 38) terms separately, each (N,)."""
    r = _target_ranges(ctx, h, px, py)
    dist = _wsum(ctx, _distance_cost(ctx, r))
    short = _short_of_dstar_on_leg(ctx, px, py, r) if _first_leg(ctx, h) else None
    pen = _worst_penalty(ctx, r, short) if ctx.worst else _wsum(ctx, _penalty_cost(ctx, r, short))
    term = _wsum(ctx, _terminal_cost(ctx, r) if h == ctx.H else np.zeros(r.shape))
    return dist, pen, term


def geometry(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Geometry term alpha / sigma_min(Phi) (eqs. 34-35), (N,), closed form over the agents' unit bearing vectors.

    sigma_min^2 = 2 (sum of squared cross products of all pairs) / (n + |z|), z = sum exp(2 i b);
    the neighbours' pairs and share of z are precomputed per step and sigma point. A bearing is
    undefined (sigma_min = 0) when an agent is within ``MIN_BEARING_RANGE_M`` of the sigma point.
    """
    alpha = ctx.cfg.alpha
    dx = px[None, :] - ctx.tx[h][:, None]
    dy = py[None, :] - ctx.ty[h][:, None]
    dx2 = dx * dx
    dy2 = dy * dy
    r2 = dx2 + dy2
    if ctx.n_agents == 1:
        return _wsum(ctx, np.where(r2 < _R2_MIN, alpha / SIGMA_FLOOR, alpha))
    undefined = (r2 < _R2_MIN) | ctx.nb_undefined[h][:, None]
    inv_r2 = 1.0 / np.where(undefined, 1.0, r2)
    cross2 = np.zeros(0)
    for j in range(ctx.k):
        c = dx * ctx.nb_ey_j[j][h][:, None] - dy * ctx.nb_ex_j[j][h][:, None]
        cross2 = c * c if j == 0 else cross2 + c * c
    pairs = cross2 * inv_r2 + ctx.pair[h][:, None]
    zr = (dx2 - dy2) * inv_r2 + ctx.zr[h][:, None]
    zi = (dx * dy) * (inv_r2 * 2.0) + ctx.zi[h][:, None]
    sigma = np.sqrt((pairs * 2.0) / (np.sqrt(zr * zr + zi * zi) + ctx.n_agents))
    sigma = np.maximum(np.where(undefined, 0.0, sigma), SIGMA_FLOOR)
    return _wsum(ctx, alpha / sigma)


def neighbour_ranges(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (k, N) to the neighbours at step h and the safety violation sum_j max(0, d_S - range_j) (N,), m.

    On the first leg (:func:`_first_leg`) the closest approach along it counts too, and a vehicle
    already inside d_S of a neighbour at the start need not get closer than it is:
    max(0, d_S - d_end, min(d_S, d_start) - d_closest).
    """
    if ctx.k == 0:
        return np.zeros((0, px.size)), np.zeros(px.size)
    ox = px[None, :] - ctx.nbx[h][:, None]
    oy = py[None, :] - ctx.nby[h][:, None]
    rng = np.sqrt(ox * ox + oy * oy)
    d_safe = ctx.cfg.d_safe_m
    short = np.maximum(d_safe - rng, 0.0)
    if _first_leg(ctx, h):
        short = np.maximum(
            short, _leg_dip(ctx, ctx.nbx[0], ctx.nby[0], ctx.nbx[1], ctx.nby[1], d_safe, px, py, safety=True)
        )
    viol = short[0]
    for j in range(1, ctx.k):
        viol = viol + short[j]
    return rng, viol


def connectivity(ctx: Context, h: int, rng: np.ndarray) -> np.ndarray:
    """Connectivity term of eq. (37), (N,): gamma |N_i| / max(lambda_2(L), LAMBDA_FLOOR), ranges rng (k, N); 0 if k = 0."""
    if ctx.k == 0:
        return np.zeros(rng.shape[1])
    if ctx.formation:
        return formation(ctx, rng)
    lam = fiedler(link_weight(ctx, rng).T, ctx.nb_w[h][None])
    return ctx.c_conn / np.maximum(lam, LAMBDA_FLOOR)


def formation(ctx: Context, rng: np.ndarray) -> np.ndarray:
    """Formation reading of eq. (37) (``planner.connectivity = "formation"``), (N,): gamma sum_j |rng_j - d_j,0| / d*.

    ``rng`` (k, N) the ranges to the neighbours at the step, d_j,0 (``ctx.nb_r0``) at the plan start.
    """
    dev = np.abs(rng[0] - ctx.nb_r0[0])
    for j in range(1, ctx.k):
        dev = dev + np.abs(rng[j] - ctx.nb_r0[j])
    return dev * ctx.c_form


def connectivity_bound(ctx: Context, h: int, rng: np.ndarray) -> np.ndarray:
    """Lower bound (N,) of the connectivity term from Fiedler's lambda_2 <= n / (n - 1) min_i L_ii; rng (k, N).

    The formation reading is cheap and exact.
    """
    if ctx.formation:
        return formation(ctx, rng)
    w = link_weight(ctx, rng)
    deg = np.minimum(w.sum(axis=0), np.min(ctx.nb_w[h].sum(axis=1)[:, None] + w, axis=0))
    return ctx.c_conn / np.maximum(deg * (ctx.n_agents / (ctx.n_agents - 1.0)), LAMBDA_FLOOR)


def stage_cost(
    ctx: Context, h: int, px: np.ndarray, py: np.ndarray, chunk: int = 4096
) -> tuple[np.ndarray, np.ndarray]:
    """Stage cost of eq. (38) (N,) = geometry + range terms + connectivity, and the safety violation (N,) in m.

    Element-wise per position (chunked to stay in cache), so a position's cost does not depend on its batch.
    """
    cost = np.empty(px.size)
    viol = np.empty(px.size)
    for lo in range(0, px.size, chunk):
        x, y = px[lo : lo + chunk], py[lo : lo + chunk]
        rng, viol[lo : lo + chunk] = neighbour_ranges(ctx, h, x, y)
        cost[lo : lo + chunk] = (geometry(ctx, h, x, y) + range_part(ctx, h, x, y)) + connectivity(ctx, h, rng)
    return cost, viol


def stage_terms(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> dict[str, np.ndarray]:
    """The cost terms of eq. (38) separately (for telemetry), each (N,), and the safety violation in m."""
    dist, pen, term = _range_terms(ctx, h, px, py)
    rng, viol = neighbour_ranges(ctx, h, px, py)
    return {
        "geometry": geometry(ctx, h, px, py),
        "distance": dist,
        "connectivity": connectivity(ctx, h, rng),
        "penalty": pen,
        "terminal": term,
        "safety_violation_m": viol,
    }


def plan_terms(ctx: Context, way: np.ndarray) -> tuple[dict[str, float], float]:
    """The terms of eq. (38) and the safety violation summed over the steps of one own path ``way`` (H, 2) m, and the cost."""
    steps = [stage_terms(ctx, h, way[h - 1 : h, 0], way[h - 1 : h, 1]) for h in range(1, ctx.H + 1)]
    terms = {name: sum(float(step[name][0]) for step in steps) for name in steps[0]}
    return terms, sum(sum(float(step[name][0]) for name in TERMS) for step in steps)


def _range_min_at(ctx: Context, last: bool | np.ndarray) -> float | np.ndarray:
    """Range (m) minimising the range terms: d* if their sum decreases below d* (eqs. 36, 38, 50), else 0."""
    cfg = ctx.cfg
    left_slope = 1.0 - cfg.alpha - cfg.soft_penalty - np.where(last, cfg.terminal_weight, 0.0)
    return np.where(left_slope < 0.0, cfg.d_star_m, 0.0)


def range_bound(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Cheap lower bound (N,) of :func:`range_part` at step h from the range r0 to the centre sigma point alone.

    The other sigma points come in pairs xi_0 +- d_j of equal weight (eqs. 32-33, propagated
    linearly), so their ranges satisfy r_+ + r_- >= 2 r0 (triangle inequality). The range cost
    f(r) is convex with its minimum at x_min (0 or d*) and non-decreasing beyond, hence
    f(r_+) + f(r_-) >= 2 f(max(r0, x_min)) and the weighted sum is at least
    w0 f(r0) + (1 - w0) f(max(r0, x_min)). Needs non-negative weights (``ctx.can_prune``).
    """
    last = h == ctx.H
    dx = px - ctx.tx0[h]
    dy = py - ctx.ty0[h]
    r0 = np.sqrt(dx * dx + dy * dy)
    x_min = float(_range_min_at(ctx, last))
    return ctx.w[0] * _range_cost(ctx, r0, last) + ctx.w_rest * _range_cost(ctx, np.maximum(r0, x_min), last)


def lower_bound(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Admissible lower bound (N,) of the cost of steps h+1..H from own positions (px, py) at step h.

    After j more steps the vehicle is within j * T_o * max(speed) of its position; each term is
    bounded over that disc: the range terms exactly on the range interval (their sum is convex and
    piecewise linear in the range with its minimum at d* or 0), geometry by the neighbours'
    bearings alone (sigma_min^2 = (n - |Z + exp(2 i b)|) / 2 <= (n - ||Z| - 1|) / 2, Z the
    neighbours' share of z), connectivity by Fiedler's bound lambda_2 <= n / (n - 1) min_i L_ii
    with the own links at their shortest possible range.
    """
    total = range_rest(ctx, h, px, py)
    return total + connectivity_rest(ctx, h, px, py) if ctx.k > 0 else total


def range_rest(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Range and geometry part (N,) of :func:`lower_bound`: the range terms per sigma point on the disc."""
    rho = ctx.r_step * np.arange(1, ctx.H - h + 1, dtype=float)[None, :, None]
    x_min = _range_min_at(ctx, (np.arange(h + 1, ctx.H + 1) == ctx.H)[None, :, None])
    # layout (L, H - h, N): sigma point, future step, position
    dx = px[None, None, :] - ctx.tx[h + 1 :].T[:, :, None]
    dy = py[None, None, :] - ctx.ty[h + 1 :].T[:, :, None]
    r = np.sqrt(dx * dx + dy * dy)
    at = np.minimum(np.maximum(x_min, np.maximum(r - rho, 0.0)), r + rho)
    best = _soft_range_cost(ctx, at)
    best[:, -1] += _terminal_cost(ctx, at[:, -1])
    return _wsum(ctx, best.reshape(best.shape[0], -1)).reshape(best.shape[1:]).sum(axis=0) + float(
        np.sum(ctx.geom_lb_w[h + 1 :])
    )


def connectivity_rest(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Lower bound (N,) of the connectivity terms (eq. 37) of steps h+1..H (see :func:`lower_bound`); k > 0."""
    rho = ctx.r_step * np.arange(1, ctx.H - h + 1, dtype=float)[None, :, None]
    # layout (k, H - h, N): neighbour, future step, position
    ox = px[None, None, :] - ctx.nbx[h + 1 :].T[:, :, None]
    oy = py[None, None, :] - ctx.nby[h + 1 :].T[:, :, None]
    if ctx.formation:
        # the range to neighbour j after the remaining steps lies in [r - rho, r + rho]
        r = np.sqrt(ox * ox + oy * oy)
        r0 = ctx.nb_r0[:, None, None]
        dev = np.maximum(np.maximum(r - rho - r0, r0 - (r + rho)), 0.0)
        return dev.sum(axis=(0, 1)) * ctx.c_form
    w = link_weight_bound(ctx, np.maximum(np.sqrt(ox * ox + oy * oy) - rho, 0.0))
    nb_deg = ctx.nb_w[h + 1 :].sum(axis=2).T[:, :, None]
    deg = np.minimum(w.sum(axis=0), np.min(nb_deg + w, axis=0))
    lam_up = deg * (ctx.n_agents / (ctx.n_agents - 1.0))
    return (ctx.c_conn / np.maximum(lam_up, LAMBDA_FLOOR)).sum(axis=0)


def range_rest_centre(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Cheap lower bound (N,) of :func:`range_rest` from the centre sigma point alone.

    Per future step the disc bound g(r) = f(clip(x_min, r - rho, r + rho)) of :func:`lower_bound`
    is convex, minimal at x_min and non-decreasing beyond, so the pairing argument of
    :func:`range_bound` (eqs. 32-33) gives w0 g(r0) + (1 - w0) g(max(r0, x_min)). Needs ``ctx.can_prune``.
    """
    n = ctx.H - h
    rho = ctx.r_step * np.arange(1, n + 1, dtype=float)[:, None]
    x_min = np.full((n, 1), float(_range_min_at(ctx, False)))
    x_min[-1] = float(_range_min_at(ctx, True))
    # layout (H - h, N): future step, position
    dx = px[None, :] - ctx.tx0[h + 1 :, None]
    dy = py[None, :] - ctx.ty0[h + 1 :, None]
    r0 = np.sqrt(dx * dx + dy * dy)
    at_r0 = np.minimum(np.maximum(np.maximum(r0 - rho, 0.0), x_min), r0 + rho)
    at_far = np.maximum(at_r0, x_min)
    cost_r0 = _soft_range_cost(ctx, at_r0)
    cost_r0[-1] += _terminal_cost(ctx, at_r0[-1])
    cost_far = _soft_range_cost(ctx, at_far)
    cost_far[-1] += _terminal_cost(ctx, at_far[-1])
    return ctx.w[0] * cost_r0.sum(axis=0) + ctx.w_rest * cost_far.sum(axis=0) + float(np.sum(ctx.geom_lb_w[h + 1 :]))
