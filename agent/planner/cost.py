"""Fast evaluation of the stage cost of eq. (38) for batches of own positions, and the search's lower bounds.

The same cost as :mod:`agent.planner.reference` (the property tests compare them on every
generated example), arranged for the branch and bound: per step h, per sigma point, per
candidate position, with the parts that do not depend on the own position precomputed in
:class:`agent.planner.context.Context`.
"""

from __future__ import annotations

import numpy as np

from agent.planner.context import Context, fiedler, link_weight
from agent.planner.problem import LAMBDA_FLOOR, MIN_BEARING_RANGE_M, SIGMA_FLOOR

_R2_MIN = MIN_BEARING_RANGE_M**2

# ----------------------------------------------------------------------------- stage cost


def _at(arr: np.ndarray, h: int | np.ndarray) -> np.ndarray:
    """Rows of a per-level array: level h broadcast over the batch (h an int) or one level per point."""
    return arr[h][None] if isinstance(h, (int, np.integer)) else arr[h]


def _col(arr: np.ndarray, h: int | np.ndarray) -> np.ndarray:
    """Values of a per-level (H+1, M) array (M sigma points or neighbours) in the (M, N) layout of the stage cost.

    Level h as one column broadcast over the batch (h an int), or one level per point.
    """
    return arr[h][:, None] if isinstance(h, (int, np.integer)) else arr[h].T


def _sigma_sum(v: np.ndarray) -> np.ndarray:
    """Sum over the sigma points (axis 0) of an (L, N) array, in numpy's pairwise order of a row sum.

    For L = 2n + 1 = 9 this is (((v0 + v1) + (v2 + v3)) + ((v4 + v5) + (v6 + v7))) + v8, the
    order in which ``(N, L).sum(axis=1)`` adds each row, so the result does not depend on the layout.
    """
    if v.shape[0] != 9:
        return np.ascontiguousarray(v.T).sum(axis=1)
    a = v[0] + v[1]
    a += v[2] + v[3]
    b = v[4] + v[5]
    b += v[6] + v[7]
    a += b
    a += v[8]
    return a


def _wsum(ctx: Context, per_sigma: np.ndarray) -> np.ndarray:
    """UT-weighted sum over the sigma points (eq. 30) of an (L, N) array, (N,); one fixed order per point."""
    return _sigma_sum(per_sigma * ctx.w[:, None])


def _is_last(ctx: Context, h: int | np.ndarray) -> bool | np.ndarray:
    """Whether step h is the terminal step H: a bool for an int h, a (1, N) mask for per-point levels."""
    return bool(h == ctx.H) if isinstance(h, (int, np.integer)) else (h == ctx.H)[None, :]


def _target_ranges(ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Own range (L, N) in m to every sigma point at step h."""
    dx = px[None, :] - _col(ctx.tx, h)
    dy = py[None, :] - _col(ctx.ty, h)
    return np.sqrt(dx * dx + dy * dy)


def _range_cost(ctx: Context, r: np.ndarray, last: bool | np.ndarray) -> np.ndarray:
    """Distance (eq. 36) + soft range penalty (eq. 50) + terminal (eq. 38, when ``last``) per sigma point."""
    cfg = ctx.cfg
    v = r * ctx.c_dist + cfg.soft_penalty * (
        np.maximum(cfg.d_star_m - r, 0.0) * ctx.inv_ds + np.maximum(r - cfg.d_max_m, 0.0) * ctx.inv_dm
    )
    if isinstance(last, (bool, np.bool_)):
        return v + np.abs(r - cfg.d_star_m) * ctx.c_term if last else v
    return v + np.where(last, np.abs(r - cfg.d_star_m) * ctx.c_term, 0.0)


def _hypot_inplace(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """sqrt(dx^2 + dy^2) written into ``dx`` (returned); ``dy`` is left as scratch."""
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(dx, out=dx)


def _soft_range_cost(ctx: Context, r: np.ndarray, short: np.ndarray, over: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance cost (eq. 36) plus the soft range penalty (eq. 50) at ranges ``r`` (m), in place.

    The same operations as :func:`_range_cost` without the terminal term, written into the scratch
    arrays ``short`` and ``over`` (shape of ``r``); returns (cost in ``over``, ``short``, free again).
    """
    cfg = ctx.cfg
    np.subtract(cfg.d_star_m, r, out=short)
    np.maximum(short, 0.0, out=short)
    short *= ctx.inv_ds
    np.subtract(r, cfg.d_max_m, out=over)
    np.maximum(over, 0.0, out=over)
    over *= ctx.inv_dm
    short += over
    short *= cfg.soft_penalty
    v = np.multiply(r, ctx.c_dist, out=over)
    v += short
    return v, short


def range_part(ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """UT-weighted distance + penalty + terminal cost (N,) at step h.

    For one level h the same operations as :func:`_range_cost` run in place (fewer temporaries).
    """
    if not isinstance(h, (int, np.integer)):
        return _wsum(ctx, _range_cost(ctx, _target_ranges(ctx, h, px, py), _is_last(ctx, h)))
    cfg = ctx.cfg
    r = px[None, :] - ctx.tx_c[h]
    dy = py[None, :] - ctx.ty_c[h]
    r = _hypot_inplace(r, dy)
    v, short = _soft_range_cost(ctx, r, dy, np.empty_like(r))
    if h == ctx.H:
        term = np.subtract(r, cfg.d_star_m, out=short)
        np.abs(term, out=term)
        term *= ctx.c_term
        v += term
    v *= ctx.w[:, None]
    return _sigma_sum(v)


def _range_terms(ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, ...]:
    """Distance (eq. 36), soft range penalty (eq. 50) and terminal (eq. 38) terms separately, each (N,)."""
    cfg = ctx.cfg
    r = _target_ranges(ctx, h, px, py)
    dist = _wsum(ctx, r * ctx.c_dist)
    pen = _wsum(
        ctx,
        cfg.soft_penalty
        * (np.maximum(cfg.d_star_m - r, 0.0) * ctx.inv_ds + np.maximum(r - cfg.d_max_m, 0.0) * ctx.inv_dm),
    )
    term = _wsum(ctx, np.where(_is_last(ctx, h), np.abs(r - cfg.d_star_m) * ctx.c_term, 0.0))
    return dist, pen, term


def geometry(ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Geometry term alpha / sigma_min(Phi) (eqs. 34-35), (N,), closed form over the agents' unit bearing vectors.

    sigma_min^2 = 2 (sum of squared cross products of all pairs) / (n + |z|), z = sum exp(2 i b);
    the neighbours' pairs and share of z are precomputed per step and sigma point.
    """
    alpha = ctx.cfg.alpha
    if isinstance(h, (int, np.integer)):
        dx = px[None, :] - ctx.tx_c[h]
        dy = py[None, :] - ctx.ty_c[h]
        und, pair, zr0, zi0, *ej = ctx.geometry_columns(int(h))
    else:
        dx = px[None, :] - _col(ctx.tx, h)
        dy = py[None, :] - _col(ctx.ty, h)
        und, pair, zr0, zi0 = (_col(a, h) for a in (ctx.nb_undefined, ctx.pair, ctx.zr, ctx.zi))
        ej = [_col(a, h) for a in (*ctx.nb_ey_j, *ctx.nb_ex_j)]
    dx2 = dx * dx
    dy2 = dy * dy
    r2 = dx2 + dy2
    if ctx.n_agents == 1:
        return _wsum(ctx, np.where(r2 < _R2_MIN, alpha / SIGMA_FLOOR, alpha))
    bad = r2 < _R2_MIN
    bad |= und
    np.copyto(r2, 1.0, where=bad)
    inv = np.divide(1.0, r2, out=r2)
    num = np.zeros(0)
    for j in range(ctx.k):
        c = dx * ej[j]
        c -= dy * ej[ctx.k + j]
        c *= c
        num = c if j == 0 else np.add(num, c, out=num)
    num *= inv
    num += pair
    zr = np.subtract(dx2, dy2, out=dx2)
    zr *= inv
    zr += zr0
    zi = np.multiply(dx, dy, out=dx)
    inv *= 2.0
    zi *= inv
    zi += zi0
    zr *= zr
    zi *= zi
    zr += zi
    np.sqrt(zr, out=zr)
    zr += ctx.n_agents
    num *= 2.0
    num /= zr
    sig = np.sqrt(num, out=num)
    np.copyto(sig, 0.0, where=bad)
    np.maximum(sig, SIGMA_FLOOR, out=sig)
    return _wsum(ctx, np.divide(alpha, sig, out=sig))


def neighbour_ranges(
    ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (k, N) to the neighbours at step h and the safety violation sum_j max(0, d_S - range_j) (N,), m."""
    if ctx.k == 0:
        return np.zeros((0, px.size)), np.zeros(px.size)
    if isinstance(h, (int, np.integer)):
        ox = px[None, :] - ctx.nbx_c[h]
        oy = py[None, :] - ctx.nby_c[h]
    else:
        ox = px[None, :] - _col(ctx.nbx, h)
        oy = py[None, :] - _col(ctx.nby, h)
    rng = _hypot_inplace(ox, oy)
    short = np.subtract(ctx.cfg.d_safe_m, rng, out=oy)
    np.maximum(short, 0.0, out=short)
    viol = short[0]
    for j in range(1, ctx.k):
        viol = viol + short[j]
    return rng, viol


def connectivity(ctx: Context, h: int | np.ndarray, rng: np.ndarray) -> np.ndarray:
    """Connectivity term gamma / max(lambda_2(L), LAMBDA_FLOOR) of eq. (37), (N,), ranges rng (k, N); 0 if k = 0."""
    if ctx.k == 0:
        return np.zeros(rng.shape[1])
    lam = fiedler(link_weight(ctx, rng).T, _at(ctx.nb_w, h))
    return ctx.cfg.gamma / np.maximum(lam, LAMBDA_FLOOR)


def connectivity_bound(ctx: Context, h: int, rng: np.ndarray) -> np.ndarray:
    """Lower bound (N,) of the connectivity term from Fiedler's lambda_2 <= n / (n - 1) min_i L_ii; rng (k, N)."""
    w = link_weight(ctx, rng)
    deg = np.minimum(w.sum(axis=0), np.min(ctx.nb_w[h].sum(axis=1)[:, None] + w, axis=0))
    return ctx.cfg.gamma / np.maximum(deg * (ctx.n_agents / (ctx.n_agents - 1.0)), LAMBDA_FLOOR)


def stage_cost(
    ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray, chunk: int = 4096
) -> tuple[np.ndarray, np.ndarray]:
    """Stage cost of eq. (38) (N,) = geometry + range terms + connectivity, and the safety violation (N,) in m.

    Element-wise per position (chunked to stay in cache), so a position's cost does not depend on its batch.
    """
    if px.size <= chunk:
        rng, viol = neighbour_ranges(ctx, h, px, py)
        return (geometry(ctx, h, px, py) + range_part(ctx, h, px, py)) + connectivity(ctx, h, rng), viol
    cost = np.empty(px.size)
    viol = np.empty(px.size)
    for lo in range(0, px.size, chunk):
        x, y = px[lo : lo + chunk], py[lo : lo + chunk]
        hh = h if isinstance(h, (int, np.integer)) else h[lo : lo + chunk]
        rng, v = neighbour_ranges(ctx, hh, x, y)
        cost[lo : lo + chunk] = (geometry(ctx, hh, x, y) + range_part(ctx, hh, x, y)) + connectivity(ctx, hh, rng)
        viol[lo : lo + chunk] = v
    return cost, viol


def stage_terms(ctx: Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> dict[str, np.ndarray]:
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
    cfg = ctx.cfg
    ds = cfg.d_star_m
    rho = ctx.r_step * np.arange(1, ctx.H - h + 1, dtype=float)[None, :, None]
    last = (np.arange(h + 1, ctx.H + 1) == ctx.H)[None, :, None]
    # layout (L, H - h, N): sigma point, future step, position
    r = px[None, None, :] - ctx.tx[h + 1 :].T[:, :, None]
    dy = py[None, None, :] - ctx.ty[h + 1 :].T[:, :, None]
    r = _hypot_inplace(r, dy)
    lo = r - rho
    np.maximum(lo, 0.0, out=lo)
    hi = np.add(r, rho, out=r)
    left_slope = 1.0 - cfg.alpha - cfg.soft_penalty - np.where(last, cfg.terminal_weight, 0.0)
    x_min = np.where(left_slope < 0.0, ds, 0.0)
    at = np.maximum(x_min, lo, out=lo)
    np.minimum(at, hi, out=at)
    # range cost of eqs. (36), (38), (50) at the clipped range, in place (see _range_cost)
    best, short = _soft_range_cost(ctx, at, dy, hi)
    term = np.subtract(at[:, -1], ds, out=short[:, -1])
    np.abs(term, out=term)
    term *= ctx.c_term
    best[:, -1] += term
    best *= ctx.w[:, None, None]
    return _sigma_sum(best).sum(axis=0) + float(np.sum(ctx.geom_lb_w[h + 1 :]))


def connectivity_rest(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Lower bound (N,) of the connectivity terms (eq. 37) of steps h+1..H (see :func:`lower_bound`); k > 0."""
    rho = ctx.r_step * np.arange(1, ctx.H - h + 1, dtype=float)[None, :, None]
    # layout (k, H - h, N): neighbour, future step, position
    ox = px[None, None, :] - ctx.nbx[h + 1 :].T[:, :, None]
    oy = py[None, None, :] - ctx.nby[h + 1 :].T[:, :, None]
    ox = _hypot_inplace(ox, oy)
    ox -= rho
    w = link_weight(ctx, np.maximum(ox, 0.0, out=ox))
    nb_deg = ctx.nb_w[h + 1 :].sum(axis=2).T[:, :, None]
    deg = np.minimum(w.sum(axis=0), np.min(nb_deg + w, axis=0))
    lam_up = deg * (ctx.n_agents / (ctx.n_agents - 1.0))
    return (ctx.cfg.gamma / np.maximum(lam_up, LAMBDA_FLOOR)).sum(axis=0)


def range_rest_centre(ctx: Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Cheap lower bound (N,) of :func:`range_rest` from the centre sigma point alone.

    Per future step the disc bound g(r) = f(clip(x_min, r - rho, r + rho)) of :func:`lower_bound`
    is convex, minimal at x_min and non-decreasing beyond, so the pairing argument of
    :func:`range_bound` (eqs. 32-33) gives w0 g(r0) + (1 - w0) g(max(r0, x_min)). Needs ``ctx.can_prune``.
    """
    cfg = ctx.cfg
    n = ctx.H - h
    rho = ctx.r_step * np.arange(1, n + 1, dtype=float)[:, None]
    # layout (2 (H - h), N): future step at r0, then at max(r0, x_min); position
    x_min = np.full((n, 1), float(_range_min_at(ctx, False)))
    x_min[-1] = float(_range_min_at(ctx, True))
    hi = px[None, :] - ctx.tx0[h + 1 :, None]
    dy = py[None, :] - ctx.ty0[h + 1 :, None]
    hi = _hypot_inplace(hi, dy)
    at = np.empty((2 * n, px.size))
    s1 = np.subtract(hi, rho, out=at[:n])
    np.maximum(s1, 0.0, out=s1)
    np.maximum(s1, x_min, out=s1)
    hi += rho
    np.minimum(s1, hi, out=s1)
    np.maximum(s1, x_min, out=at[n:])
    cost, short = _soft_range_cost(ctx, at, np.empty_like(at), np.empty_like(at))
    ends = [n - 1, 2 * n - 1]
    term = np.subtract(at[ends], cfg.d_star_m, out=short[:2])
    np.abs(term, out=term)
    term *= ctx.c_term
    cost[ends] += term
    total = ctx.w[0] * cost[:n].sum(axis=0)
    total += ctx.w_rest * cost[n:].sum(axis=0)
    total += float(np.sum(ctx.geom_lb_w[h + 1 :]))
    return total
