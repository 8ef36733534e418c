"""The exact DMPC search (eqs. 29-31, 43): dynamic programming over the merge graph with branch and bound."""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.planner.context import Context
from auv_swarm.agent.planner.cost import (
    connectivity,
    connectivity_bound,
    connectivity_rest,
    floor_shortfall,
    geometry,
    lower_bound,
    neighbour_ranges,
    plan_terms,
    range_bound,
    range_part,
    range_rest,
    range_rest_centre,
    stage_cost,
)
from auv_swarm.agent.planner.graph import Graph, merge_graph
from auv_swarm.agent.planner.problem import Plan, PlanProblem, control_set, speed_set
from auv_swarm.contract.config import ChannelConfig, PlannerConfig

_PRUNE_RTOL = 1e-9  # relative margin of every pruning test, far above rounding, so pruning stays exact
_ROLLOUTS = 8  # greedy completions tried when the incumbent (upper bound) is updated
_REFINE_MIN = 400  # live states at level H - 1 from which the incumbent is refined by a second rollout
_BOUND_LEVELS = 2  # the remaining-cost bound is used when expanding the last levels, where the graph is wide


def _compress(keys: np.ndarray, space: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct values and inverse of non-negative int64 keys below ``space`` (a lookup table if it is small)."""
    if space > 32 * keys.size + 4096:
        uniq, inverse = np.unique(keys, return_inverse=True)
        return uniq, inverse.reshape(-1)
    keys = keys.astype(np.intp, copy=False)
    seen = np.zeros(space, dtype=bool)
    seen[keys] = True
    uniq = np.flatnonzero(seen)
    lut = np.empty(space, dtype=np.int64)
    lut[uniq] = np.arange(uniq.size)
    return uniq, lut[keys]


# ----------------------------------------------------------------------------- search


def _step_table(ctx: Context, g: Graph) -> tuple[np.ndarray, np.ndarray]:
    """Displacements x and y in m of every step type of the graph, plus a final zero for "no step"."""
    speeds = ctx.speeds.tolist()
    n = g.type_g.size
    step_x, step_y = np.zeros(n + 1), np.zeros(n + 1)
    for i, (a, b) in enumerate(zip(g.type_g.tolist(), g.type_speed.tolist(), strict=True)):
        heading = ctx.theta0 + a * ctx.unit
        dist = ctx.T * speeds[b]
        step_x[i], step_y[i] = dist * math.cos(heading), dist * math.sin(heading)
    return step_x, step_y


def _positions(ctx: Context, g: Graph, h: int, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Own positions (x, y) in m of position nodes at level h: the start plus their steps in sorted order."""
    step_x, step_y = ctx.steps
    cols = g.pos_cols[h]
    x = step_x[cols[0][nodes]] + ctx.p0[0]
    y = step_y[cols[0][nodes]] + ctx.p0[1]
    for j in range(1, h):
        x += step_x[cols[j][nodes]]
        y += step_y[cols[j][nodes]]
    return x, y


def _rollout(ctx: Context, g: Graph, h: int, starts: np.ndarray, base: np.ndarray) -> float:
    """Best total cost of greedy completions (cheapest next step each time) from states ``starts`` at level h."""
    cur = starts
    total = base.copy()
    rows = np.arange(starts.size)
    for hh in range(h + 1, ctx.H + 1):
        kids = g.child[hh][cur]
        p, at = np.unique(g.state_pos[hh][kids] if hh < ctx.H else kids, return_inverse=True)
        cost, viol = stage_cost(ctx, hh, *_positions(ctx, g, hh, p))
        cost[viol > 0.0] = np.inf
        cost = cost[at.reshape(kids.shape)]
        best = cost.argmin(axis=1)
        total = total + cost[rows, best]
        cur = kids[rows, best]
    return float(total.min())


def _search(ctx: Context, g: Graph) -> tuple[np.ndarray | None, int]:
    """Exact branch and bound over the merge graph: (indices, nodes fully evaluated); None if all infeasible.

    Level by level: the children of the expanded states are first bounded cheaply, cheapest bound
    first (range terms of this and the remaining steps from the centre sigma point alone,
    :func:`range_bound` and :func:`range_rest_centre`, with the geometry and connectivity bounds;
    then the remaining steps' connectivity bound; then the exact range terms; then the full bound of
    the remaining steps); only children that can still beat the incumbent (the best greedy
    completion found so far) get their full cost. A child is tested once, with the cheapest
    cost so far among its expanded parents (float addition is monotone, so this keeps exactly the
    children that some in-edge keeps). A state is expanded only if its exact cost so far plus the
    bound of the remaining steps can still beat the incumbent; the incumbent is refined at level
    H - 1 only when that level is wide. Stage costs are kept per candidate node, and the backward
    values reuse the children gathered on the way forward.
    """
    H = ctx.H
    f_prev = np.zeros(1)
    exp_idx = np.zeros(1, dtype=np.int64)
    f_exp = np.zeros(1)
    ub = math.inf
    nodes = 0
    # per level: the expanded states, their stage costs and the children (n_exp, |U|) expanded from the level before
    expanded: list[np.ndarray] = [exp_idx]
    exp_cost: list[np.ndarray] = [np.zeros(1)]
    kid_rows: list[np.ndarray] = [np.zeros((0, 0), dtype=np.int32)]
    # per level 1..H-1: forward values of all states (inf where not expanded), overwritten by the backward values
    values: list[np.ndarray] = [np.zeros(0)] * H
    for h in range(1, H + 1):
        kids = g.child[h][exp_idx]
        keys = g.state_pos[h][kids] if h < H else kids
        cand, kc = _compress(keys.reshape(-1), g.pos_digits[h].shape[0])
        px, py = _positions(ctx, g, h, cand)
        bound_rest = ctx.can_prune and H - _BOUND_LEVELS <= h < H
        if ctx.can_prune and math.isfinite(ub):
            lim = ub + _PRUNE_RTOL * max(1.0, abs(ub))
            # cheapest cost so far into each candidate: f + b <= lim holds for some in-edge iff it does for this one
            f_in = np.full(cand.size, np.inf)
            np.minimum.at(f_in, kc, f_exp.repeat(kids.shape[1]))
            sel, x, y, ranged, conn, rem = _survivors(ctx, h, px, py, f_in, lim, bound_rest)
        else:
            rng, viol = neighbour_ranges(ctx, h, px, py)
            sel = np.flatnonzero(viol == 0.0)
            x, y = px[sel], py[sel]
            ranged = range_part(ctx, h, x, y)
            conn = connectivity(ctx, h, rng[:, sel])
            rem = lower_bound(ctx, h, x, y) if bound_rest else np.zeros(sel.size)
        cost_sel = (geometry(ctx, h, x, y) + ranged) + conn
        cost = np.full(cand.size, np.inf)
        cost[sel] = cost_sel
        nodes += sel.size
        kid_rows.append(kc.reshape(kids.shape) if h == H else kids)
        if h == H:
            break
        # forward values (cost so far) of the states at the evaluated nodes (each node's states are contiguous)
        at_node = cand[sel]
        st, _ = _spans(g.node_start[h], g.node_count[h], at_node)
        per_node = g.node_count[h][at_node]
        cost_st = cost_sel.repeat(per_node)
        edges, first = _spans(g.in_start[h], g.in_count[h], st)
        f_st = cost_st + np.minimum.reduceat(f_prev[g.in_parent[h][edges]], first) if st.size else cost_st
        bound_st = f_st + rem.repeat(per_node)
        live = np.isfinite(f_st)
        if ctx.can_prune and live.any():
            alive = np.flatnonzero(live)
            # the incumbent is refined before step H only where that level is wide enough to pay off
            if h == min(2, H - 1) or (h == H - 1 and alive.size > _REFINE_MIN):
                if alive.size > _ROLLOUTS:
                    alive = alive[bound_st[alive].argpartition(_ROLLOUTS - 1)[:_ROLLOUTS]]
                ub = min(ub, _rollout(ctx, g, h, st[alive], f_st[alive]))
            live &= bound_st <= ub + _PRUNE_RTOL * max(1.0, abs(ub))
        exp_idx = st[live]
        f_exp = f_st[live]
        f_prev = values[h] = np.full(g.state_pos[h].size, np.inf)
        f_prev[exp_idx] = f_exp
        expanded.append(exp_idx)
        exp_cost.append(cost_st[live])
    # backward values (cost to go, from the states' own stage cost on) of the expanded states, level by level
    last = cost[kid_rows[H]]
    kid_vals = last
    for h in range(H - 1, 0, -1):
        v = values[h]
        v[expanded[h]] = exp_cost[h] + kid_vals.min(axis=1)
        kid_vals = v[kid_rows[h]]
    values[0] = kid_vals.min(axis=1)
    if not np.isfinite(values[0][0]):
        return None, nodes
    return _extract(g, values, None, H, (expanded[H - 1], last)), nodes


def _survivors(
    ctx: Context, h: int, px: np.ndarray, py: np.ndarray, f_in: np.ndarray, lim: float, bound_rest: bool
) -> tuple[np.ndarray, ...]:
    """Candidates at step h that can still beat the incumbent: (indices, x, y, range terms, connectivity, rest bound).

    The bounds grow in cost order, each tested on the survivors of the one before: range terms
    of the centre sigma point (:func:`range_bound`) with the geometry bound, then (``bound_rest``)
    the rest from the centre sigma point (:func:`range_rest_centre`), then the connectivity term
    (its lower bound for k > 2) and the safety distance, then the remaining steps' connectivity
    bound, the exact range terms and the full bound of the remaining steps. Every test adds
    non-negative terms to the one before and float addition is monotone, so a candidate dropped
    early fails every later test too: the survivors are the same as with all tests on all
    candidates. The connectivity returned is the exact term (eq. 37) of the survivors.
    """
    g_lb = ctx.geom_lb_w[h]
    rb = range_bound(ctx, h, px, py)
    at = np.flatnonzero(f_in + (rb + g_lb) <= lim)
    f, rb, x, y = _pick(at, f_in, rb, px, py)
    if bound_rest:
        rrc = range_rest_centre(ctx, h, x, y)
        at, f, rb, x, y, rrc = _pick(np.flatnonzero(f + ((rb + g_lb) + rrc) <= lim), at, f, rb, x, y, rrc)
    rng, viol = neighbour_ranges(ctx, h, x, y)
    exact_conn = ctx.k <= 2
    conn = connectivity(ctx, h, rng) if exact_conn else connectivity_bound(ctx, h, rng)
    quick = np.where(viol == 0.0, rb + (g_lb + conn), np.inf)
    if bound_rest:
        quick += rrc
    at, f, x, y, conn, rng, quick = _pick(np.flatnonzero(f + quick <= lim), at, f, x, y, conn, rng, quick)
    rem = np.zeros(at.size)
    if bound_rest and ctx.k > 0:
        rem = connectivity_rest(ctx, h, x, y)
        at, f, x, y, conn, rng, rem = _pick(np.flatnonzero(f + (quick + rem) <= lim), at, f, x, y, conn, rng, rem)
    ranged = range_part(ctx, h, x, y)
    bound = (ranged + g_lb) + conn
    keep = f + bound <= lim
    if bound_rest:
        at, f, x, y, conn, rng, rem, ranged, bound = _pick(
            np.flatnonzero(keep), at, f, x, y, conn, rng, rem, ranged, bound
        )
        rem = rem + range_rest(ctx, h, x, y)
        keep = f + (bound + rem) <= lim
    at, x, y, ranged, conn, rng, rem = _pick(np.flatnonzero(keep), at, x, y, ranged, conn, rng, rem)
    return at, x, y, ranged, conn if exact_conn else connectivity(ctx, h, rng), rem


def _pick(i: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The entries ``i`` of each array (1-D, or 2-D along its columns)."""
    return tuple(a[:, i] if a.ndim == 2 else a[i] for a in arrays)


def _spans(start: np.ndarray, count: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated index ranges [start[i], start[i] + count[i]) for i in ``sel``, and where each begins."""
    c = count[sel]
    ends = c.cumsum()
    begins = ends - c
    if ends.size == 0:
        return np.zeros(0, dtype=np.int64), begins
    return (start[sel] - begins).repeat(c) + np.arange(ends[-1]), begins


def _extract(
    g: Graph,
    values: list[np.ndarray],
    second: list[np.ndarray] | None,
    H: int,
    last: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Lexicographically smallest index sequence that follows minimal backward values (then minimal ``second``).

    ``values`` holds levels 0..H; with ``last`` = (sorted states at H - 1, their children's values
    (n, |U|)) the values of step H are read from there and ``values`` needs levels 0..H-1 only.
    """
    s = 0
    out = np.empty(H, dtype=np.int64)
    for h in range(1, H + 1):
        kids = g.child[h][s]
        v = last[1][int(np.searchsorted(last[0], s))] if last is not None and h == H else values[h][kids]
        if second is not None:
            v = np.where(v == v.min(), second[h][kids], np.inf)
        u = int(np.argmin(v))
        out[h - 1] = u
        s = int(kids[u])
    return out


def _fallback(ctx: Context, g: Graph) -> tuple[np.ndarray, int]:
    """Every sequence is infeasible: minimise the total violation of eq. (50)'s floors (m), the safety distance's
    plus the range floor d*'s (:func:`floor_shortfall`), then the cost; exact, no pruning.

    The violations of every position come first (cheap); the cost, whose connectivity term needs the whole
    team's Laplacian, is evaluated only at the positions of states on a least-violation path, the only ones
    the tie-break reads (``cost.stage_cost`` is element-wise, so a position's cost does not depend on which
    others are evaluated with it)."""
    H = ctx.H
    viols: list[np.ndarray] = [np.zeros(1)]
    for h in range(1, H + 1):
        px, py = _positions(ctx, g, h, np.arange(g.pos_digits[h].shape[0]))
        viols.append(neighbour_ranges(ctx, h, px, py)[1] + floor_shortfall(ctx, h, px, py))
    vv: list[np.ndarray] = [np.zeros(0)] * (H + 1)
    vv[H] = viols[H]
    best_kids: list[np.ndarray] = [np.zeros((0, 0), dtype=bool)] * H
    for h in range(H - 1, -1, -1):
        a = vv[h + 1][g.child[h + 1]]
        amin = a.min(axis=1)
        best_kids[h] = a == amin[:, None]
        vv[h] = viols[h][g.state_pos[h]] + amin if h > 0 else amin
    # the states on least-violation paths, level by level from the root, and their positions
    on_path = [np.zeros(1, dtype=bool)] + [np.zeros(0, dtype=bool)] * H
    on_path[0][0] = True
    for h in range(H):
        nxt = np.zeros(g.state_pos[h + 1].shape[0], dtype=bool)
        nxt[g.child[h + 1][on_path[h]][best_kids[h][on_path[h]]]] = True
        on_path[h + 1] = nxt
    costs: list[np.ndarray] = [np.zeros(1)]
    nodes = 0
    for h in range(1, H + 1):
        need = np.unique(g.state_pos[h][on_path[h]])
        c = np.full(g.pos_digits[h].shape[0], np.inf)
        c[need] = stage_cost(ctx, h, *_positions(ctx, g, h, need))[0]
        costs.append(c)
        nodes += need.size
    vc: list[np.ndarray] = [np.zeros(0)] * (H + 1)
    vc[H] = costs[H]
    for h in range(H - 1, -1, -1):
        b = np.where(best_kids[h], vc[h + 1][g.child[h + 1]], np.inf).min(axis=1)
        vc[h] = costs[h][g.state_pos[h]] + b if h > 0 else b
    return _extract(g, vv, vc, H), nodes


def _path(ctx: Context, indices: np.ndarray) -> np.ndarray:
    """Own positions (H, 2) in m along a control index sequence, headings on the lattice."""
    g = 0
    x, y = ctx.p0
    out = np.empty((ctx.H, 2))
    for h, u in enumerate(indices):
        a, s = divmod(int(u), ctx.n_speed)
        g = (g + ctx.m[a]) % ctx.wrap if ctx.wrap else g + ctx.m[a]
        vx, vy = ctx.step_vector(g, ctx.speed_class[s])
        x, y = x + vx, y + vy
        out[h] = (x, y)
    return out


def _make_plan(ctx: Context, indices: np.ndarray, nodes: int) -> Plan:
    way = _path(ctx, indices)
    terms, cost = plan_terms(ctx, way)
    a, s = np.divmod(indices, ctx.n_speed)
    return Plan(
        controls=np.column_stack([ctx.dtheta[a], ctx.speeds[s]]),
        indices=indices.astype(np.int64),
        cost=cost,
        terms=terms,
        feasible=terms["safety_violation_m"] == 0.0,
        waypoints=way,
        nodes=nodes,
    )


def warm_up(planner: PlannerConfig, channel: ChannelConfig, u_max: float, r_max: float) -> None:
    """Build the cached merge graphs for every control-set shape an agent can meet.

    The graph depends on which speeds of the control set coincide or are zero; ``u_e`` is the only
    speed that varies, so the shapes are u_e = 0, u_e equal to each other speed, and u_e distinct
    from them all. Building their graphs at start-up keeps that one-off cost out of the first plans'
    wall time.
    """
    fixed = [v for v in speed_set(planner, 0.0, u_max) if v > 0.0]
    u_es = (0.0, *fixed, 0.5 * fixed[0])
    for u_e in u_es:
        ctx = Context(
            PlanProblem(
                position=np.zeros(2),
                heading=0.0,
                xi=np.array([planner.d_star_m, 0.0, 0.0, 0.0]),
                P=np.eye(4),
                neighbours=(),
                controls=control_set(planner, u_e, u_max, r_max),
                planner=planner,
                channel=channel,
            )
        )
        merge_graph(ctx.m, ctx.wrap, ctx.speed_class, ctx.H)


def plan(problem: PlanProblem) -> Plan:
    """Exact minimiser of eq. (38) subject to eq. (50) over all |U|^H control sequences (eqs. 29-31, 43).

    Dynamic programming over merged states with branch and bound: the cost of step h depends
    only on this agent's position at step h (neighbours and target belief are fixed), and a
    position is an order-independent integer combination of step vectors on the heading grid, so
    sequences reaching the same (position, heading) share one state (graph cached per control-set
    shape and H). States and children that provably cannot beat the best complete sequence found
    by greedy completions are skipped (admissible bounds, see :func:`lower_bound`). The optimum is
    read back with backward values; among exactly equal costs the lexicographically smallest
    index sequence wins. If every sequence violates the safety distance, the least total
    violation of the safety distance and the range floor d* together (m), then the least cost, is chosen.
    """
    ctx = Context(problem)
    g = merge_graph(ctx.m, ctx.wrap, ctx.speed_class, ctx.H)
    ctx.steps = _step_table(ctx, g)
    indices, nodes = _search(ctx, g)
    if indices is None:
        indices, extra = _fallback(ctx, g)
        nodes += extra
    return _make_plan(ctx, indices, nodes)
