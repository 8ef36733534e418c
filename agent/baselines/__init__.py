"""The section 3.3 baselines beside our DMPC: dec-MPC, distributed PSO and centralised MPC.

All three minimise the DMPC's own cost (eq. 38 with the constraints of eq. 50) through
:mod:`agent.baselines.cost`; they differ in what an AUV knows of the others and how it
searches. The method of a run is ``planner.method``; see docs/baselines.md.
"""

from __future__ import annotations

from contract.config import Scenario


def make_method_planner(scenario: Scenario, auv: int) -> object | None:
    """The planner of AUV ``auv`` for ``planner.method`` (``plan(problem) -> Plan``); None for centralised.

    Under the centralised method the AUV does not plan: it follows the central planner
    (:mod:`central.core`).
    """
    from agent.baselines.decmpc import DecMpcPlanner
    from agent.baselines.dpso import DpsoPlanner
    from agent.planner import DmpcPlanner

    method = scenario.planner.method
    factories = {"dmpc": DmpcPlanner, "dec-mpc": DecMpcPlanner, "dpso": DpsoPlanner}
    if method == "centralised":
        return None
    return factories[method](scenario, auv)
