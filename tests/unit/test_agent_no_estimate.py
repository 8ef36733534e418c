"""Issue 27 item 2: without an estimate an AUV does not run on along its last plan; it returns towards its last
estimate and holds there, never getting farther from it. Before its first estimate it spreads from its team
across the line of sight, at most d_M / 2 from where it began (a cluster gains the baseline it needs)."""

from __future__ import annotations

import math

import numpy as np

from auv_swarm.agent.core import AgentCore, NeighbourTrack
from auv_swarm.agent.estimator import not_ok
from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.contract.geometry import wrap_angle
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


def test_before_its_first_bearing_the_auv_stays_still() -> None:
    core = AgentCore(1, load_scenario("paper-3.1-scenario1"))
    nav = wire.Nav(t_s=0.0, source="world", tick=0, auv=1, x=0.0, y=0.0, theta=1.0, u=0.0, r=0.0, rx_expected=0)
    out = core.on_tick(nav, wire.Sensor(t_s=0.0, source="world", tick=0, auv=1, bearing_rad=None), [])
    assert (out.command.u, out.command.r) == (0.0, 0.0) and math.isfinite(out.telemetry.fiedler)


def _spread(core: AgentCore, bearing: float, ticks: int, monkeypatch) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Run ``core`` from the origin (heading east) with a constant bearing and an estimator that never fixes."""
    monkeypatch.setattr(core.estimator, "update", lambda bearings, t_s: not_ok(t_s, "test: no fix"))
    state = np.array([0.0, 0.0, 0.0])
    dt = core.scenario.run.tick_s
    commands = []
    for tick in range(ticks):
        t = tick * dt
        nav = wire.Nav(
            t_s=t, source="world", tick=tick, auv=core.auv, x=state[0], y=state[1], theta=state[2], u=0.0, r=0.0,
            rx_expected=0,
        )  # fmt: skip
        out = core.on_tick(nav, wire.Sensor(t_s=t, source="world", tick=tick, auv=core.auv, bearing_rad=bearing), [])
        commands.append((out.command.u, out.command.r))
        state = vehicle_step(state, out.command.u, out.command.r, dt, core.u_max, core.r_max)
    return state, commands


def test_before_its_first_estimate_a_lone_auv_spreads_across_the_line_of_sight_and_stops_at_half_d_max(
    monkeypatch,
) -> None:
    scenario = load_scenario("paper-3.1-scenario1")
    core = AgentCore(0, scenario)  # slot position 0, no neighbour heard: the left-hand side
    bearing = math.pi / 4
    state, commands = _spread(core, bearing, 600, monkeypatch)
    half = 0.5 * scenario.planner.d_max_m
    travelled = float(np.hypot(state[0], state[1]))
    assert half <= travelled <= half + core.u_max * scenario.run.tick_s
    left = bearing + math.pi / 2  # across the line of sight, to the left
    assert abs(wrap_angle(state[2] - left)) < 1e-9  # holds that heading exactly
    direction = math.atan2(state[1], state[0])
    assert abs(direction - left) < math.radians(10.0)  # the first turn (radius u_max / r_max = 20 m) bends it
    wait = int(scenario.planner.step_s / scenario.run.tick_s)
    first = next(i for i, c in enumerate(commands) if c != (0.0, 0.0))
    frame = core.frame_s / scenario.run.tick_s  # its slot comes once a TDMA frame
    assert wait <= first < wait + frame  # still for one step T_o (the first estimate may yet come), then its slot
    assert commands[first][0] == core.u_max and commands[-1][0] == 0.0  # spreads at u_max, then stops


def test_an_auv_spreads_away_from_the_team_it_has_heard(monkeypatch) -> None:
    scenario = load_scenario("paper-3.1-scenario1")
    core = AgentCore(1, scenario)  # slot position 1: alone it would take the right-hand side
    bearing = 0.0  # the source due east; left is north
    core.neighbours[0] = NeighbourTrack(
        auv=0, t_s=0.0, position=np.array([0.0, -40.0]), heading=0.0, controls=np.zeros((0, 2)), u_e=0.0, round=0,
        last_heard_s=0.0,
    )  # fmt: skip
    state, commands = _spread(core, bearing, 200, monkeypatch)
    assert commands[60] != (0.0, 0.0) and set(commands[:60]) == {(0.0, 0.0)}  # T_o = 60 s, then its slot at 60 s
    turn_radius = core.u_max / core.r_max  # it turns north at u_max: an arc of this radius first
    assert state[1] > 50.0 and abs(state[0]) <= turn_radius + 1.0  # away from the neighbour to its south: north
