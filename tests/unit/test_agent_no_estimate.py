"""Issue 27 item 2: without an estimate an AUV does not run on along its last plan; it returns towards its last
estimate and holds there, never getting farther from it."""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.core import AgentCore
from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.world.model import vehicle_step


def test_without_an_estimate_the_auv_returns_to_its_last_estimate_and_holds() -> None:
    scenario = load_scenario("paper-3.1-scenario1")
    core = AgentCore(0, scenario)
    fix = np.array([-30.0, -100.0])
    core.last_fix = (float(fix[0]), float(fix[1]))
    state = np.array([270.0, -100.0, 0.0])  # 300 m east of the fix, heading east (away)
    core.command_hold = (0.0, 1.0)  # the step it was executing: run on east at 1 m/s
    start = float(np.hypot(*(state[:2] - fix)))
    dists, commands = [], []
    dt = scenario.run.tick_s
    for tick in range(1500):
        t = tick * dt
        nav = wire.Nav(
            t_s=t, source="world", tick=tick, auv=0, x=state[0], y=state[1], theta=state[2], u=0.0, r=0.0, rx_expected=0
        )
        sensor = wire.Sensor(t_s=t, source="world", tick=tick, auv=0, bearing_rad=None)
        out = core.on_tick(nav, sensor, [])
        assert not out.telemetry.estimate_ok
        commands.append((out.command.u, out.command.r))
        state = vehicle_step(state, out.command.u, out.command.r, dt, core.u_max, core.r_max)
        dists.append(float(np.hypot(*(state[:2] - fix))))
    assert max(dists) <= start + 1e-6  # never farther than when the estimate was lost
    assert dists[-1] <= scenario.planner.d_star_m + 1.0
    assert commands[-1][0] == 0.0  # holding
    assert commands[0][0] == 0.0 and abs(commands[0][1]) == core.r_max  # facing away: turns in place first


def test_before_any_estimate_the_auv_stays_still() -> None:
    core = AgentCore(1, load_scenario("paper-3.1-scenario1"))
    nav = wire.Nav(t_s=0.0, source="world", tick=0, auv=1, x=0.0, y=0.0, theta=1.0, u=0.0, r=0.0, rx_expected=0)
    out = core.on_tick(nav, wire.Sensor(t_s=0.0, source="world", tick=0, auv=1, bearing_rad=None), [])
    assert (out.command.u, out.command.r) == (0.0, 0.0) and math.isfinite(out.telemetry.fiedler)
