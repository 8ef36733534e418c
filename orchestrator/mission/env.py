"""The swarm as a PettingZoo ``ParallelEnv``: one agent per AUV, one step per TDMA slot (docs/env.md).

``auv_swarm.env.parallel_env(scenario)`` re-exports :func:`parallel_env`. Underneath runs the mission of
:func:`~auv_swarm.run_mission` in process: the same world, channel, estimators and agent cores over the same
in-memory bus (:class:`~auv_swarm.orchestrator.mission.inprocess.InProcessMission`), seeded like a mission.
The env changes one thing only: the planner of the AUV whose TDMA slot a step runs is given that agent's
action as its plan (:class:`SlotPlanner`); everything else the AUV does (estimate, share, guidance, the
hold, spread and return without an estimate) is its core's. With the plans DMPC chose given back as
actions the mission's metrics are those of ``run_mission`` (tests/unit/test_env.py).

Step k runs the ticks of TDMA slot k (``channel.slot_s / run.tick_s`` ticks, sim time), the slot of AUV
``slot_order[k % n]``: at the slot's first tick that AUV plans (when it holds an estimate), with the plan
``actions["auv_<id>"]`` gives, and broadcasts it in the slot's frame. Observations and the reward are taken
after the slot's last tick.
"""

from __future__ import annotations

import functools
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

try:
    from gymnasium import spaces
    from pettingzoo import ParallelEnv
except ImportError:  # the extra is missing: one line says which
    raise ImportError("auv_swarm.env needs PettingZoo, the extra rl: pip install 'auv-swarm[rl]'") from None

from auv_swarm.agent.core import AgentCore, slot_index
from auv_swarm.agent.estimator import Bearing
from auv_swarm.agent.node import AgentNode
from auv_swarm.agent.planner import Plan, PlanProblem, speed_set
from auv_swarm.agent.planner.reference import make_plan
from auv_swarm.contract import payload, wire
from auv_swarm.contract.config import ConfigError, Scenario, load_scenario
from auv_swarm.contract.ocean import slot_frame_bits
from auv_swarm.orchestrator.mission.api import check_runnable
from auv_swarm.orchestrator.mission.inprocess import InProcessMission
from auv_swarm.results.collect import MessageLog
from auv_swarm.results.metrics import compute_metrics

AGENT_PREFIX = "auv_"
"""An agent's name is this prefix and its AUV id (``auv_0``, ``auv_1``, ...)."""


def agent_name(auv: int) -> str:
    """The PettingZoo agent of AUV ``auv``."""
    return f"{AGENT_PREFIX}{auv}"


def parallel_env(scenario: Scenario | str | Path, *, max_cycles: int | None = None) -> SwarmEnv:
    """The swarm of ``scenario`` (a built-in name, a TOML path or a ``Scenario``) as a PettingZoo ``ParallelEnv``.

    ``max_cycles``: truncate an episode after this many steps (TDMA slots); None: at the mission's end
    (``run.duration_s``). Raises ConfigError for a scenario the env cannot run (an AUV restart, the
    centralised method, a fault of processes mode only).
    """
    return SwarmEnv(scenario, max_cycles=max_cycles)


def check_env_scenario(scenario: Scenario) -> None:
    """Raise ConfigError, one line naming the key, if the env cannot run ``scenario``."""
    check_runnable(scenario, "inprocess")
    for i, f in enumerate(scenario.faults):
        if f.action == "restart":
            raise ConfigError(
                f"faults[{i}]: the env cannot run an AUV restart ({f.target} at {f.at_s:g} s): "
                "PettingZoo forbids an agent's revival"
            )
    if scenario.planner.method == "centralised":
        raise ConfigError("planner.method 'centralised': its AUVs plan nothing, so the env has no action to give them")


class SlotPlanner:
    """An AUV's planner under the env: the plan of the action set for the slot being stepped, or, with no
    action, the AUV's own planner (``planner.method``).

    The action's plan is built on the problem's control set (eqs. 46-49) and costed with the reference cost
    of eqs. (34)-(38), (50) (:func:`~auv_swarm.agent.planner.reference.make_plan`), so its controls are the
    very numbers the planner would give for the same indices.
    """

    def __init__(self, own: Any) -> None:
        self.own = own
        self.shares_plans = bool(getattr(own, "shares_plans", True))
        self.action: np.ndarray | None = None
        """(H, 2) (heading index, speed index) rows for the next plan, or None: the own planner plans."""
        self.last: Plan | None = None
        """The plan made during the current step, or None."""
        self.applied = False
        """True when the current step's plan was the action's."""

    def arm(self, action: np.ndarray | None) -> None:
        """Set the action for the slot about to run (None: the own planner's plan)."""
        self.action, self.last, self.applied = action, None, False

    def plan(self, problem: PlanProblem) -> Plan:
        """The action's plan, or the own planner's without one."""
        if self.action is None:
            self.last = self.own.plan(problem)
            return self.last
        n_speeds = problem.controls.speeds.size
        indices = self.action[:, 0].astype(np.int64) * n_speeds + self.action[:, 1].astype(np.int64)
        self.last = make_plan(problem, indices, 0)
        self.applied = True
        return self.last


class SwarmEnv(ParallelEnv):
    """The swarm of one scenario as a PettingZoo ``ParallelEnv`` (module docstring; docs/env.md field by field)."""

    metadata = {"name": "auv_swarm_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(self, scenario: Scenario | str | Path, *, max_cycles: int | None = None) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        check_env_scenario(self.scenario)
        whole = isinstance(max_cycles, int) and not isinstance(max_cycles, bool)
        if max_cycles is not None and not (whole and max_cycles >= 1):
            raise ConfigError(f"max_cycles must be an integer >= 1 or None, got {max_cycles!r}")
        self.max_cycles = max_cycles
        self.render_mode = None
        s = self.scenario
        self.n = s.agents.count
        self.possible_agents = [agent_name(a) for a in range(self.n)]
        self.agents: list[str] = []
        self.horizon = s.planner.horizon
        self.n_speeds = len(speed_set(s.planner, 0.0, s.agents.u_max_mps))
        ch = s.channel
        physical = s.ocean.model == "physical"  # each bearing carries its sigma (payload v3)
        per_frame = payload.max_bearings(slot_frame_bits(ch, s.ocean), self.horizon, s.planner.n_headings, physical)
        self.max_bearings = math.ceil(ch.slot_s / s.run.tick_s - 1e-9) + (self.n - 1) * per_frame
        """Rows of the ``bearings`` observation: a step's own bearings and a full frame from every neighbour."""
        nvec = np.array([[s.planner.n_headings, self.n_speeds]] * self.horizon, dtype=np.int64)
        self.action_spaces = {name: spaces.MultiDiscrete(nvec, dtype=np.int64) for name in self.possible_agents}
        self.observation_spaces = {name: self._make_observation_space() for name in self.possible_agents}
        self.mission_seed: int | None = None
        """``run.seed`` of the current episode's mission."""
        self.cycles = 0
        self._mission: InProcessMission | None = None
        self._log: MessageLog | None = None
        self._planners: dict[int, SlotPlanner] = {}
        self._heard: dict[int, list[Bearing]] = {}
        self._dropped: dict[int, int] = {}
        self._truth: wire.Truth | None = None
        self._started = 0.0
        self._wall_s = 0.0
        self._closed = False

    # spaces --------------------------------------------------------------------------------------------------------

    def observation_space(self, agent: str) -> spaces.Dict:
        """The observation of ``agent``, the same object at every call (every agent's has the same shape;
        docs/env.md)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.MultiDiscrete:
        """(H, 2): per horizon step h, (heading index into linspace(-dtheta_max, dtheta_max, n_headings), speed
        index into the speed set of ``planner.speed_set``): the control indices of eqs. (46)-(49)."""
        return self.action_spaces[agent]

    def _make_observation_space(self) -> spaces.Dict:
        inf, n, k = np.inf, self.n, self.max_bearings
        box = functools.partial(spaces.Box, -inf, inf, dtype=np.float64)
        return spaces.Dict(
            {
                "time_s": spaces.Box(0.0, inf, (1,), dtype=np.float64),
                "slot_owner": spaces.Discrete(2),
                "navigation": box((5,)),
                "estimate_ok": spaces.Discrete(2),
                "estimate": box((4,)),
                "covariance": box((4, 4)),
                "bearings": box((k, 4)),
                "bearings_sender": spaces.MultiDiscrete(np.full(k, n, dtype=np.int64)),
                "bearings_mask": spaces.MultiBinary(k),
                "neighbours": box((n, 4)),
                "neighbours_mask": spaces.MultiBinary(n),
            }
        )

    # the episode ---------------------------------------------------------------------------------------------------

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Build a fresh mission of the scenario with ``run.seed = seed``; without a seed the scenario's own on the
        first reset and the previous one plus 1 on every later one. ``options`` is not used."""
        if self._mission is not None and not self._closed:
            self._mission.bus.close()
        if seed is None:
            seed = self.scenario.run.seed if self.mission_seed is None else self.mission_seed + 1
        self.mission_seed = int(seed)
        scenario = self.scenario.with_overrides(seed=self.mission_seed)
        self._log = MessageLog()
        self._planners = {}
        self._started = time.perf_counter()
        self._wall_s = 0.0
        self._mission = InProcessMission(
            scenario, [self._log, self], agent_node=self._agent_node, frame_sinks=[self._log]
        )
        self._closed = False
        self.cycles = 0
        self.agents = [agent_name(a) for a in sorted(self._mission.world.alive)]
        self._heard = {a: [] for a in self._planners}
        self._dropped = dict.fromkeys(self._planners, 0)
        self._truth = self._mission.world.truth()
        obs = {agent_name(a): self._observe(a) for a in self._live()}
        return obs, {name: {"seed": self.mission_seed, "t_s": 0.0} for name in obs}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Run the TDMA slot about to start: its owner's action becomes its plan (see the module docstring)."""
        mission = self._mission
        if mission is None or not self.agents:
            raise RuntimeError("the episode is over (or never began): call reset()")
        owner = self.slot_owner
        action = actions.get(agent_name(owner)) if owner is not None else None
        armed = None if action is None else self._checked(action)
        for auv, planner in self._planners.items():
            planner.arm(armed if auv == owner else None)
        live = self._live()
        self._heard = {a: [] for a in self._planners}
        self._dropped = dict.fromkeys(self._planners, 0)
        tick = self._run_slot()
        self.cycles += 1
        reward, team_error = self._reward(tick)
        alive = set(mission.world.alive)
        ended = mission.finished or (self.max_cycles is not None and self.cycles >= self.max_cycles)
        names = [agent_name(a) for a in live]
        obs = {agent_name(a): self._observe(a) for a in live}
        rewards = dict.fromkeys(names, reward)
        terminations = {agent_name(a): a not in alive for a in live}
        truncations = {agent_name(a): ended and a in alive for a in live}
        infos = {agent_name(a): self._info(a, owner, team_error) for a in live}
        self.agents = [n for n in names if not (terminations[n] or truncations[n])]
        if not self.agents:
            self._finish()
        return obs, rewards, terminations, truncations, infos

    @property
    def slot_owner(self) -> int | None:
        """The AUV whose TDMA slot the next step runs (None once the mission has ended)."""
        if self._mission is None or self._mission.finished:
            return None
        s = self.scenario
        return s.slot_order[slot_index(self._mission.world.model.time_s, s.channel.slot_s) % len(s.slot_order)]

    @property
    def time_s(self) -> float:
        """Sim time (s) of the next tick to run."""
        return 0.0 if self._mission is None else self._mission.world.model.time_s

    def metrics(self) -> dict[str, Any]:
        """The mission's metrics (``metrics.json``, as :func:`~auv_swarm.run_mission` computes them), once the episode
        is over; an episode cut short by ``max_cycles`` is ``complete: false``, ``incomplete_reason: "interrupted"``.
        ``wall_time_s`` is the wall time of the mission's ticks, ``run_wall_time_s`` from ``reset`` to here (the
        policy's time included)."""
        if self._mission is None or self.agents:
            raise RuntimeError("the episode is still running (or never began): metrics come at its end")
        mission, log = self._mission, self._log
        assert log is not None
        record = log.to_record(mission.scenario, "inprocess", self._wall_s)
        record.run_wall_time_s = time.perf_counter() - self._started
        if mission.finished:
            record.set_outcome(True, None, 0)
        else:
            record.set_outcome(False, "interrupted", 130)
        return compute_metrics(record)

    def state(self) -> np.ndarray:
        """The true world at the last tick run (for centralised training): the target (x, y, vx, vy) then, per AUV,
        (x, y, theta, alive); m, m/s, rad."""
        tr = self._truth
        if tr is None:
            raise RuntimeError("no state before reset()")
        rows = [(*tr.agents.get(a, (0.0, 0.0, 0.0)), float(a in tr.alive)) for a in range(self.n)]
        return np.concatenate([np.asarray(tr.target, dtype=np.float64), np.asarray(rows, dtype=np.float64).ravel()])

    def render(self) -> None:
        """Not rendered here: ``run_mission(..., out=...)`` records a mission for rerun (docs/recorder.md)."""
        return None

    def close(self) -> None:
        """Drop the mission (its bus closed)."""
        if self._mission is not None and not self._closed:
            self._mission.bus.close()
            self._closed = True

    # the sink of the mission's messages ----------------------------------------------------------------------------

    def on_message(self, msg: wire.Message) -> None:
        """Keep the last truth (the reward's and ``state``'s); the env is one of the mission's sinks."""
        if isinstance(msg, wire.Truth):
            self._truth = msg

    # inside --------------------------------------------------------------------------------------------------------

    def _agent_node(self, core: AgentCore) -> AgentNode:
        """The AUV's shell as a mission builds it, its planner under the env's hand (:class:`SlotPlanner`)."""
        core.planner = self._planners[core.auv] = SlotPlanner(core.planner)
        return AgentNode(core)

    def _live(self) -> list[int]:
        return [int(name[len(AGENT_PREFIX) :]) for name in self.agents]

    def _checked(self, action: Any) -> np.ndarray:
        """The owner's action as (H, 2) int64 indices; ValueError in one line if it is not one of the space."""
        space = self.action_spaces[self.possible_agents[0]]
        a = np.asarray(action)
        whole = a.dtype.kind in "iu" or (a.dtype.kind == "f" and bool(np.all(np.isfinite(a) & (a == np.round(a)))))
        if a.shape != space.shape or not whole or not space.contains(a.astype(np.int64)):
            raise ValueError(
                f"an action must be (H = {self.horizon}, 2) integers (heading index < {space.nvec[0, 0]}, "
                f"speed index < {self.n_speeds}), got {a.tolist()!r}"
            )
        return a.astype(np.int64)

    def _run_slot(self) -> int:
        """Run every tick of the current TDMA slot (to the mission's end at most); return the last tick run."""
        mission = self._mission
        assert mission is not None
        slot_s = self.scenario.channel.slot_s
        slot = slot_index(mission.world.model.time_s, slot_s)
        tick = mission.world.tick
        while not mission.finished and slot_index(mission.world.model.time_s, slot_s) == slot:
            tick = mission.world.tick
            self._tick()
            for auv, heard in self._heard.items():
                core = mission.nodes[auv].core
                if core.nav is not None and core.nav.tick == tick:
                    heard.extend(core.heard)
        return tick

    def _finish(self) -> None:
        """The episode is over: run a mission whose AUVs all died to its end (nothing acts any more), as
        ``run_mission`` would, unless ``max_cycles`` cut it; close it."""
        mission = self._mission
        assert mission is not None
        cut = self.max_cycles is not None and self.cycles >= self.max_cycles
        while not mission.finished and not cut:
            self._tick()
        mission.close()
        self._closed = True

    def _tick(self) -> None:
        """One tick of the mission, its wall time added to the metrics' ``wall_time_s``."""
        assert self._mission is not None
        start = time.perf_counter()
        self._mission.step()
        self._wall_s += time.perf_counter() - start

    def _reward(self, tick: int) -> tuple[float, float | None]:
        """The reward at the slot's last tick (docs/env.md): minus the mean over the live AUVs of the tracking
        error over d*, an AUV without an estimate counted at d_M; and the team-mean error (m) of the AUVs with
        one (results.metrics' definition; None when none has one)."""
        mission, tr = self._mission, self._truth
        assert mission is not None and tr is not None
        pl = self.scenario.planner
        errors, scored = [], []
        for a in tr.alive:
            core = mission.nodes[a].core
            est = core.last_estimate
            if core.nav is None or core.nav.tick != tick:
                continue
            if est is not None and est.ok:
                e = math.hypot(float(est.xi[0]) - tr.target[0], float(est.xi[1]) - tr.target[1])
                errors.append(e)
                scored.append(e)
            else:
                scored.append(pl.d_max_m)
        reward = -sum(scored) / (len(scored) * pl.d_star_m) if scored else 0.0
        return float(reward), (sum(errors) / len(errors) if errors else None)

    def _observe(self, auv: int) -> dict[str, Any]:
        """What AUV ``auv`` knows after the last tick it ran (docs/env.md, field by field)."""
        mission = self._mission
        assert mission is not None
        core = mission.nodes[auv].core
        nav = core.nav
        if nav is not None:
            navigation = [nav.x, nav.y, nav.theta, nav.u, nav.r]
        else:  # before the first tick: the pose it believes it starts at (the world's dead reckoning), at rest
            navigation = [*mission.world.model.believed(auv).tolist(), 0.0, 0.0]
        est = core.last_estimate
        ok = est is not None and bool(est.ok)
        table, sender, mask = self._bearings(auv)
        neighbours = np.zeros((self.n, 4))
        neighbours_mask = np.zeros(self.n, dtype=np.int8)
        for j, nb in core.neighbours.items():
            neighbours[j] = (float(nb.position[0]), float(nb.position[1]), nb.heading, nb.t_s)
            neighbours_mask[j] = 1
        return {
            "time_s": np.array([nav.t_s if nav is not None else 0.0]),
            "slot_owner": int(self.slot_owner == auv),
            "navigation": np.array(navigation, dtype=np.float64),
            "estimate_ok": int(ok),
            "estimate": np.array(est.xi, dtype=np.float64) if ok else np.zeros(4),
            "covariance": np.array(est.reported_P, dtype=np.float64) if ok else np.zeros((4, 4)),
            "bearings": table,
            "bearings_sender": sender,
            "bearings_mask": mask,
            "neighbours": neighbours,
            "neighbours_mask": neighbours_mask,
        }

    def _bearings(self, auv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The bearings AUV ``auv`` took in during the step, in the order it took them (its own, then those
        received over the channel, tick by tick), the newest ``max_bearings`` when more came."""
        k = self.max_bearings
        heard = self._heard.get(auv, [])
        self._dropped[auv] = max(0, len(heard) - k)
        heard = heard[-k:]
        table = np.zeros((k, 4))
        sender = np.zeros(k, dtype=np.int64)
        mask = np.zeros(k, dtype=np.int8)
        for i, b in enumerate(heard):
            table[i] = (b.t_s, b.sensor_xy[0], b.sensor_xy[1], b.bearing_rad)
            sender[i] = b.source
            mask[i] = 1
        return table, sender, mask

    def _info(self, auv: int, owner: int | None, team_error: float | None) -> dict[str, Any]:
        planner = self._planners[auv]
        plan = planner.last if auv == owner else None
        pairs = np.zeros((0, 2), dtype=np.int64)
        if plan is not None:
            speeds = self.n_speeds
            pairs = np.column_stack(np.divmod(np.asarray(plan.indices, dtype=np.int64), speeds))
        tr = self._truth
        return {
            "t_s": float(tr.t_s) if tr is not None else 0.0,
            "slot_owner": auv == owner,
            "action_applied": bool(auv == owner and planner.applied),
            "plan": pairs,
            "team_error_m": team_error,
            "bearings_dropped": self._dropped.get(auv, 0),
        }
