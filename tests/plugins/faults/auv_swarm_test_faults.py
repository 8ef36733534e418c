"""Fault-injection methods for the tests, installed as a plug-in package (entry points in pyproject.toml).

- planner ``fault-raise``: the DMPC, but its first plan raises when ``run.seed`` is :data:`FAULT_SEED` (a mission
  whose plug-in raises: ``incomplete_reason = "method_error"``, a failed row in a sweep);
- planner ``fault-die``: the DMPC, but its process dies (``os._exit``, after :data:`DIE_AFTER_S` wall seconds, so
  the sweep's scheduler has placed the task) when it is built for a mission of seed :data:`FAULT_SEED`: a worker
  that dies under the same mission every time;
- estimator ``fault-raise``: the constant-velocity window (``wls-cv``), but it raises from t = :data:`RAISE_AT_S`.
"""

from __future__ import annotations

import os
import time

from auv_swarm.agent.estimator import BearingEstimator
from auv_swarm.agent.planner.protocol import DmpcPlanner

FAULT_SEED = 2
DIE_AFTER_S = 1.5
RAISE_AT_S = 30.0


class RaiseOnSeed(DmpcPlanner):
    """DMPC whose plans raise in the missions of seed :data:`FAULT_SEED`."""

    def __init__(self, scenario, auv: int) -> None:
        super().__init__(scenario, auv)
        self.seed = scenario.run.seed

    def plan(self, problem):
        if self.seed == FAULT_SEED:
            raise RuntimeError(f"failure injected by the fault-raise planner (seed {self.seed})")
        return super().plan(problem)


class DieOnSeed(DmpcPlanner):
    """DMPC whose process dies when it is built for a mission of seed :data:`FAULT_SEED`."""

    def __init__(self, scenario, auv: int) -> None:
        if scenario.run.seed == FAULT_SEED:
            time.sleep(DIE_AFTER_S)
            os._exit(70)
        super().__init__(scenario, auv)


class RaiseAfter(BearingEstimator):
    """``wls-cv`` that raises at every update from t = :data:`RAISE_AT_S` on."""

    def update(self, bearings, t_s: float):
        if t_s >= RAISE_AT_S:
            raise ValueError("failure injected by the fault-raise estimator")
        return super().update(bearings, t_s)
