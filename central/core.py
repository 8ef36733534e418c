"""The central planner of the centralised MPC baseline (paper section 3.3), tick by tick, as a pure object.

"Not feasible in practice" underwater, it is the lower bound of Table 3: one planner that
knows every live AUV's navigation state and every bearing the moment it is measured (no
acoustic channel, no delay, no loss). It keeps one estimator (eqs. 11-15) fed with every
AUV's bearings and, at the first tick of every TDMA frame (the DMPC's re-planning period,
n T_s), plans all live AUVs jointly (:func:`agent.baselines.centralised.joint_plan`), each
from its navigation (where it believes it is; its true pose under perfect navigation). Every
tick it sends each AUV the team's estimate and, at planning ticks, that AUV's plan; the AUVs
only follow (``agent.core``, method ``centralised``). The joint search starts from the previous
joint plan re-sampled to now (policy of intent, eq. 42), or from every AUV going straight on at
its base speed.
"""

from __future__ import annotations

import math
import time

import numpy as np

from auv_swarm.agent.baselines.centralised import Member, joint_plan
from auv_swarm.agent.core import NeighbourTrack
from auv_swarm.agent.estimator import Bearing, BearingEstimator, Estimate
from auv_swarm.agent.planner import base_speed, control_set, warm_up
from auv_swarm.contract import wire
from auv_swarm.contract.acoustics import fiedler_value, snr_laplacian
from auv_swarm.contract.config import Scenario

_EPS = 1e-9
SOURCE = "central"


class CentralCore:
    """Estimator and joint planner of the centralised MPC; see the module docstring."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.order = scenario.slot_order
        self.frame_s = len(self.order) * scenario.channel.slot_s
        self.u_max = scenario.agents.u_max_mps
        self.r_max = scenario.agents.r_max_radps
        self.estimator = BearingEstimator(scenario.estimator, math.radians(scenario.sensor.sigma_m_deg))
        warm_up(scenario.planner, scenario.channel, self.u_max, self.r_max)
        self.tracks: dict[int, NeighbourTrack] = {}
        self.plans = 0

    def _is_frame_start(self, t_s: float) -> bool:
        frame = math.floor(t_s / self.frame_s + _EPS)
        return t_s - frame * self.frame_s < self.scenario.run.tick_s - _EPS

    def on_tick(
        self, tick: int, t_s: float, navs: dict[int, wire.Nav], sensors: dict[int, wire.Sensor]
    ) -> dict[int, wire.CentralPlan]:
        """One tick: every live AUV's navigation and bearing in, one :class:`wire.CentralPlan` per AUV out."""
        alive = sorted(navs)
        self.estimator.add(
            Bearing(t_s=t_s, sensor_xy=(navs[a].x, navs[a].y), bearing_rad=s.bearing_rad, source=a)
            for a, s in sorted(sensors.items())
            if s.bearing_rad is not None and a in navs
        )
        est = self.estimator.estimate(t_s)
        planned, wall_ms = {}, 0.0
        if self._is_frame_start(t_s) and est.ok and alive:
            start = time.perf_counter()
            planned = self._joint(t_s, navs, est)
            wall_ms = (time.perf_counter() - start) * 1e3
            self.plans += 1
        positions = np.array([(navs[a].x, navs[a].y) for a in alive])
        fiedler = float(fiedler_value(snr_laplacian(positions, self.scenario.channel))) if len(alive) > 1 else 0.0
        out = {}
        for a in alive:
            p = planned.get(a)
            out[a] = wire.CentralPlan(
                t_s=t_s,
                source=SOURCE,
                tick=tick,
                auv=a,
                estimate_ok=bool(est.ok),
                estimate_reason=est.reason[:200],
                xi=tuple(np.asarray(est.xi, dtype=float).tolist()),
                P=tuple(np.asarray(est.reported_P, dtype=float).ravel().tolist()),
                n_measurements=len(self.estimator),
                planned=p is not None,
                plan=tuple((float(u), float(v)) for u, v in p.controls) if p is not None else (),
                waypoints=tuple((float(x), float(y)) for x, y in p.waypoints) if p is not None else (),
                cost=float(p.cost) if p is not None else 0.0,
                terms={k: float(v) for k, v in p.terms.items()} if p is not None else {},
                plan_wall_ms=wall_ms if p is not None else 0.0,
                fiedler=fiedler,
            )
        return out

    def _joint(self, t_s: float, navs: dict[int, wire.Nav], est: Estimate) -> dict:
        pl = self.scenario.planner
        H, step = pl.horizon, pl.step_s
        p_hat, speed_hat = est.xi[:2], float(np.hypot(*est.xi[2:]))
        members, start = [], {}
        for a in sorted(navs):
            nav = navs[a]
            rng = float(np.hypot(p_hat[0] - nav.x, p_hat[1] - nav.y))
            u_e = base_speed(rng, pl.d_star_m, speed_hat, step, self.u_max)
            members.append(
                Member(
                    id=a,
                    position=(nav.x, nav.y),
                    heading=nav.theta,
                    controls=control_set(pl, u_e, self.u_max, self.r_max),
                )
            )
            track = self.tracks.get(a)
            start[a] = track.as_neighbour(t_s, step, H).sequence if track is not None else np.tile([0.0, u_e], (H, 1))
        order = [a for a in self.order if a in navs]
        result = joint_plan(members, order, start, est.xi, est.P, pl, self.scenario.channel)
        for m in members:
            self.tracks[m.id] = NeighbourTrack(
                auv=m.id,
                t_s=t_s,
                position=np.array(m.position),
                heading=m.heading,
                controls=result.plans[m.id].controls,
                u_e=float(m.controls.speeds[1]),
                round=0,
                last_heard_s=t_s,
            )
        return result.plans
