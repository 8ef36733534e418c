"""Decentralised MPC (dec-MPC), the paper's section 3.3 baseline.

"Each agent optimizes its trajectory assuming neighboring agents follow an optimal
policy, without any exchange of control sequences." Our reading:

- the acoustic payload carries no plan (its plan field is empty, H = 0), only the sender's
  state, base speed and new bearings (share and estimate is unchanged), so a receiver
  knows a neighbour's last state and dead-reckons it straight on at its base speed;
- at its planning instant an AUV predicts each neighbour j's plan by solving j's problem
  itself with the exact planner: j's dead-reckoned position and heading now, this AUV's
  own target estimate, j's base speed of eq. (47) from that estimate, and as j's
  neighbours this AUV (following its own previous plan, which it knows; straight on at its
  base speed before the first) and the other neighbours (their plans predicted earlier in
  the same call, else straight on). One level of prediction: predicted neighbours do not
  in turn predict anyone. Neighbours are predicted in id order;
- it then solves its own problem against the predicted plans. Its optimisation time counts
  every solve (the agent times the whole :meth:`DecMpcPlanner.plan`).
"""

from __future__ import annotations

import numpy as np

from auv_swarm.agent.planner import Neighbour, Plan, PlanProblem, base_speed, control_set, plan, warm_up
from auv_swarm.contract.config import Scenario


class DecMpcPlanner:
    """dec-MPC for one AUV: the planner protocol's ``plan(problem)``, neighbours' plans predicted, not received."""

    shares_plans = False
    """The payload carries no plan for this method."""

    def __init__(self, scenario: Scenario, auv: int) -> None:
        self.u_max = scenario.agents.u_max_mps
        self.r_max = scenario.agents.r_max_radps
        warm_up(scenario.planner, scenario.channel, self.u_max, self.r_max)
        self.last: np.ndarray | None = None
        self.predictions = 0

    def predict(self, problem: PlanProblem) -> tuple[Neighbour, ...]:
        """Each neighbour of ``problem`` with its predicted plan (the exact optimum of its problem as seen here)."""
        pl = problem.planner
        xi, H = problem.xi, int(pl.horizon)
        me = Neighbour(
            id=-1,
            position=tuple(problem.position),
            heading=problem.heading,
            sequence=self.last if self.last is not None else np.tile([0.0, float(problem.controls.speeds[1])], (H, 1)),
        )
        current = {nb.id: nb for nb in problem.neighbours}
        for nb in problem.neighbours:
            pos = np.asarray(nb.position, dtype=float)
            rng = float(np.hypot(*(xi[:2] - pos)))
            u_e = base_speed(rng, pl.d_star_m, float(np.hypot(*xi[2:])), pl.step_s, self.u_max)
            around = (me, *(current[k] for k in sorted(current) if k != nb.id))
            theirs = PlanProblem(
                position=pos,
                heading=nb.heading,
                xi=xi,
                P=problem.P,
                neighbours=around,
                controls=control_set(pl, u_e, self.u_max, self.r_max),
                planner=pl,
                channel=problem.channel,
                link=problem.link,
            )
            current[nb.id] = Neighbour(nb.id, nb.position, nb.heading, plan(theirs).controls)
            self.predictions += 1
        return tuple(current[nb.id] for nb in problem.neighbours)

    def plan(self, problem: PlanProblem) -> Plan:
        """Predict every neighbour's plan, then the exact own plan against those predictions."""
        own = PlanProblem(
            position=problem.position,
            heading=problem.heading,
            xi=problem.xi,
            P=problem.P,
            neighbours=self.predict(problem),
            controls=problem.controls,
            planner=problem.planner,
            channel=problem.channel,
            link=problem.link,
        )
        result = plan(own)
        self.last = result.controls
        return result
