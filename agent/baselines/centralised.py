"""Centralised MPC, the paper's section 3.3 lower bound: one planner, every AUV, full information.

The joint problem: choose every live AUV's control sequence at once to minimise the joint
cost of eq. (38) summed over the team,

    J = sum_h [ alpha / sigma_min(Phi_h) + gamma (n - 1) / lambda_2(L_h) ]
        + sum_i sum_h [ (1 - alpha) d_i,h / d* + soft range penalty_i,h ] + sum_i terminal_i,

subject to the safety distance d_S between every pair at every step (eq. 50; least total
violation first when no joint sequence is feasible). The geometry and connectivity terms
are shared (they depend on every AUV's position), the others are each AUV's own, so an
agent's DMPC cost is J minus the other agents' own terms: minimising agent i's cost with
the others fixed is exactly minimising J over agent i's sequence.

Search (|U|^(n H) = 27^15 joint sequences is out of reach): block coordinate descent, each
block one agent's whole sequence solved by the exact planner (:func:`agent.planner.plan`)
given the others, agents visited in turn until a full pass improves nobody (a change must
lower the agent's (violation, cost) by more than a relative 1e-12, so the descent ends).
It is run from the first ``planner.central_orders`` rotations of the slot order (default 1),
each from the same start (the previous joint plan re-sampled to now, or every agent going
straight on at its base speed), and the best joint result is kept. Measured on 28 joint plans
of Sim 2 and Sim 4 (600 s each, seed 1): the other two rotations found a lower J in 7, by
0.08 % at the median of those and 1.2 % at most, for three times the work (docs/baselines.md). :func:`exhaustive_joint` is the plain reference it is tested
against on small instances.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from auv_swarm.agent.baselines.cost import SequenceCost, own_terms, pair_violation, plan_of
from auv_swarm.agent.planner import ControlSet, Neighbour, Plan, PlanProblem, brute_force, plan
from auv_swarm.contract.config import ChannelConfig, PlannerConfig

_IMPROVE_RTOL = 1e-12


MAX_PASSES = 50
"""Coordinate descent stops after this many full passes over the team even if a move was still accepted."""


@dataclass(frozen=True)
class Member:
    """One AUV of the joint problem: position (m), heading (rad) and its control set (eqs. 46-49)."""

    id: int
    position: tuple[float, float]
    heading: float
    controls: ControlSet


@dataclass(frozen=True)
class JointPlan:
    """Every AUV's plan (as its own DMPC cost sees it given the others), the joint cost J and violation (m)."""

    plans: dict[int, Plan]
    cost: float
    violation_m: float
    solves: int
    order: tuple[int, ...]


@dataclass(frozen=True)
class _Team:
    """What stays fixed while a joint plan is sought: the live AUVs, the team's target estimate (``xi``, ``P``;
    eqs. 14-15) and the configs."""

    members: Sequence[Member]
    xi: np.ndarray
    P: np.ndarray
    planner: PlannerConfig
    channel: ChannelConfig
    link: object | None = None

    def problem(self, me: Member, others: Sequence[Member], seqs: Mapping[int, np.ndarray]) -> PlanProblem:
        """``me``'s single-agent problem with ``others`` following their sequences in ``seqs``.

        Its first leg is checked on straight legs (``"straight"`` for every ``planner.leg_constraint`` but
        ``"ends"``), as :func:`pair_violation` checks the pairs: the turn margin and the flown arc are the own
        vehicle's only, so two members would each see a different violation of the same pair, and the
        coordinate descent need not settle (it ran for minutes in a 6-AUV clustered coordination mission).
        """
        planner = self.planner
        if planner.leg_constraint != "ends":
            planner = dataclasses.replace(planner, leg_constraint="straight")
        return PlanProblem(
            position=np.array(me.position, dtype=float),
            heading=me.heading,
            xi=self.xi,
            P=self.P,
            neighbours=tuple(Neighbour(o.id, o.position, o.heading, seqs[o.id]) for o in others),
            controls=me.controls,
            planner=planner,
            channel=self.channel,
            link=self.link,
        )

    def cost(self, seqs: Mapping[int, np.ndarray]) -> tuple[float, float]:
        """(J, total pairwise safety violation in m) of the joint sequence ``seqs`` (id -> (H, 2))."""
        first, rest = self.members[0], list(self.members[1:])
        cost, viol = SequenceCost(self.problem(first, rest, seqs))(seqs[first.id][None])
        total = float(cost[0])
        violation = float(viol[0])
        for k, m in enumerate(rest):
            total += own_terms(self.problem(m, [], seqs), seqs[m.id])
            a = Neighbour(m.id, m.position, m.heading, seqs[m.id])
            for o in rest[k + 1 :]:
                b = Neighbour(o.id, o.position, o.heading, seqs[o.id])
                violation += pair_violation(
                    a, b, self.planner.step_s, self.planner.d_safe_m, self.planner.leg_constraint != "ends"
                )
        return total, violation

    def descend(self, order: Sequence[int], start: Mapping[int, np.ndarray]) -> tuple[dict[int, np.ndarray], int]:
        """Block coordinate descent from ``start`` visiting agents in ``order`` until a full pass changes nothing
        (or after ``MAX_PASSES`` passes, a guard against a descent that does not settle); (the joint sequence,
        how many single-agent plans it took)."""
        by_id = {m.id: m for m in self.members}
        seqs = {i: np.asarray(s, dtype=float) for i, s in start.items()}
        version = {i: 0 for i in seqs}
        solved_at: dict[int, tuple[int, ...]] = {}
        solves = 0
        changed = True
        passes = 0
        while changed and passes < MAX_PASSES:
            changed = False
            passes += 1
            for i in order:
                seen = tuple(version[j] for j in order if j != i)
                if solved_at.get(i) == seen:
                    continue
                problem = self.problem(by_id[i], [by_id[j] for j in order if j != i], seqs)
                best = plan(problem)
                solves += 1
                solved_at[i] = seen
                cost, viol = SequenceCost(problem)(seqs[i][None])
                now_v, now_c = float(viol[0]), float(cost[0])
                tol = _IMPROVE_RTOL * max(1.0, abs(now_c))
                new_v = float(best.terms["safety_violation_m"])
                if new_v < now_v - 1e-9 or (abs(new_v - now_v) <= 1e-9 and best.cost < now_c - tol):
                    seqs[i] = best.controls
                    version[i] += 1
                    changed = True
        return seqs, solves


def joint_cost(
    members: Sequence[Member],
    seqs: Mapping[int, np.ndarray],
    xi: np.ndarray,
    P: np.ndarray,
    planner: PlannerConfig,
    channel: ChannelConfig,
    link: object | None = None,
) -> tuple[float, float]:
    """(J, total pairwise safety violation in m) of the joint sequence ``seqs`` (id -> (H, 2)); ``link`` a
    physical ocean's link model."""
    return _Team(members, xi, P, planner, channel, link).cost(seqs)


def joint_plan(
    members: Sequence[Member],
    order: Sequence[int],
    start: Mapping[int, np.ndarray],
    xi: np.ndarray,
    P: np.ndarray,
    planner: PlannerConfig,
    channel: ChannelConfig,
    orders: int | None = None,
    link: object | None = None,
) -> JointPlan:
    """The best joint plan coordinate descent finds from the first ``orders`` rotations of ``order``.

    ``members``: the live AUVs; ``order``: their ids in slot order; ``start``: id -> (H, 2) start
    sequence; ``orders``: how many rotations (default ``planner.central_orders``, at most n); ``link`` a physical
    ocean's link model.
    """
    ids = [m.id for m in members]
    if sorted(order) != sorted(ids) or set(start) != set(ids):
        raise ValueError(f"order and start must name exactly the members {sorted(ids)}")
    team = _Team(members, xi, P, planner, channel, link)
    best: tuple[float, float, dict[int, np.ndarray], tuple[int, ...]] | None = None
    solves = 0
    k = planner.central_orders if orders is None else orders
    for r in range(max(1, min(int(k), len(order)))):
        rotation = tuple(order[r:]) + tuple(order[:r])
        seqs, n = team.descend(rotation, start)
        solves += n
        cost, viol = team.cost(seqs)
        if best is None or (viol, cost) < (best[1], best[0]):
            best = (cost, viol, seqs, rotation)
    assert best is not None
    cost, viol, seqs, rotation = best
    plans = {}
    for m in members:
        others = [o for o in members if o.id != m.id]
        plans[m.id] = plan_of(team.problem(m, others, seqs), seqs[m.id], 0)
    return JointPlan(plans=plans, cost=cost, violation_m=viol, solves=solves, order=rotation)


def exhaustive_joint(
    members: Sequence[Member],
    xi: np.ndarray,
    P: np.ndarray,
    planner: PlannerConfig,
    channel: ChannelConfig,
    link: object | None = None,
) -> tuple[float, float, dict[int, np.ndarray]]:
    """Reference: the least (violation, J) over all |U|^(n H) joint sequences on the grid (small instances only).

    Every sequence of the other agents is enumerated; the first agent's best reply to each is
    the exact single-agent brute force, which is its exact minimum of J given the others.
    """
    team = _Team(members, xi, P, planner, channel, link)
    first, rest = members[0], list(members[1:])
    H = int(planner.horizon)
    per_agent = [list(itertools.product(range(m.controls.size), repeat=H)) for m in rest]
    best: tuple[float, float, dict[int, np.ndarray]] | None = None
    for combo in itertools.product(*per_agent):
        seqs = {m.id: m.controls.controls[list(idx)] for m, idx in zip(rest, combo, strict=True)}
        seqs[first.id] = np.zeros((H, 2))
        reply = brute_force(team.problem(first, rest, seqs))
        seqs[first.id] = reply.controls
        cost, viol = team.cost(seqs)
        if best is None or (viol, cost) < (best[1], best[0]):
            best = (cost, viol, seqs)
    assert best is not None
    return best
