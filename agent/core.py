"""One AUV's onboard logic, tick by tick: share and estimate, sequential DMPC, guidance.

The core is pure: it consumes the world's navigation and sensor messages and the
channel's modem deliveries for one tick, and returns the command, the modem
transmissions and the telemetry for that tick. The pose in the navigation message is
where the AUV believes it is (docs/navigation.md): it measures, plans, shares and steers
from it, and reports it in its telemetry. The zenoh shell (``agent.node``)
and the in-process runner drive the same object, so both give the same result.

Timing (paper section 2.5): the TDMA frame is T_f = n T_s. At the first tick of
its own slot an agent plans (eq. 43) with the freshest information it holds and
transmits [state, planned controls, new bearings] (section 2.4.2). Plans are
sequences of H steps of T_o seconds, anchored at the time they were made; a
neighbour's plan is re-sampled at this agent's planning instants, and extended
by its base control after its end, which is the policy of intent of eq. (42).
Agents earlier in the slot order have planned in this frame (fresh plans), later
ones are represented by their previous frame's plan (intent).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from auv_swarm.agent.estimator import Bearing, Estimate, make_estimator
from auv_swarm.agent.guidance import guidance
from auv_swarm.agent.methods import make_planner
from auv_swarm.agent.planner import ControlSet, Neighbour, Plan, PlanProblem, base_speed, control_set, speed_set
from auv_swarm.contract import wire
from auv_swarm.contract.acoustics import fiedler_value, snr_laplacian
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.geometry import wrap_angle
from auv_swarm.contract.ocean import OceanModel, slot_frame_bits
from auv_swarm.contract.payload import AcousticPayload, decode_payload, encode_payload
from auv_swarm.contract.tltable import ocean_for

_EPS = 1e-9
_SPREAD_CENTRE_M = 1.0
"""Within this much of the team's centre (m, across the line of sight) an AUV spreads by its slot position."""


def slot_index(t_s: float, slot_s: float) -> int:
    """The TDMA slot the sim time ``t_s`` (s) falls in, slots of ``slot_s`` (s) counted from 0 at t = 0; the slot's
    owner is ``scenario.slot_order[slot_index % n]`` (paper section 2.5)."""
    return math.floor(t_s / slot_s + _EPS)


def follow_anchor(anchor_m: float, distance_m: float, dt_s: float, tau_s: float) -> float:
    """The ``"topology"`` reading's reference pair distance after ``dt_s`` (eq. 37, docs/planner.md).

    ``tau_s = 0`` keeps it for good (the "topology of the network assigned in advance"); ``tau_s > 0``
    moves it toward the measured distance as a moving average, ``a + min(1, dt / tau) (d - a)``, so that a
    team keeps its formation over times shorter than tau and may let it drift over longer ones.
    """
    if tau_s <= 0.0:
        return anchor_m
    return anchor_m + min(1.0, max(dt_s, 0.0) / tau_s) * (distance_m - anchor_m)


@dataclass
class NeighbourTrack:
    """What this agent knows of another AUV, from its last decoded payload."""

    auv: int
    t_s: float
    position: np.ndarray
    heading: float
    controls: np.ndarray
    u_e: float
    round: int
    last_heard_s: float

    def path(self, t_s: float, step_s: float) -> tuple[np.ndarray, float]:
        """Position and heading at ``t_s`` along the announced plan, then the base control (eq. 42)."""
        s = max(0.0, t_s - self.t_s)
        x, y = self.position.tolist()
        heading = self.heading
        for dtheta, speed in self.controls.tolist():
            heading = heading + dtheta
            leg = min(s, step_s)
            run = speed * leg
            x, y = x + run * math.cos(heading), y + run * math.sin(heading)
            s -= leg
            if s <= 0.0:
                return np.array([x, y]), heading
        run = self.u_e * s
        return np.array([x + run * math.cos(heading), y + run * math.sin(heading)]), heading

    def as_neighbour(self, t_s: float, step_s: float, horizon: int) -> Neighbour:
        """The neighbour's plan re-sampled on this agent's planning instants t_s + h T_o."""
        samples = [self.path(t_s + h * step_s, step_s) for h in range(horizon + 1)]
        start, heading0 = samples[0]
        seq = np.zeros((horizon, 2))
        prev_heading = heading0
        for h in range(1, horizon + 1):
            delta = samples[h][0] - samples[h - 1][0]
            dist = float(np.hypot(delta[0], delta[1]))
            heading = math.atan2(delta[1], delta[0]) if dist > 1e-9 else prev_heading
            seq[h - 1] = (wrap_angle(heading - prev_heading), dist / step_s)
            prev_heading = heading
        return Neighbour(id=self.auv, position=(float(start[0]), float(start[1])), heading=heading0, sequence=seq)


@dataclass
class TickOutput:
    """What an agent emits for one tick."""

    command: wire.Command
    tx: list[wire.ModemTx]
    telemetry: wire.Telemetry


@dataclass
class AgentStats:
    """Counters of things that went wrong without stopping the agent."""

    payload_decode_errors: int = 0
    payload_sender_mismatch: int = 0
    payload_bearings_dropped: int = 0
    plans: int = 0


class AgentCore:
    """The onboard software of AUV ``auv``: estimator, planner, guidance and modem logic."""

    def __init__(self, auv: int, scenario: Scenario, ocean: OceanModel | None = None) -> None:
        """``ocean``: the scenario's physical ocean (default ``contract.tltable.ocean_for``, which reads its TL
        table); its link model weights the planner's connectivity graph, and bearings travel with their sigma."""
        self.auv = auv
        self.ocean = ocean if ocean is not None else ocean_for(scenario)
        self.link = None if self.ocean is None else self.ocean.link
        self.source = f"auv/{auv}"
        self.scenario = scenario
        self.order = scenario.slot_order
        if auv not in self.order:
            raise ValueError(f"auv must be one of the slot order {list(self.order)}, got {auv}")
        self.slot_index = self.order.index(auv)
        self.n = len(self.order)
        ch, pl = scenario.channel, scenario.planner
        self.frame_s = self.n * ch.slot_s
        self.sigma_m_rad = math.radians(scenario.sensor.sigma_m_deg)
        self.estimator = make_estimator(scenario.estimator, self.sigma_m_rad, auv)
        self.budget_bits = slot_frame_bits(ch, scenario.ocean)
        self.u_max = scenario.agents.u_max_mps
        self.r_max = scenario.agents.r_max_radps
        self.dtheta_grid = control_set(pl, 0.0, self.u_max, self.r_max).dtheta
        # under the centralised method the AUV does not plan: it follows the central planner (central/)
        self.planner = make_planner(scenario, auv) if pl.method != "centralised" else None
        self.shares_plans = bool(getattr(self.planner, "shares_plans", True))
        self.neighbours: dict[int, NeighbourTrack] = {}
        # planner.connectivity = "topology": per neighbour id, the reference pair distance (m) and when it was set (s)
        self.anchors: dict[int, tuple[float, float]] = {}
        self.outbox: list[Bearing] = []
        self.current_plan: Plan | None = None
        self.current_controls: ControlSet | None = None
        # what guidance holds: the current plan's first step as (heading rad, speed m/s), or the return
        # towards the last good estimate when there is none (see _hold_without_estimate)
        self.command_hold: tuple[float, float] | None = None
        self.last_estimate: Estimate | None = None
        # what the last tick brought: the navigation the core ran on (the pose it believes it has) and the
        # bearings it took in (its own, then those decoded from its neighbours' frames), for observers
        self.nav: wire.Nav | None = None
        self.heard: list[Bearing] = []
        # where the last ok estimate put the source (m), and whether the AUV is returning towards it
        self.last_fix: tuple[float, float] | None = None
        self.returning = False
        # before the first estimate: the last own bearing (rad), and where the spread began and its heading
        self.last_bearing: float | None = None
        self.started_s: float | None = None
        self.spread_from: tuple[float, float] | None = None
        self.spread_heading: float | None = None
        self.seq = 0
        self.fiedler = 0.0
        self.stats = AgentStats()
        self.method = pl.method

    def _is_slot_start(self, t_s: float) -> bool:
        slot = slot_index(t_s, self.scenario.channel.slot_s)
        if self.order[slot % self.n] != self.auv:
            return False
        return t_s - slot * self.scenario.channel.slot_s < self.scenario.run.tick_s - _EPS

    def _round(self, t_s: float) -> int:
        return math.floor(t_s / self.frame_s + _EPS)

    def _ingest(self, rx: list[wire.ModemRx], t_s: float) -> list[Bearing]:
        """Take in the frames the channel delivered: neighbour tracks are updated, the bearings they carry
        returned. The sender is the one the channel stamped (``ModemRx.sender``); a payload claiming another
        sender is dropped and counted."""
        received: list[Bearing] = []
        for msg in sorted(rx, key=lambda m: (m.t_arrival, m.sender, m.seq)):
            try:
                p = decode_payload(msg.payload, self.scenario.planner.n_headings)
            except wire.DecodeError:
                self.stats.payload_decode_errors += 1
                continue
            sender = msg.sender
            if p.sender != sender or sender == self.auv or sender not in self.order:
                self.stats.payload_sender_mismatch += 1
                continue
            received.extend(
                Bearing(
                    t_s=b[0],
                    sensor_xy=(b[1], b[2]),
                    bearing_rad=b[3],
                    source=sender,
                    sigma_rad=b[4] if p.sigma else None,
                )
                for b in p.bearings
            )
            speeds = speed_set(self.scenario.planner, p.u_e, self.u_max)
            controls = np.array(
                [
                    (
                        self.dtheta_grid[i] if 0 <= i < len(self.dtheta_grid) else 0.0,
                        speeds[s] if 0 <= s < len(speeds) else 0.0,
                    )
                    for i, s in p.plan
                ]
            ).reshape(-1, 2)
            known = self.neighbours.get(sender)
            if known is None or p.t_s >= known.t_s:
                self.neighbours[sender] = NeighbourTrack(
                    auv=sender,
                    t_s=p.t_s,
                    position=np.array([p.x, p.y]),
                    heading=p.theta,
                    controls=controls,
                    u_e=p.u_e,
                    round=p.round,
                    last_heard_s=t_s,
                )
        return received

    def _live_neighbours(self, t_s: float) -> list[NeighbourTrack]:
        horizon_s = 4.0 * self.frame_s
        return [nb for _, nb in sorted(self.neighbours.items()) if t_s - nb.last_heard_s <= horizon_s]

    def _plan(self, t_s: float, position: np.ndarray, heading: float, est: Estimate) -> tuple[Plan, ControlSet, float]:
        pl = self.scenario.planner
        p_hat, v_hat = est.xi[:2], est.xi[2:]
        u_e = base_speed(
            float(np.hypot(*(p_hat - position))), pl.d_star_m, float(np.hypot(*v_hat)), pl.step_s, self.u_max
        )
        controls = control_set(pl, u_e, self.u_max, self.r_max)
        neighbours = tuple(nb.as_neighbour(t_s, pl.step_s, pl.horizon) for nb in self._live_neighbours(t_s))
        anchor = None
        if pl.connectivity == "topology":
            # the pair distance at the first plan that knew each neighbour is its reference: for good, or
            # followed as a moving average when planner.anchor_tau_s > 0 (follow_anchor)
            for nb in neighbours:
                d = float(np.hypot(nb.position[0] - position[0], nb.position[1] - position[1]))
                a, t_prev = self.anchors.get(nb.id, (d, t_s))
                self.anchors[nb.id] = (follow_anchor(a, d, t_s - t_prev, pl.anchor_tau_s), t_s)
            anchor = tuple(self.anchors[nb.id][0] for nb in neighbours)
        problem = PlanProblem(
            position=position,
            heading=heading,
            xi=est.xi,
            P=est.P,
            neighbours=neighbours,
            controls=controls,
            planner=pl,
            channel=self.scenario.channel,
            anchor_m=anchor,
            link=self.link,
        )
        start = time.perf_counter()
        result = self.planner.plan(problem)
        wall_ms = (time.perf_counter() - start) * 1e3
        return result, controls, wall_ms

    def on_tick(
        self, nav: wire.Nav, sensor: wire.Sensor, rx: list[wire.ModemRx], central: wire.CentralPlan | None = None
    ) -> TickOutput:
        """Process one tick: measurements in, (u, r) and modem frames out.

        With ``planner.method = "centralised"`` the AUV only follows: ``central`` (the central
        planner's message for this tick) gives the estimate and, at planning ticks, the plan.
        """
        if sensor.bearing_rad is not None:
            self.last_bearing = float(sensor.bearing_rad)
        if self.started_s is None:
            self.started_s = nav.t_s
        self.nav = nav
        if self.method == "centralised":
            return self._follow(nav, central)
        t_s = nav.t_s
        bearings: list[Bearing] = []
        if sensor.bearing_rad is not None:
            own = Bearing(
                t_s=t_s,
                sensor_xy=(nav.x, nav.y),
                bearing_rad=sensor.bearing_rad,
                source=self.auv,
                sigma_rad=sensor.sigma_rad,
            )
            bearings.append(own)
            self.outbox.append(own)
        bearings += self._ingest(rx, t_s)
        self.heard = bearings
        est = self.estimator.update(bearings, t_s)
        self.last_estimate = est
        if est.ok:
            self.last_fix = (float(est.xi[0]), float(est.xi[1]))

        planned = False
        plan_wall_ms = 0.0
        tx: list[wire.ModemTx] = []
        if self._is_slot_start(t_s):
            self.fiedler = self._fiedler(nav)
            if est.ok:
                result, controls, plan_wall_ms = self._plan(t_s, np.array([nav.x, nav.y]), nav.theta, est)
                self.current_plan, self.current_controls = result, controls
                self.command_hold = (nav.theta + float(result.controls[0, 0]), float(result.controls[0, 1]))
                self.returning = False
                planned = True
                self.stats.plans += 1
            tx.append(self._transmit(nav))
        if not est.ok:
            self._hold_without_estimate(nav)

        u, r = self._guidance(nav)
        command = wire.Command(t_s=t_s, source=self.source, tick=nav.tick, auv=self.auv, u=u, r=r, tx_count=len(tx))
        telemetry = self._telemetry(nav, est, planned, plan_wall_ms)
        return TickOutput(command=command, tx=tx, telemetry=telemetry)

    def _follow(self, nav: wire.Nav, central: wire.CentralPlan | None) -> TickOutput:
        """Centralised MPC: take the central planner's estimate and plan; nothing on the acoustic link."""
        if central is None or central.tick != nav.tick or central.auv != self.auv:
            raise ValueError(f"auv {self.auv}: the centralised method needs the central plan of tick {nav.tick}")
        if central.estimate_ok:
            self.last_fix = (float(central.xi[0]), float(central.xi[1]))
        if central.planned and central.plan:
            self.command_hold = (nav.theta + float(central.plan[0][0]), float(central.plan[0][1]))
            self.stats.plans += 1
        elif self.last_fix is None:
            self._spread_before_first_estimate(nav)
        self.fiedler = central.fiedler
        u, r = self._guidance(nav)
        command = wire.Command(t_s=nav.t_s, source=self.source, tick=nav.tick, auv=self.auv, u=u, r=r, tx_count=0)
        telemetry = wire.Telemetry(
            t_s=nav.t_s,
            source=self.source,
            tick=nav.tick,
            auv=self.auv,
            estimate_ok=central.estimate_ok,
            estimate_reason=central.estimate_reason,
            xi=central.xi,
            P=central.P,
            plan=central.plan if central.planned else (),
            waypoints=central.waypoints if central.planned else (),
            cost=central.cost if central.planned else 0.0,
            terms=dict(central.terms) if central.planned else {},
            plan_wall_ms=central.plan_wall_ms if central.planned else 0.0,
            n_measurements=central.n_measurements,
            planned=central.planned,
            fiedler=self.fiedler,
            nav=(nav.x, nav.y, nav.theta),
        )
        return TickOutput(command=command, tx=[], telemetry=telemetry)

    def _guidance(self, nav: wire.Nav) -> tuple[float, float]:
        if self.command_hold is None:
            return 0.0, 0.0
        heading, speed = self.command_hold
        return guidance((nav.x, nav.y, nav.theta), heading, speed, self.u_max, self.r_max, self.scenario.run.tick_s)

    def _hold_without_estimate(self, nav: wire.Nav) -> None:
        """No estimate this tick: do not run on along an old plan (issue 27 item 2).

        Before any estimate the AUV spreads from its team (:meth:`_spread_before_first_estimate`).
        Afterwards it heads back towards the last good estimate of the source at u_max while it is
        farther than d* from it (turning in place first if it faces more than 90 deg away), and stops
        (holds, u = 0) once within d*; it never moves away from that point, so it stays within
        max(d*, its distance when the estimate was lost) <= d_M of it. While it is within d* of
        the point and has not started returning, it goes on with the step it was executing.
        """
        if self.last_fix is None:
            self._spread_before_first_estimate(nav)
            return
        dx, dy = self.last_fix[0] - nav.x, self.last_fix[1] - nav.y
        dist = math.hypot(dx, dy)
        d_star = self.scenario.planner.d_star_m
        if not self.returning and self.command_hold is not None and dist <= d_star:
            return  # still near the source: finish the step being executed; the next frame decides
        self.returning = True
        heading = math.atan2(dy, dx) if dist > _EPS else nav.theta
        # facing away (more than 90 deg off the point) it turns in place, so the range never grows
        closing = math.cos(heading - nav.theta) > 0.0
        self.command_hold = (heading, self.u_max if dist > d_star and closing else 0.0)

    def _spread_before_first_estimate(self, nav: wire.Nav) -> None:
        """No estimate yet: spread across the line of sight, so the team's bearings gain the baseline that
        triangulation needs (eq. 34; a cluster's bearings are nearly parallel and fix no range).

        For one optimisation step T_o after it started, and until its first own bearing, the AUV stays
        still (a team in useful geometry has its first estimate by then: 10-36 s in the paper's
        scenarios). At its first slot start after that it picks the perpendicular to its last bearing
        that points away from the centre of the team it knows (its own position and the neighbours'
        last reported ones; with none heard, or on the centre line, even slot positions take the
        left-hand side, odd ones the right), holds that heading at ``u_max`` until it is ``d_M / 2``
        from where it started, and stops there: two AUVs spreading apart end at most ``d_M`` farther
        apart than they started. The first estimate ends the spread (docs/planner.md).
        """
        if self.spread_heading is None:
            waited = nav.t_s - (self.started_s if self.started_s is not None else nav.t_s)
            if waited < self.scenario.planner.step_s or self.last_bearing is None or not self._is_slot_start(nav.t_s):
                self.command_hold = None
                return
            left = self.last_bearing + math.pi / 2.0
            ex, ey = math.cos(left), math.sin(left)
            xs = [nav.x, *(float(nb.position[0]) for nb in self.neighbours.values())]
            ys = [nav.y, *(float(nb.position[1]) for nb in self.neighbours.values())]
            offset = (nav.x - sum(xs) / len(xs)) * ex + (nav.y - sum(ys) / len(ys)) * ey
            side = 1.0 if offset > _SPREAD_CENTRE_M else -1.0 if offset < -_SPREAD_CENTRE_M else 0.0
            if side == 0.0:
                side = 1.0 if self.slot_index % 2 == 0 else -1.0
            self.spread_heading = float(wrap_angle(self.last_bearing + side * math.pi / 2.0))
            self.spread_from = (nav.x, nav.y)
        assert self.spread_from is not None
        travelled = math.hypot(nav.x - self.spread_from[0], nav.y - self.spread_from[1])
        far = travelled >= 0.5 * self.scenario.planner.d_max_m
        self.command_hold = (self.spread_heading, 0.0 if far else self.u_max)

    def _transmit(self, nav: wire.Nav) -> wire.ModemTx:
        pl = self.scenario.planner
        if self.current_plan is not None and self.current_controls is not None and self.shares_plans:
            n_speeds = len(self.current_controls.speeds)
            pairs = tuple((int(i) // n_speeds, int(i) % n_speeds) for i in self.current_plan.indices)
            u_e = float(self.current_controls.speeds[1])
        elif self.current_controls is not None:
            pairs = ()
            u_e = float(self.current_controls.speeds[1])
        else:
            pairs = ()
            u_e = 0.0
        payload = AcousticPayload(
            sender=self.auv,
            t_s=nav.t_s,
            x=nav.x,
            y=nav.y,
            theta=nav.theta,
            u_e=u_e,
            plan=pairs,
            round=self._round(nav.t_s) % 256,
            bearings=tuple(self._wire_bearing(b) for b in self.outbox),
            sigma=self.ocean is not None,
        )
        data, dropped = encode_payload(payload, self.budget_bits, pl.n_headings)
        self.stats.payload_bearings_dropped += dropped
        self.outbox = []
        self.seq += 1
        return wire.ModemTx(t_s=nav.t_s, source=self.source, tick=nav.tick, auv=self.auv, seq=self.seq, payload=data)

    def _wire_bearing(self, b: Bearing) -> tuple[float, ...]:
        """A bearing as the payload carries it: (t_s, x, y, bearing) and, under a physical ocean, its sigma (rad;
        the scenario's uniform-noise std when the sensor gave none)."""
        row = (b.t_s, b.sensor_xy[0], b.sensor_xy[1], b.bearing_rad)
        if self.ocean is None:
            return row
        return (*row, b.sigma_rad if b.sigma_rad is not None else self.sigma_m_rad / math.sqrt(3.0))

    def _telemetry(self, nav: wire.Nav, est: Estimate, planned: bool, plan_wall_ms: float) -> wire.Telemetry:
        p = self.current_plan if planned else None
        return wire.Telemetry(
            t_s=nav.t_s,
            source=self.source,
            tick=nav.tick,
            auv=self.auv,
            estimate_ok=bool(est.ok),
            estimate_reason=est.reason[:200],
            xi=tuple(np.asarray(est.xi, dtype=float).tolist()),
            P=tuple(np.asarray(est.reported_P, dtype=float).ravel().tolist()),
            plan=tuple((float(a), float(b)) for a, b in p.controls) if p is not None else (),
            waypoints=tuple((float(a), float(b)) for a, b in p.waypoints) if p is not None else (),
            cost=float(p.cost) if p is not None else 0.0,
            terms={k: float(v) for k, v in p.terms.items()} if p is not None else {},
            plan_wall_ms=float(plan_wall_ms),
            n_measurements=len(self.estimator),
            planned=planned,
            fiedler=self.fiedler,
            nav=(nav.x, nav.y, nav.theta),
        )

    def _fiedler(self, nav: wire.Nav) -> float:
        """lambda_2 of the SNR Laplacian (eqs. 25-26) over this AUV and the neighbours it believes alive.

        Evaluated once per TDMA frame, in this AUV's slot; telemetry repeats the last value.
        """
        step_s = self.scenario.planner.step_s
        positions = [(nav.x, nav.y)] + [tuple(nb.path(nav.t_s, step_s)[0]) for nb in self._live_neighbours(nav.t_s)]
        if len(positions) < 2:
            return 0.0
        return float(fiedler_value(snr_laplacian(np.array(positions), self.scenario.channel, self.link)))
