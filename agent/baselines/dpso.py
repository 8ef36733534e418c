"""Distributed particle swarm optimisation (DPSO), the paper's section 3.3 baseline (Wang et al., 2023).

Each AUV plans in its TDMA slot inside the same sequential framework as the DMPC
(neighbours' fresh plans or policy of intent, eqs. 40-43) and minimises the same cost
(eq. 38 with the constraints of eq. 50), but over *continuous* control sequences: every
step's heading change in [-dtheta_max, +dtheta_max] rad and speed in [0, u_max] m/s,
the vehicle limits of eq. (50) (dtheta_max <= r_max T_o). A particle is one sequence,
a point of R^(2H).

The swarm (global-best topology, Kennedy and Eberhart 1995; inertia and acceleration
coefficients of Clerc and Kennedy 2002 by default):

    v <- w v + c1 r1 (p_best - x) + c2 r2 (g_best - x),   x <- clip(x + v, lo, hi)

with r1, r2 uniform in [0, 1) per component, |v| clamped to the box width. Particles
start uniformly in the box, with velocities uniform in [lo - x, hi - x] (SPSO-2011); one
particle starts at the agent's own policy of intent (its previous plan shifted by one step
and padded with the base control (0, u_e), eq. 42), the warm start every MPC uses; the
plan the AUV follows is the continuous one, the payload carries its nearest grid indices
(:func:`agent.baselines.cost.grid_indices`).
Comparison is lexicographic, as in the exact planner: less total safety violation first,
then less cost. Every draw comes from the generator passed in (the run's seed), so a
mission is deterministic.
"""

from __future__ import annotations

import numpy as np

from auv_swarm.agent.baselines.cost import SequenceCost, plan_of
from auv_swarm.agent.planner import Plan, PlanProblem
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.rng import stream


def _better(cost: np.ndarray, viol: np.ndarray, best_cost: np.ndarray, best_viol: np.ndarray) -> np.ndarray:
    """Lexicographic (violation, cost) comparison, element-wise."""
    return (viol < best_viol) | ((viol == best_viol) & (cost < best_cost))


def dpso_plan(problem: PlanProblem, rng: np.random.Generator, warm: np.ndarray | None = None) -> Plan:
    """The best continuous sequence a particle swarm finds for ``problem`` (swarm settings from ``planner.dpso_*``).

    ``warm``: an (H, 2) sequence placed as the first particle (clipped to the box), or None.
    ``Plan.nodes`` counts the sequences evaluated.
    """
    cfg = problem.planner
    H = int(cfg.horizon)
    n_p, iters = int(cfg.dpso_particles), int(cfg.dpso_iterations)
    w, c1, c2 = float(cfg.dpso_inertia), float(cfg.dpso_c1), float(cfg.dpso_c2)
    u_max = float(np.max(problem.controls.speeds))
    d_max = float(cfg.dtheta_max_rad)
    lo = np.tile([-d_max, 0.0], H)
    hi = np.tile([d_max, u_max], H)
    span = hi - lo
    x = lo + rng.random((n_p, 2 * H)) * span
    if warm is not None:
        x[0] = np.clip(np.asarray(warm, dtype=float).reshape(2 * H), lo, hi)
    v = (lo - x) + rng.random((n_p, 2 * H)) * span

    cost_of = SequenceCost(problem)

    def evaluate(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return cost_of(pos.reshape(-1, H, 2))

    cost, viol = evaluate(x)
    p_best, p_cost, p_viol = x.copy(), cost, viol
    g = _lex_argmin(p_cost, p_viol)
    for _ in range(iters):
        r1 = rng.random((n_p, 2 * H))
        r2 = rng.random((n_p, 2 * H))
        v = w * v + c1 * r1 * (p_best - x) + c2 * r2 * (p_best[g] - x)
        np.clip(v, -span, span, out=v)
        x = np.clip(x + v, lo, hi)
        cost, viol = evaluate(x)
        better = _better(cost, viol, p_cost, p_viol)
        p_best[better] = x[better]
        p_cost = np.where(better, cost, p_cost)
        p_viol = np.where(better, viol, p_viol)
        g = _lex_argmin(p_cost, p_viol)
    return plan_of(problem, p_best[g].reshape(H, 2), n_p * (iters + 1))


def _lex_argmin(cost: np.ndarray, viol: np.ndarray) -> int:
    """Index of the least violation, then least cost (first on ties)."""
    least = viol == viol.min()
    return int(np.argmin(np.where(least, cost, np.inf)))


class DpsoPlanner:
    """DPSO for one AUV (the planner protocol's ``plan(problem)``), drawing from the run's seed."""

    shares_plans = True
    """The payload carries the plan (quantised to the grid)."""

    def __init__(self, scenario: Scenario, auv: int) -> None:
        self.rng = stream(scenario.run.seed, "dpso", auv)
        self.last: np.ndarray | None = None

    def plan(self, problem: PlanProblem) -> Plan:
        """The swarm's best sequence, warm-started from the policy of intent of the previous plan (eq. 42)."""
        warm = None
        if self.last is not None:
            warm = np.vstack([self.last[1:], [0.0, float(problem.controls.speeds[1])]])
        result = dpso_plan(problem, self.rng, warm)
        self.last = result.controls
        return result
