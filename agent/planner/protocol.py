"""The planner protocol: one verb, ``plan(problem) -> Plan``, and the registry of methods by name.

A scenario picks its method with ``planner.method`` (default ``"dmpc"``, today's exact DMPC
search). The agent builds its planner once with :func:`make_planner` and calls
``planner.plan(problem)`` at each of its slots; nothing else in the agent depends on the method.

Adding a method (docs/planner.md, "Adding a method"):
1. write a class with ``plan(self, problem: PlanProblem) -> Plan`` (a pure core: any random
   stream comes from ``contract.rng.stream(scenario.run.seed, ...)`` in its constructor);
2. register its factory ``(scenario, auv) -> Planner`` in :data:`PLANNERS` under its name and add
   the name to ``contract.config.PLANNER_METHODS`` (a test checks the two agree).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from auv_swarm.agent.planner.problem import Plan, PlanProblem
from auv_swarm.agent.planner.search import plan, warm_up
from auv_swarm.contract.config import ConfigError, Scenario


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


PlannerFactory = Callable[[Scenario, int], Planner]
"""Builds the planner of AUV ``auv`` for a scenario: ``factory(scenario, auv)``."""


def _dec_mpc(scenario: Scenario, auv: int) -> Planner:
    from auv_swarm.agent.baselines.decmpc import DecMpcPlanner

    return DecMpcPlanner(scenario, auv)


def _dpso(scenario: Scenario, auv: int) -> Planner:
    from auv_swarm.agent.baselines.dpso import DpsoPlanner

    return DpsoPlanner(scenario, auv)


PLANNERS: dict[str, PlannerFactory] = {
    "dmpc": DmpcPlanner,
    "dec-mpc": _dec_mpc,
    "dpso": _dpso,
}
"""Planning methods by the name ``planner.method`` gives them (the section 3.3 baselines: docs/baselines.md).

``centralised`` is not here: its AUVs do not plan, they follow the central planner (``central/``).
"""


def make_planner(scenario: Scenario, auv: int) -> Planner:
    """The planner ``scenario.planner.method`` names, for AUV ``auv``; ConfigError naming the key if unknown."""
    name = scenario.planner.method
    if name == "centralised":
        raise ConfigError("planner.method 'centralised' has no per-AUV planner: the AUVs follow the central planner")
    factory = PLANNERS.get(name)
    if factory is None:
        allowed = ", ".join(repr(k) for k in sorted(PLANNERS))
        raise ConfigError(f"planner.method must be one of {allowed}, got {name!r}")
    return factory(scenario, auv)
