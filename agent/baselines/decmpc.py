"""Decentralised MPC (dec-MPC), the paper's section 3.3 baseline.

"Each agent optimizes its trajectory assuming neighboring agents follow an optimal
policy, without any exchange of control sequences." Our reading:

- the acoustic payload carries no plan (H = 0 in the payload), only the sender's state,
  its base speed and its new bearings (share and estimate is unchanged);
- at its planning instant an AUV predicts each live neighbour j's plan by solving j's
  problem itself, with the exact planner: j's state as last received (time t_j), the
  AUV's *own* target estimate moved to t_j with the constant-velocity model (eq. 50),
  j's base speed of eq. (47) from that estimate, and as j's neighbours this AUV (its own
  current plan, which it knows) and the other neighbours (their latest predicted plans,
  or straight on at their base speed before any prediction). One level of prediction:
  the predicted neighbours do not in turn predict anyone;
- it then solves its own problem against those predicted plans (eq. 43 with predictions
  in place of the received plans). Its optimisation time counts every solve.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from agent.planner import PlanProblem, base_speed, control_set, plan
from contract.config import ChannelConfig, PlannerConfig


class Track(Protocol):
    """What an AUV knows of another (``agent.core.NeighbourTrack``): a state at ``t_s`` and a sequence after it."""

    auv: int
    t_s: float
    position: np.ndarray
    heading: float
    controls: np.ndarray
    u_e: float

    def as_neighbour(self, t_s: float, step_s: float, horizon: int): ...


def moved_belief(xi: np.ndarray, P: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The target belief (xi, P) moved by ``dt_s`` seconds (may be negative) with F of eq. (50)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt_s
    return F @ np.asarray(xi, dtype=float), F @ np.asarray(P, dtype=float) @ F.T


def predict_plans(
    me: Track,
    others: Sequence[Track],
    previous: dict[int, Track],
    xi: np.ndarray,
    P: np.ndarray,
    t_est_s: float,
    planner: PlannerConfig,
    channel: ChannelConfig,
    u_max: float,
    r_max: float,
) -> list[Track]:
    """Each of ``others`` with its predicted plan: the exact optimum of its own problem as this AUV sees it.

    ``me``: this AUV with its current plan. ``others``: the neighbours' last received states
    (their ``controls`` are ignored). ``previous``: the last prediction per neighbour id,
    used for the neighbours of a neighbour until it is predicted afresh in this call (only
    while it starts from that neighbour's latest state; a newer state goes straight on at its
    base speed until predicted).
    (xi, P): this AUV's target estimate at ``t_est_s``. Returns the tracks in the order of
    ``others``, each a copy with ``controls`` and ``u_e`` replaced.
    """
    H, step = int(planner.horizon), float(planner.step_s)
    latest: dict[int, Track] = {**previous}
    out = []
    for nb in others:
        x_j, p_j = moved_belief(xi, P, nb.t_s - t_est_s)
        pos = np.asarray(nb.position, dtype=float)
        u_e = base_speed(float(np.hypot(*(x_j[:2] - pos))), planner.d_star_m, float(np.hypot(*x_j[2:])), step, u_max)
        around = [me] + [_freshest(latest.get(k.auv), k) for k in others if k.auv != nb.auv]
        problem = PlanProblem(
            position=pos,
            heading=nb.heading,
            xi=x_j,
            P=p_j,
            neighbours=tuple(t.as_neighbour(nb.t_s, step, H) for t in around),
            controls=control_set(planner, u_e, u_max, r_max),
            planner=planner,
            channel=channel,
        )
        predicted = dataclasses.replace(nb, controls=plan(problem).controls, u_e=u_e)
        latest[nb.auv] = predicted
        out.append(predicted)
    return out


def _freshest(predicted: Track | None, raw: Track) -> Track:
    """The prediction if it starts from the neighbour's latest state, else the state going straight on."""
    return predicted if predicted is not None and predicted.t_s >= raw.t_s else raw
