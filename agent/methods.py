"""The planning methods an AUV can run, by the name ``planner.method`` gives them.

A scenario picks its method with ``planner.method`` (default ``"dmpc"``, the exact DMPC search of
:mod:`auv_swarm.agent.planner`). The agent builds its planner once with :func:`make_planner` and calls
``planner.plan(problem)`` at each of its slots; nothing else in the agent depends on the method.

The names are :mod:`auv_swarm.contract.methods`'s: the built-ins (``contract.methods.BUILTIN``: the DMPC, the
section 3.3 baselines of docs/baselines.md, and ``centralised``, whose AUVs do not plan but follow the central
planner, ``central/``), those registered with :func:`register` and the installed plug-ins (entry point group
``auv_swarm.planners``). A method is a class (or function) ``factory(scenario, auv)`` returning an object with
``plan(self, problem: PlanProblem) -> Plan`` (the :class:`~auv_swarm.agent.planner.protocol.Planner` protocol; a
pure core: any random stream comes from ``contract.rng.stream(scenario.run.seed, ...)``); docs/planner.md and
docs/python.md.
"""

from __future__ import annotations

from collections.abc import Callable

from auv_swarm.agent import plugins
from auv_swarm.agent.planner.protocol import Planner
from auv_swarm.contract.config import Scenario

PlannerFactory = Callable[[Scenario, int], Planner]
"""Builds the planner of AUV ``auv`` for a scenario: ``factory(scenario, auv)``."""


def register(name: str, factory: PlannerFactory) -> None:
    """Make ``planner.method = name`` build ``factory(scenario, auv)``: in this process, and in the processes it
    starts (processes mode, a sweep's workers) when ``factory`` is defined at the top level of a module or a script
    (it is handed over by reference, ``module:QualName`` or ``path/to/file.py:QualName``, and imported there).

    A lambda or a closure works in this process only; a mission elsewhere is refused with one line saying so.
    Raises ValueError for an empty name, a built-in's or a taken one, or a factory that is not callable.
    """
    plugins.register("planner", name, factory)


def make_planner(scenario: Scenario, auv: int) -> Planner:
    """The planner ``scenario.planner.method`` names, for AUV ``auv``; ConfigError naming the key if unknown (or
    ``centralised``, which has no per-AUV planner). A plug-in's errors are MethodErrors naming the AUV."""
    return plugins.build("planner", scenario.planner.method, auv, scenario, auv)
