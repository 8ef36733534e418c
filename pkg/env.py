"""The swarm as a PettingZoo environment (docs/env.md): ``auv_swarm.env.parallel_env(scenario)``.

Needs the extra ``rl`` (``pip install 'auv-swarm[rl]'``); without it, importing this module raises an ImportError
that says so in one line. The code lives in :mod:`auv_swarm.orchestrator.mission.env`::

    from auv_swarm.env import parallel_env

    env = parallel_env("paper-3.2-challenging")
    observations, infos = env.reset(seed=1)
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
"""

from auv_swarm.orchestrator.mission.env import SlotPlanner, SwarmEnv, agent_name, parallel_env

__all__ = ["parallel_env", "SwarmEnv", "SlotPlanner", "agent_name"]
