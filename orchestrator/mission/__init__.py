"""One mission: :func:`~auv_swarm.orchestrator.mission.api.run_mission`, its two launch modes (in process,
and one OS process per component), supervision and faults, the router and results-collector processes,
and what the sweep and the CLI share with it (progress, results folders, compose's image and secrets)."""
