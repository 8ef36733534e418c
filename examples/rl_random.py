"""Step the swarm as a PettingZoo environment with a random policy for one mission, and print its error.

    python examples/rl_random.py [--scenario paper-3.2-challenging] [--seed 1] [--duration S]

Needs the extra rl (``pip install 'auv-swarm[rl]'``). Each step is one TDMA slot; the slot owner's random
(heading index, speed index) sequence becomes the plan it broadcasts (docs/env.md). The DMPC's own mission
of the same seed is ``auv-swarm run --scenario paper-3.2-challenging --seed 1``.
"""

from __future__ import annotations

import argparse

import auv_swarm
from auv_swarm.contract.config import ConfigError
from auv_swarm.contract.usage import fail


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper-3.2-challenging", help="built-in name or TOML path")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=None, help="sim seconds (default: the scenario's)")
    args = parser.parse_args(argv)
    try:
        from auv_swarm.env import parallel_env

        scenario = auv_swarm.load_scenario(args.scenario).with_overrides(duration_s=args.duration)
        env = parallel_env(scenario)
    except (ImportError, ConfigError) as exc:
        return fail(str(exc))

    observations, infos = env.reset(seed=args.seed)
    for i, agent in enumerate(env.possible_agents):  # a reproducible random policy
        env.action_space(agent).seed(args.seed + i)
    steps, total_reward, applied = 0, 0.0, 0
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        steps += 1
        total_reward += sum(rewards.values()) / len(rewards)
        applied += sum(info["action_applied"] for info in infos.values())
    metrics = env.metrics()
    env.close()

    print(f"{steps} steps (TDMA slots), {applied} random plans applied, return {total_reward:.1f}")
    error = metrics["tracking_error_mean_m"]  # None when no AUV ever held an estimate
    print(f"tracking error {'none' if error is None else f'{error:.1f} m'} mean (random policy, seed {args.seed})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
