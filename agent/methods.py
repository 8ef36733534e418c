"""The planning methods an AUV can run, by the name ``planner.method`` gives them.

A scenario picks its method with ``planner.method`` (default ``"dmpc"``, the exact DMPC search of
:mod:`auv_swarm.agent.planner`). The agent builds its planner once with :func:`make_planner` and calls
``planner.plan(problem)`` at each of its slots; nothing else in the agent depends on the method.

Adding a method (docs/planner.md, "Adding a method"):
1. write a class with ``plan(self, problem: PlanProblem) -> Plan`` (the
   :class:`~auv_swarm.agent.planner.protocol.Planner` protocol; a pure core: any random stream comes
   from ``contract.rng.stream(scenario.run.seed, ...)`` in its constructor);
2. register its factory ``(scenario, auv) -> Planner`` in :data:`PLANNERS` under its name and add
   the name to ``contract.config.PLANNER_METHODS`` (a test checks the two agree).
"""

from __future__ import annotations

from collections.abc import Callable

from auv_swarm.agent.baselines.decmpc import DecMpcPlanner
from auv_swarm.agent.baselines.dpso import DpsoPlanner
from auv_swarm.agent.planner.protocol import DmpcPlanner, Planner
from auv_swarm.contract.config import ConfigError, Scenario

PlannerFactory = Callable[[Scenario, int], Planner]
"""Builds the planner of AUV ``auv`` for a scenario: ``factory(scenario, auv)``."""


PLANNERS: dict[str, PlannerFactory] = {
    "dmpc": DmpcPlanner,
    "dec-mpc": DecMpcPlanner,
    "dpso": DpsoPlanner,
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
