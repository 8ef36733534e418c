"""The planner of one AUV (eqs. 27-50), a small package.

- :mod:`~auv_swarm.agent.planner.problem`: control set (eqs. 46-49), unscented belief (eqs. 32-33),
  :class:`PlanProblem`, :class:`Neighbour`, :class:`Plan`;
- :mod:`~auv_swarm.agent.planner.reference`: the cost of eqs. (34)-(38) and (50) written plainly from the
  paper, and :func:`brute_force` over every sequence with that cost;
- :mod:`~auv_swarm.agent.planner.context`, :mod:`~auv_swarm.agent.planner.cost`, :mod:`~auv_swarm.agent.planner.graph`,
  :mod:`~auv_swarm.agent.planner.search`: the fast exact search (merge graph + branch and bound) and its
  cost evaluation;
- :mod:`~auv_swarm.agent.planner.protocol`: the :class:`Planner` protocol and the DMPC's planner (the
  methods ``planner.method`` chooses from are registered in :mod:`auv_swarm.agent.methods`).

docs/planner.md describes the method and lists where our cost departs from the paper.
"""

from auv_swarm.agent.planner.problem import (
    LAMBDA_FLOOR,
    N_XI,
    SIGMA_FLOOR,
    ControlSet,
    Neighbour,
    Plan,
    PlanProblem,
    base_speed,
    control_set,
    sigma_points,
    speed_set,
)
from auv_swarm.agent.planner.protocol import Planner
from auv_swarm.agent.planner.reference import brute_force
from auv_swarm.agent.planner.search import plan, warm_up

__all__ = [
    "LAMBDA_FLOOR",
    "N_XI",
    "SIGMA_FLOOR",
    "ControlSet",
    "Neighbour",
    "Plan",
    "PlanProblem",
    "Planner",
    "base_speed",
    "brute_force",
    "control_set",
    "plan",
    "sigma_points",
    "speed_set",
    "warm_up",
]
