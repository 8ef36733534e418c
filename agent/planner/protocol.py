"""The planner protocol: one verb, ``plan(problem) -> Plan``, and our DMPC's planner.

The methods a scenario can pick with ``planner.method`` are registered in :mod:`auv_swarm.agent.methods`
(the DMPC here, the section 3.3 baselines in :mod:`auv_swarm.agent.baselines`); the planner package
imports no baseline.
"""

from __future__ import annotations

from typing import Protocol

from auv_swarm.agent.planner.problem import Plan, PlanProblem
from auv_swarm.agent.planner.search import plan, warm_up
from auv_swarm.contract.config import Scenario


class Planner(Protocol):
    """One planning method of one AUV (the Stone Soup habit: one small interface per role)."""

    def plan(self, problem: PlanProblem) -> Plan:
        """The control sequence this method chooses for ``problem`` (eq. 43), with its cost terms."""
        ...


class DmpcPlanner:
    """Our DMPC's planner: the exact minimiser of eq. (38) subject to eq. (50) (:func:`agent.planner.search.plan`).

    Builds the cached merge graphs of every control-set shape the agent can meet at construction,
    so that one-off cost stays out of the first plans' wall time.
    """

    shares_plans = True
    """The acoustic payload carries this method's plans (dec-MPC's planner says False)."""

    def __init__(self, scenario: Scenario, auv: int) -> None:
        warm_up(scenario.planner, scenario.channel, scenario.agents.u_max_mps, scenario.agents.r_max_radps)

    def plan(self, problem: PlanProblem) -> Plan:
        """Exact DMPC plan of ``problem`` (eqs. 29-31, 43)."""
        return plan(problem)
