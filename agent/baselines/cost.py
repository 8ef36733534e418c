"""The DMPC cost of eq. (38) for any control sequence, continuous or on the grid, and its joint form.

The exact planner (:func:`agent.planner.plan`) searches the grid of eqs. (46)-(49); the
baselines need the same cost for sequences it never enumerates: DPSO's continuous
(heading change, speed) sequences, and the centralised planner's joint cost of every
AUV's sequence at once. Both evaluate the planner's own stage cost on the positions a
sequence reaches, so the four methods of Table 3 optimise one objective.

Step model (as the planner's): a control (dtheta rad, speed m/s) first turns the heading,
then moves ``speed * T_o`` metres along it.
"""

from __future__ import annotations

import numpy as np

from auv_swarm.agent.planner import Neighbour, Plan, PlanProblem
from auv_swarm.agent.planner.context import Context
from auv_swarm.agent.planner.cost import leg_closest, plan_terms, stage_cost
from auv_swarm.agent.planner.problem import LEG_TOL_M

OWN_TERMS = ("distance", "penalty", "terminal")
"""Terms of eq. (38) that depend on one agent's own sequence only (eq. 36, the soft range of eq. 50, terminal)."""

SHARED_TERMS = ("geometry", "connectivity")
"""Terms of eq. (38) that depend on every agent's positions (eqs. 34-35, 37)."""


def rollout(position: np.ndarray, heading: float, controls: np.ndarray, step_s: float) -> np.ndarray:
    """Positions (N, H, 2) in m after each step of the sequences ``controls`` (N, H, 2), turn then go."""
    u = np.asarray(controls, dtype=float)
    if u.ndim != 3 or u.shape[2] != 2:
        raise ValueError(f"controls must be an (N, H, 2) array of (dtheta, speed), got shape {u.shape}")
    headings = float(heading) + np.cumsum(u[:, :, 0], axis=1)
    run = u[:, :, 1] * float(step_s)
    out = np.empty(u.shape)
    out[:, :, 0] = float(position[0]) + np.cumsum(run * np.cos(headings), axis=1)
    out[:, :, 1] = float(position[1]) + np.cumsum(run * np.sin(headings), axis=1)
    return out


class SequenceCost:
    """Cost of eq. (38) and safety violation of any sequences for one problem (its fixed parts built once)."""

    def __init__(self, problem: PlanProblem) -> None:
        self.problem = problem
        self.ctx = Context(problem)

    def __call__(self, controls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cost (N,) and total safety violation (N,) in m of each sequence in ``controls`` (N, H, 2)."""
        ctx = self.ctx
        u = np.asarray(controls, dtype=float)
        if u.ndim != 3 or u.shape[1] != ctx.H:
            raise ValueError(f"controls must be an (N, H = {ctx.H}, 2) array, got shape {u.shape}")
        way = rollout(self.problem.position, self.problem.heading, u, ctx.T)
        cost = np.zeros(u.shape[0])
        viol = np.zeros(u.shape[0])
        for h in range(1, ctx.H + 1):
            x, y = np.ascontiguousarray(way[:, h - 1, 0]), np.ascontiguousarray(way[:, h - 1, 1])
            c, v = stage_cost(ctx, h, x, y)
            cost += c
            viol += v
        return cost, viol


def sequence_costs(problem: PlanProblem, controls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cost of eq. (38) (N,) and total safety violation (N,) in m of each sequence in ``controls`` (N, H, 2).

    For a sequence on the problem's control grid this is the cost :func:`agent.planner.plan`
    minimises (same stage cost, same sigma points, same neighbours).
    """
    return SequenceCost(problem)(controls)


def grid_indices(problem: PlanProblem, controls: np.ndarray) -> np.ndarray:
    """Control-set indices (H,) closest to the sequence ``controls`` (H, 2): what the acoustic payload can carry.

    Headings are quantised cumulatively (each step's grid turn is the one whose summed heading
    is nearest the sequence's summed heading), so quantisation errors do not pile up along the
    plan; speeds go to the nearest speed of the control set (``planner.speed_set``).
    """
    cs = problem.controls
    u = np.asarray(controls, dtype=float).reshape(-1, 2)
    target = np.cumsum(u[:, 0])
    held = 0.0
    out = np.empty(u.shape[0], dtype=np.int64)
    for h in range(u.shape[0]):
        a = int(np.argmin(np.abs(held + cs.dtheta - target[h])))
        held += float(cs.dtheta[a])
        s = int(np.argmin(np.abs(u[h, 1] - cs.speeds)))
        out[h] = a * cs.speeds.size + s
    return out


def plan_of(problem: PlanProblem, controls: np.ndarray, nodes: int) -> Plan:
    """A :class:`Plan` for the sequence ``controls`` (H, 2): its cost, terms and waypoints.

    ``indices`` are the nearest grid indices (:func:`grid_indices`); ``controls`` keep the
    sequence itself, so a continuous plan is executed as planned and only quantised on the link.
    """
    ctx = Context(problem)
    u = np.asarray(controls, dtype=float).reshape(ctx.H, 2)
    way = rollout(problem.position, problem.heading, u[None], ctx.T)[0]
    terms, cost = plan_terms(ctx, way)
    return Plan(
        controls=u.copy(),
        indices=grid_indices(problem, u),
        cost=cost,
        terms=terms,
        feasible=terms["safety_violation_m"] == 0.0,
        waypoints=way,
        nodes=nodes,
    )


def own_terms(problem: PlanProblem, controls: np.ndarray) -> float:
    """Sum of the own terms (:data:`OWN_TERMS`) of one agent's sequence (H, 2): independent of the others."""
    alone = PlanProblem(
        position=problem.position,
        heading=problem.heading,
        xi=problem.xi,
        P=problem.P,
        neighbours=(),
        controls=problem.controls,
        planner=problem.planner,
        channel=problem.channel,
    )
    terms = plan_of(alone, controls, 0).terms
    return float(sum(terms[k] for k in OWN_TERMS))


def pair_violation(a: Neighbour, b: Neighbour, step_s: float, d_safe_m: float, first_leg: bool = True) -> float:
    """Safety violation sum_h max(0, d_S - |p_a,h - p_b,h|) (m) of two agents' sequences.

    With ``first_leg`` (``planner.leg_constraint`` other than "ends") step 1 also counts how much closer than
    min(d_S, their distance at the start) the two come along it, on straight legs (the planner's
    "straight" reading: the centralised plan has no turn margin or flown arc).
    """
    pa, pb = a.trajectory(step_s), b.trajectory(step_s)
    gap = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    short = np.maximum(d_safe_m - gap, 0.0)
    if first_leg:
        ax, ay = a.position[0] - b.position[0], a.position[1] - b.position[1]
        bx = (pa[0, 0] - a.position[0]) - (pb[0, 0] - b.position[0])
        by = (pa[0, 1] - a.position[1]) - (pb[0, 1] - b.position[1])
        dip = min(d_safe_m, float(np.hypot(ax, ay))) - float(leg_closest(ax, ay, bx, by))
        short[0] = max(short[0], dip if dip > LEG_TOL_M else 0.0)
    return float(np.sum(short))
