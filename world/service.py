"""The world's side of the lockstep tick protocol, as a pure object.

One tick k at sim time t_k = k * tick_s runs in three phases, the same in the
multi-process swarm (``world.node``) and in one process
(``orchestrator.inprocess``):

1. ``channel_tick()``: the world tells the channel the true positions at t_k,
   who is alive, and how many modem frames each AUV sent at tick k-1. The
   channel submits those frames, delivers everything that has fully arrived by
   t_k and answers with ``ChannelDone`` (how many frames each AUV will get).
2. ``agent_inputs(done)``: the world publishes the clock, the truth, and per AUV
   its navigation (with the number of modem frames to wait for) and its bearing.
   Each AUV waits for its navigation, its bearing and exactly that many frames,
   so what it computes never depends on the order messages arrive in.
3. ``apply(commands)``: with every live AUV's command for tick k in hand (or a
   timeout for a hung one), the world integrates to t_{k+1} and applies the
   scheduled kills.
"""

from __future__ import annotations

from dataclasses import dataclass

from auv_swarm.contract import wire
from auv_swarm.contract.config import Scenario
from auv_swarm.contract.rng import stream
from auv_swarm.world.model import WorldModel, initial_agent_states, world_streams

_TIME_TOL_S = 1e-9


@dataclass(frozen=True)
class AgentInputs:
    """The world's messages to one AUV for one tick."""

    nav: wire.Nav
    sensor: wire.Sensor


def check_scenario(scenario: Scenario) -> None:
    """Raise ValueError, as :class:`WorldService` would, if the world cannot start ``scenario``; builds no world.

    Beyond the config's own checks the world rejects one thing: a team it cannot place
    (:func:`~auv_swarm.world.model.initial_agent_states`). The placement is drawn here from the stream the world
    draws it from, so the answer is the world's for this seed; the target's trajectory is not built.
    """
    spawn_rng, _target_rng, _sensor_rng = world_streams(stream(scenario.run.seed, "world"))
    initial_agent_states(scenario, spawn_rng)


class WorldService:
    """Ground truth and clock, driven tick by tick (see the module docstring)."""

    def __init__(self, scenario: Scenario, hold_at: tuple[float, ...] = ()) -> None:
        """``hold_at``: sim times (s) of the faults a launcher injects from outside (processes mode: the channel,
        router, world and recorder faults, and a drill's unannounced ones); the world holds the clock at the first
        tick at or after each until the launcher confirms (:meth:`hold_due`, ``world.lockstep``)."""
        if any(not (isinstance(t, (int, float)) and 0.0 <= t < float("inf")) for t in hold_at):
            raise ValueError(f"hold_at must be finite sim times >= 0 s, got {list(hold_at)}")
        self.scenario = scenario
        self._holds = sorted(float(t) for t in hold_at)
        nav_rng = None if scenario.navigation.perfect else stream(scenario.run.seed, "navigation")
        self.model = WorldModel(scenario, stream(scenario.run.seed, "world"), nav_rng)
        self.n_ticks = int(round(scenario.run.duration_s / scenario.run.tick_s))
        self.tx_counts: dict[int, int] = {}
        self._finished = False
        self._faults = sorted((f for f in scenario.faults if f.auv is not None), key=lambda f: (f.at_s, f.auv))
        self._rejoin_at: dict[int, float] = {}
        self._resume_at: dict[int, float] = {}
        self.stopped: set[int] = set()
        """AUVs stopped by a scheduled ``stop`` fault: alive and moving on their held command, but off the
        channel (no frames to or from them) and not answering (their commands are ignored)."""

    @property
    def tick(self) -> int:
        """The tick about to run."""
        return self.model.tick

    @property
    def finished(self) -> bool:
        """True once the mission's last tick (the one at ``run.duration_s``) has run."""
        return self._finished

    @property
    def alive(self) -> tuple[int, ...]:
        """Live AUV ids, sorted."""
        return tuple(sorted(self.model.alive))

    def channel_tick(self, sessions: dict[int, str] | None = None, refused: tuple[int, ...] = ()) -> wire.ChannelTick:
        """Phase 1: what the channel needs to process tick k; ``sessions`` and ``refused`` as in
        :class:`wire.ChannelTick` (the world's lockstep knows them)."""
        m = self.model
        return wire.ChannelTick(
            t_s=m.time_s,
            source="world",
            tick=m.tick,
            tx_expected={a: self.tx_counts.get(a, 0) for a in sorted(m.states)},
            positions={a: tuple(s[:2].tolist()) for a, s in sorted(m.states.items())},
            alive=tuple(a for a in self.alive if a not in self.stopped),
            sessions=dict(sessions or {}),
            refused=refused,
        )

    def truth(self) -> wire.Truth:
        """The true target and vehicles at the current tick."""
        m = self.model
        pos, vel = m.target()
        return wire.Truth(
            t_s=m.time_s,
            source="world",
            tick=m.tick,
            target=(float(pos[0]), float(pos[1]), float(vel[0]), float(vel[1])),
            agents={a: tuple(s.tolist()) for a, s in sorted(m.states.items())},
            alive=self.alive,
        )

    def clock(self) -> wire.Clock:
        """The clock message of the current tick."""
        return wire.Clock(t_s=self.model.time_s, source="world", tick=self.model.tick, alive=self.alive)

    def agent_inputs(self, done: wire.ChannelDone | None) -> dict[int, AgentInputs]:
        """Phase 2: navigation (the pose the AUV believes it has, ``WorldModel.believed``) and bearing of every live
        AUV (senses once per tick)."""
        m = self.model
        bearings = m.sense()
        rx_count = done.rx_count if done is not None else {}
        t_s, tick = m.time_s, m.tick
        out = {}
        for a in self.alive:
            x, y, theta = m.believed(a).tolist()
            u, r = m.commands.get(a, (0.0, 0.0))
            nav = wire.Nav(
                t_s=t_s,
                source="world",
                tick=tick,
                auv=a,
                x=x,
                y=y,
                theta=theta,
                u=float(u),
                r=float(r),
                rx_expected=int(rx_count.get(a, 0)),
            )
            b = bearings.get(a)
            sensor = wire.Sensor(t_s=t_s, source="world", tick=tick, auv=a, bearing_rad=None if b is None else float(b))
            out[a] = AgentInputs(nav=nav, sensor=sensor)
        return out

    def apply(self, commands: dict[int, wire.Command]) -> list[wire.WorldEvent]:
        """Phase 3: hold the commands, integrate to the next tick, apply scheduled kills.

        The tick at ``run.duration_s`` is the mission's last: it is sensed and answered, but nothing moves
        past it, so a 1500 s mission ends at 1500 s.
        """
        m = self.model
        if m.tick >= self.n_ticks:
            self._finished = True
            return []
        self.tx_counts = {}
        for a in self.alive:
            cmd = commands.get(a)
            if cmd is not None and cmd.tick == m.tick and a not in self.stopped:
                try:
                    m.set_command(a, cmd.u, cmd.r)
                except ValueError:
                    continue
                self.tx_counts[a] = cmd.tx_count
        killed = m.advance()
        events = [
            wire.WorldEvent(t_s=m.time_s, source="world", kind="kill", auv=a, text=f"AUV {a} killed at {m.time_s:g} s")
            for a in killed
        ]
        return events + self._due_faults()

    def _due_faults(self) -> list[wire.WorldEvent]:
        """AUV faults due by now (at the first tick boundary >= at_s), as ``kill`` events whose text starts with
        the action (``kill:``, ``term:``, ``restart:``): the launcher acts on that word."""
        m = self.model
        events = []
        while self._faults and self._faults[0].at_s <= m.time_s + _TIME_TOL_S:
            f = self._faults.pop(0)
            if f.action == "stop":
                if f.auv in m.alive:
                    self.stopped.add(f.auv)
                    self._resume_at[f.auv] = f.at_s + f.duration_s
                    text = f"stop: AUV {f.auv} stopped at {m.time_s:g} s for {f.duration_s:g} s"
                    events.append(wire.WorldEvent(t_s=m.time_s, source="world", kind="hung", auv=f.auv, text=text))
                continue
            if not m.kill(f.auv):
                continue
            text = f"{f.action}: AUV {f.auv} fault at {m.time_s:g} s"
            if f.action == "restart":
                self._rejoin_at[f.auv] = f.at_s + f.down_s
                text += f", back after {f.down_s:g} s"
            events.append(wire.WorldEvent(t_s=m.time_s, source="world", kind="kill", auv=f.auv, text=text))
        return events

    def hold_due(self) -> bool:
        """True at the first tick at or after one (or more) of the ``hold_at`` times (each counts once): the launcher
        injects its faults on this tick's truth, and the clock waits for its confirmation."""
        due = False
        while self._holds and self._holds[0] <= self.model.time_s + _TIME_TOL_S:
            self._holds.pop(0)
            due = True
        return due

    def resumes_due(self) -> list[int]:
        """Stopped AUVs due to answer again at the current tick (sorted)."""
        now = self.model.time_s + _TIME_TOL_S
        return sorted(a for a, t in self._resume_at.items() if t <= now)

    def resume(self, auv: int) -> wire.WorldEvent:
        """A stopped AUV is back on the channel and waited for again from this tick on."""
        self._resume_at.pop(auv, None)
        self.stopped.discard(auv)
        t_s = self.model.time_s
        return wire.WorldEvent(t_s=t_s, source="world", kind="resume", auv=auv, text=f"stop: AUV {auv} resumes")

    def rejoins_due(self) -> list[int]:
        """Restarted AUVs due back at the current tick (sorted)."""
        now = self.model.time_s + _TIME_TOL_S
        return sorted(a for a, t in self._rejoin_at.items() if t <= now)

    def rejoin(self, auv: int) -> wire.WorldEvent:
        """Re-admit a restarted AUV at the current tick: it gets navigation again from this tick on."""
        self._rejoin_at.pop(auv, None)
        self.model.revive(auv)
        t_s = self.model.time_s
        return wire.WorldEvent(t_s=t_s, source="world", kind="rejoin", auv=auv, text=f"AUV {auv} rejoined at {t_s:g} s")

    def give_up_rejoin(self, auv: int, reason: str) -> wire.WorldEvent:
        """A restarted AUV that did not come back: it stays dead (a ``death`` with the reason)."""
        self._rejoin_at.pop(auv, None)
        return wire.WorldEvent(t_s=self.model.time_s, source="world", kind="death", auv=auv, text=reason)

    def quarantine(self, auv: int, reason: str) -> wire.WorldEvent:
        """A compromised AUV (a second login with its password): dead where it is from now on, its scheduled
        restart or resume cancelled (a ``death`` with the reason)."""
        self._rejoin_at.pop(auv, None)
        self._resume_at.pop(auv, None)
        self.stopped.discard(auv)
        return self.declare_dead(auv, reason)

    def declare_dead(self, auv: int, reason: str) -> wire.WorldEvent:
        """An AUV process died or hung without being scheduled to: stop it in the world too."""
        self.model.kill(auv)
        return wire.WorldEvent(t_s=self.model.time_s, source="world", kind="death", auv=auv, text=reason)
