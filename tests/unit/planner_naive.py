"""The planner's cost of one sequence, plainly: loops over the steps and sigma points, SVD and eigvalsh."""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.planner import LAMBDA_FLOOR, SIGMA_FLOOR, PlanProblem, sigma_points
from auv_swarm.contract import acoustics


def naive_cost(problem: PlanProblem, indices: np.ndarray) -> tuple[float, float]:
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
                short = max(short, segment_dip((x0, y0), (x, y), point[:2], tgt, cfg.d_star_m + margin))
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
                    short = max(short, segment_dip((x0, y0), (x, y), n.position, nb[j][0], cfg.d_safe_m + margin))
                violation += short
    return total, violation


def segment_dip(a0, a1, b0, b1, limit: float) -> float:
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
