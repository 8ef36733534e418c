"""The planner of one AUV (eqs. 27-50), a small package.

- :mod:`~agent.planner.problem`: control set (eqs. 46-49), unscented belief (eqs. 32-33),
  :class:`PlanProblem`, :class:`Neighbour`, :class:`Plan`;
- :mod:`~agent.planner.reference`: the cost of eqs. (34)-(38) and (50) written plainly from the
  paper, and :func:`brute_force` over every sequence with that cost;
- :mod:`~agent.planner.context`, :mod:`~agent.planner.cost`, :mod:`~agent.planner.graph`,
  :mod:`~agent.planner.search`: the fast exact search (merge graph + branch and bound) and its
  cost evaluation;
- :mod:`~agent.planner.protocol`: the :class:`Planner` protocol and the registry of methods
  chosen by ``planner.method``.

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
)
from auv_swarm.agent.planner.protocol import PLANNERS, Planner, make_planner
from auv_swarm.agent.planner.reference import brute_force
from auv_swarm.agent.planner.search import plan, warm_up

__all__ = [
    "LAMBDA_FLOOR",
    "N_XI",
    "PLANNERS",
    "SIGMA_FLOOR",
    "ControlSet",
    "Neighbour",
    "Plan",
    "PlanProblem",
    "Planner",
    "base_speed",
    "brute_force",
    "control_set",
    "make_planner",
    "plan",
    "sigma_points",
    "warm_up",
]
