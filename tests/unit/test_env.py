"""The swarm as a PettingZoo environment (``auv_swarm.env``, docs/env.md): PettingZoo's own API and seed tests, the
replay of DMPC's plans against ``run_mission``, the reward's definition, deaths, truncation and refusals."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

from auv_swarm import load_scenario, run_mission
from auv_swarm.agent.planner import speed_set
from auv_swarm.contract import wire
from auv_swarm.contract.config import ConfigError
from auv_swarm.env import agent_name, parallel_env
from auv_swarm.results.metrics import comparable

SCENARIO = "paper-3.2-challenging"
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


class PlanLog:
    """The plans the AUVs made in a mission, by (AUV, tick), as (dtheta rad, speed m/s) rows (their telemetry)."""

    def __init__(self) -> None:
        self.plans: dict[tuple[int, int], tuple[tuple[float, float], ...]] = {}

    def on_message(self, msg: object) -> None:
        if isinstance(msg, wire.Telemetry) and msg.planned:
            self.plans[(msg.auv, msg.tick)] = msg.plan


def as_action(scenario, plan: tuple[tuple[float, float], ...]) -> np.ndarray:
    """A plan's (dtheta, speed) rows as (heading index, speed index) rows: the heading grid of eq. (48) exactly, a
    speed the set's fixed entries or else u_e (index 1; a u_e equal to a fixed speed gives the same control)."""
    pl, u_max = scenario.planner, scenario.agents.u_max_mps
    grid = np.linspace(-pl.dtheta_max_rad, pl.dtheta_max_rad, pl.n_headings) if pl.n_headings > 1 else np.zeros(1)
    fixed = speed_set(pl, math.nan, u_max)
    rows = []
    for dtheta, speed in plan:
        (heading,) = np.flatnonzero(grid == dtheta)
        matches = [i for i, v in enumerate(fixed) if v == speed]
        rows.append((int(heading), matches[0] if matches else 1))
    return np.array(rows, dtype=np.int64)


def expected_reward(scenario, obs: dict, infos: dict, target: np.ndarray) -> float:
    """docs/env.md's reward from the observations and the true target: minus the mean over the AUVs alive at the
    slot's last tick of |estimate - target| / d*, an AUV without an estimate counted at d_M."""
    pl = scenario.planner
    ran = [o for a, o in obs.items() if o["time_s"][0] == infos[a]["t_s"]]
    errors = [float(np.hypot(*(o["estimate"][:2] - target[:2]))) if o["estimate_ok"] else pl.d_max_m for o in ran]
    return -sum(errors) / (len(errors) * pl.d_star_m)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_replaying_dmpcs_plans_gives_run_missions_metrics(seed: int) -> None:
    """The plans DMPC chose in ``run_mission``, given back action by action (random actions for the agents whose
    slot it is not), give the same comparable metrics; the AUV killed at 750 s is terminated there."""
    scenario = load_scenario(SCENARIO).with_overrides(seed=seed)
    log = PlanLog()
    expected = run_mission(scenario, sinks=[log])
    env = parallel_env(SCENARIO)
    obs, infos = env.reset(seed=seed)
    assert env.mission_seed == seed and set(infos) == set(env.possible_agents)
    applied, died_at = 0, None
    while env.agents:
        owner, tick = env.slot_owner, round(env.time_s / scenario.run.tick_s)
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        plan = log.plans.get((owner, tick))
        actions[agent_name(owner)] = as_action(scenario, plan) if plan else np.zeros((5, 2), dtype=np.int64)
        obs, rewards, terminations, truncations, infos = env.step(actions)
        for agent, o in obs.items():
            assert env.observation_space(agent).contains(o), agent
        reward = expected_reward(scenario, obs, infos, env.state()[:4])
        assert all(r == pytest.approx(reward, rel=1e-12) for r in rewards.values()) and set(rewards) == set(obs)
        if agent_name(owner) in infos:
            info = infos[agent_name(owner)]
            assert info["action_applied"] == (plan is not None)
            applied += info["action_applied"]
            if plan is not None:
                np.testing.assert_array_equal(info["plan"], actions[agent_name(owner)])
        assert not any(i["action_applied"] for a, i in infos.items() if a != agent_name(owner))
        if terminations.get("auv_1"):
            died_at = infos["auv_1"]["t_s"]
    assert comparable(env.metrics()) == comparable(expected.metrics)
    assert applied == expected.metrics["plan_count"] > 0
    assert died_at is not None and 748.0 <= died_at < 750.0 + 14.0
    assert set(truncations) == {"auv_0", "auv_2"} and all(truncations.values())


def test_pettingzoos_parallel_api_test_passes() -> None:
    parallel_api_test(parallel_env(SCENARIO))


def test_pettingzoos_parallel_seed_test_passes() -> None:
    parallel_seed_test(lambda: parallel_env(SCENARIO))


def test_no_action_runs_the_built_in_planner_and_infos_hold_no_wall_clock() -> None:
    """An owner given no action plans with its own planner (``action_applied`` false); the infos of two runs of one
    seed are equal (nothing of the wall clock in them); ``max_cycles`` truncates an incomplete mission."""
    runs = []
    for _ in range(2):
        env = parallel_env(SCENARIO, max_cycles=12)
        env.reset(seed=5)
        steps = []
        while env.agents:
            steps.append(env.step({})[1:])
        runs.append((steps, env.metrics()))
    (steps, metrics), (again, _) = runs
    assert len(steps) == 12 and all(steps[-1][2].values())  # truncated at max_cycles
    assert repr(steps) == repr(again)
    infos = [i for step in steps for i in step[3].values()]
    assert not any(i["action_applied"] for i in infos)
    assert any(len(i["plan"]) == 5 for i in infos)  # the built-in planner planned once an estimate came
    assert metrics["complete"] is False and metrics["incomplete_reason"] == "interrupted"
    assert metrics["sim_duration_s"] == pytest.approx(12 * 14.0 - 2.0)


def test_the_navigation_observed_is_the_one_the_auv_believes() -> None:
    """Under a compass bias (docs/navigation.md) the observed heading is the true one turned by the bias, at reset
    and after the slot's last tick; the observed position drifts from the true one."""
    keys = {"navigation.heading_bias_deg": 10.0, "navigation.drift_fraction": 0.05}
    env = parallel_env(load_scenario(SCENARIO).with_keys(keys), max_cycles=20)
    obs, _ = env.reset(seed=1)

    def turned_by_the_bias(obs: dict) -> bool:
        truth = env.state()[4:].reshape(-1, 4)
        turns = [o["navigation"][2] - truth[int(a[4:]), 2] - math.radians(10.0) for a, o in obs.items()]
        return all(abs(math.remainder(t, 2 * math.pi)) < 1e-9 for t in turns)

    assert turned_by_the_bias(obs)
    while env.agents:
        obs = env.step({})[0]
    assert turned_by_the_bias(obs)
    truth = env.state()[4:].reshape(-1, 4)
    assert all(np.hypot(*(o["navigation"][:2] - truth[int(a[4:]), :2])) > 1.0 for a, o in obs.items())


def test_resets_without_a_seed_run_the_scenarios_seed_then_the_next() -> None:
    env = parallel_env(SCENARIO)
    seeds = [env.reset()[1]["auv_0"]["seed"], env.reset()[1]["auv_0"]["seed"], env.reset(seed=9)[1]["auv_0"]["seed"]]
    assert seeds == [1, 2, 9] and env.reset()[1]["auv_0"]["seed"] == 10


def test_an_action_outside_the_space_is_refused_in_one_line() -> None:
    env = parallel_env(SCENARIO)
    env.reset(seed=1)
    with pytest.raises(ValueError, match=r"^an action must be \(H = 5, 2\) integers") as bad:
        env.step({agent_name(env.slot_owner): np.full((5, 2), 9)})
    assert "\n" not in str(bad.value)


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        (
            {"faults": [{"at_s": 300.0, "target": "auv:2", "action": "restart", "down_s": 60.0}]},
            "faults[0]: the env cannot run an AUV restart (auv:2 at 300 s): PettingZoo forbids an agent's revival",
        ),
        ({"planner.method": "centralised"}, "planner.method 'centralised'"),
    ],
)
def test_scenarios_the_env_cannot_run_are_refused_in_one_line(keys: dict, message: str) -> None:
    scenario = load_scenario(SCENARIO).with_keys(keys)
    with pytest.raises(ConfigError) as refused:
        parallel_env(scenario)
    assert str(refused.value).startswith(message) and "\n" not in str(refused.value)


def test_without_pettingzoo_the_import_says_which_extra_in_one_line() -> None:
    code = "import sys\nsys.modules['pettingzoo'] = None\nimport auv_swarm.env\n"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1] == (
        "ImportError: auv_swarm.env needs PettingZoo, the extra rl: pip install 'auv-swarm[rl]'"
    )


def test_the_random_policy_example_runs_a_mission(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "rl_random.py"), "--duration", "300"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stdout.splitlines()
    assert lines[0].startswith("22 steps (TDMA slots), ") and lines[1].startswith("tracking error "), done.stdout


def test_the_bearings_rows_hold_a_full_frame_from_every_neighbour_in_either_ocean() -> None:
    """K = the own bearings of a slot + (n - 1) frames: 7 + 2 x 27 under the paper's payload v2, 7 + 2 x 23 under
    a physical ocean's v3 (a noise figure beside each bearing; docs/ocean.md's 23 bearings a frame)."""
    assert parallel_env("paper-3.2-challenging").max_bearings == 7 + 2 * 27
    assert parallel_env("ocean-coastal-summer").max_bearings == 7 + 2 * 23
