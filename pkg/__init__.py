"""auv-swarm: a distributed AUV swarm for cooperative underwater acoustic source tracking.

The one import package of the project. Its subpackages are the repository's top-level folders
(``auv_swarm.agent``, ``auv_swarm.contract``, ``auv_swarm.world``, ...; docs/README.md maps them).
The root keeps a few entry points for Python and notebooks, loaded on first use so that importing
a component (``import auv_swarm.agent``) loads nothing of the orchestrator or the results::

    import auv_swarm
    scenario = auv_swarm.load_scenario("paper-3.2-challenging").with_overrides(seed=2)
    result = auv_swarm.run_mission(scenario)
    print(result.metrics["tracking_error_mean_m"])
    auv_swarm.export("runs/my-run", format="csv")  # a run folder's raw data (also: result.export(...))
    auv_swarm.compare(["runs/a", "runs/b"])  # runs side by side, compare.png

docs/python.md describes the API.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__all__ = ["load_scenario", "run_mission", "MissionResult", "Launch", "Scenario", "ConfigError", "export", "compare"]

_LAZY = {
    "load_scenario": "auv_swarm.contract.config",
    "Scenario": "auv_swarm.contract.config",
    "ConfigError": "auv_swarm.contract.config",
    "run_mission": "auv_swarm.orchestrator.mission.api",
    "MissionResult": "auv_swarm.orchestrator.mission.api",
    "Launch": "auv_swarm.orchestrator.mission.api",
    "export": "auv_swarm.results.export",
    "compare": "auv_swarm.results.compare",
}


def __getattr__(name: str) -> Any:
    """The public names of :data:`_LAZY`, imported when first asked for (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'auv_swarm' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
