"""The AUV's target estimator: one protocol, a registry by name, fast paths and a readable reference.

- ``base``: ``Bearing``, ``Estimate``, the ``Estimator`` protocol (``update(bearings, t_s) -> Estimate``),
  the constant-velocity transition (14), the bearing Jacobian and the consensus step (21).
- ``window``: ``wls-cv``, the moving-window pseudo-linear WLS with Gauss-Newton (fast path).
- ``adaptive``: ``adaptive-window`` (the default), the 600 s ``wls-cv`` window and the manoeuvring-track
  model side by side, mixed by the likelihood of their innovations with a prior for the long window.
- ``spline``: the manoeuvring-track model, a piecewise-linear track with an acceleration-noise prior.
- ``kernels``: the fast path's numerical kernels.
- ``reference``: the same WLS and Gauss-Newton written plainly from eqs. (6)-(15), and the track
  model's fit written row by row, for tests.

``make_estimator`` builds the estimator a scenario names in ``estimator.method``; a built-in one is a
class with the ``Estimator`` verb and its name and reference in ``contract.methods.BUILTIN`` (docs/estimator.md);
a user's own is added from outside the package with :func:`register` or as an installed plug-in (entry point
group ``auv_swarm.estimators``; docs/python.md, examples/own_estimator.py).
"""

from __future__ import annotations

from collections.abc import Callable

from auv_swarm.agent import plugins
from auv_swarm.agent.estimator.adaptive import AdaptiveWindowEstimator
from auv_swarm.agent.estimator.base import (
    UNKNOWN_VARIANCE,
    Bearing,
    Estimate,
    Estimator,
    bearing_jacobian,
    consensus,
    not_ok,
    transition,
)
from auv_swarm.agent.estimator.window import BearingEstimator
from auv_swarm.contract.config import ESTIMATOR_METHODS, EstimatorConfig

EstimatorFactory = Callable[[EstimatorConfig, float], Estimator]
"""Builds an estimator from the scenario's ``EstimatorConfig`` and the bearing noise's half-width sigma_m (rad)."""


def register(name: str, factory: EstimatorFactory) -> None:
    """Make ``estimator.method = name`` build ``factory(cfg, sigma_m_rad)``.

    ``factory`` is a class (or function) taking the scenario's ``EstimatorConfig`` and the bearing noise's
    uniform half-width (rad) and returning an object with ``update(bearings, t_s) -> Estimate`` and ``__len__``.
    It holds in this process and, when ``factory`` is defined at the top level of a module or a script, in the
    processes this one starts (processes mode, a sweep's workers), which import it by reference
    (``agent.methods.register`` says how). Raises ValueError for an empty name, a built-in's or a taken one, or
    a factory that is not callable.
    """
    plugins.register("estimator", name, factory)


def make_estimator(cfg: EstimatorConfig, sigma_m_rad: float, auv: int | None = None) -> Estimator:
    """The estimator ``cfg.method`` names, for bearings with uniform noise of half-width ``sigma_m_rad`` (rad).

    Raises ``ConfigError`` naming ``estimator.method`` and the allowed names if the name is unknown; a plug-in's
    errors are MethodErrors (naming AUV ``auv`` when given).
    """
    return plugins.build("estimator", cfg.method, auv, cfg, sigma_m_rad)


__all__ = [
    "AdaptiveWindowEstimator",
    "ESTIMATOR_METHODS",
    "UNKNOWN_VARIANCE",
    "Bearing",
    "BearingEstimator",
    "Estimate",
    "Estimator",
    "bearing_jacobian",
    "consensus",
    "make_estimator",
    "register",
    "not_ok",
    "transition",
]
