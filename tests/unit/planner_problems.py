"""Random single-AUV planning problems for the planner's tests (exact search, reference cost)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from hypothesis import strategies as st

from auv_swarm.agent.planner import Neighbour, PlanProblem, base_speed, control_set
from auv_swarm.contract.config import ChannelConfig, PlannerConfig


def random_problem(
    rng: np.random.Generator,
    *,
    n_headings: int,
    horizon: int,
    n_neighbours: int,
    range_m: tuple[float, float] = (300.0, 1500.0),
    velocity_sd: float = 0.5,
    position_scale: tuple[float, float] = (5.0, 150.0),
    velocity_scale: tuple[float, float] = (0.05, 0.8),
    u_e: float | None = None,
    spread_m: float = 1500.0,
    noise_db: float | Sequence[float] = 40.0,
    **planner: float,
) -> PlanProblem:
    """The AUV at the origin with a random heading; the target estimate at a uniform bearing and a range uniform in
    ``range_m`` (m), velocity ~ N(0, ``velocity_sd``) m/s, covariance A A^T with A's position rows scaled by a
    uniform draw from ``position_scale`` (m) and its velocity rows from ``velocity_scale`` (m/s);
    ``n_neighbours`` neighbours uniform in +-``spread_m`` (m) following random sequences of the control set.

    Step 130 s, d* 500 m, d_max 1500 m, and ``planner``'s other config keys; the base speed of eq. (47) unless
    ``u_e`` is given (m/s). ``noise_db``: the channel's noise level (dB), or levels to draw it from (last).
    """
    cfg = PlannerConfig(horizon=horizon, n_headings=n_headings, step_s=130.0, d_star_m=500.0, d_max_m=1500.0, **planner)
    bearing = rng.uniform(-math.pi, math.pi)
    rng_m = rng.uniform(*range_m)
    xi = np.array([rng_m * math.cos(bearing), rng_m * math.sin(bearing), *rng.normal(0.0, velocity_sd, 2)])
    a = (
        rng.normal(size=(4, 4))
        * np.array([rng.uniform(*position_scale)] * 2 + [rng.uniform(*velocity_scale)] * 2)[:, None]
    )
    if u_e is None:
        u_e = base_speed(rng_m, cfg.d_star_m, float(np.hypot(*xi[2:])), cfg.step_s, 2.0)
    controls = control_set(cfg, u_e, 2.0, 0.05)
    nbs = []
    for j in range(n_neighbours):
        seq = np.column_stack([rng.choice(controls.dtheta, horizon), rng.choice([0.0, 1.0, 2.0], horizon)])
        pos = tuple(rng.uniform(-spread_m, spread_m, 2))
        nbs.append(Neighbour(id=j + 1, position=pos, heading=rng.uniform(-math.pi, math.pi), sequence=seq))
    heading = rng.uniform(-math.pi, math.pi)
    level = noise_db if isinstance(noise_db, (int, float)) else float(rng.choice(noise_db))
    return PlanProblem(
        position=np.zeros(2),
        heading=heading,
        xi=xi,
        P=a @ a.T,
        neighbours=tuple(nbs),
        controls=controls,
        planner=cfg,
        channel=ChannelConfig(noise_level_db=level),
    )


def problem_sizes(headings: Sequence[int], max_horizon: int, max_neighbours: int) -> dict[str, st.SearchStrategy]:
    """Hypothesis strategies for a random problem's ``seed``, ``n_headings`` (one of ``headings``), ``horizon``
    (1 to ``max_horizon`` steps) and ``n_neighbours`` (0 to ``max_neighbours``), to spread into ``@given``."""
    return {
        "seed": st.integers(0, 2**32 - 1),
        "n_headings": st.sampled_from(list(headings)),
        "horizon": st.integers(1, max_horizon),
        "n_neighbours": st.integers(0, max_neighbours),
    }
