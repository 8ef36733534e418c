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
class with the ``Estimator`` verb, an entry in ``ESTIMATORS`` and its name in
``contract.config.ESTIMATOR_METHODS`` (docs/estimator.md); a user's own is added from outside the package
with :func:`register` (docs/python.md, examples/own_estimator.py).
"""

from __future__ import annotations

from collections.abc import Callable

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
from auv_swarm.contract.config import ESTIMATOR_METHODS, ConfigError, EstimatorConfig, accept_estimator_method

ESTIMATORS: dict[str, Callable[[EstimatorConfig, float], Estimator]] = {
    "wls-cv": BearingEstimator,
    "adaptive-window": AdaptiveWindowEstimator,
}
"""Estimator factories by ``estimator.method`` name; each takes the config and sigma_m (rad)."""


def register(name: str, factory: Callable[[EstimatorConfig, float], Estimator]) -> None:
    """Make ``estimator.method = name`` build ``factory(cfg, sigma_m_rad)`` in this process.

    ``factory`` is a class (or function) taking the scenario's ``EstimatorConfig`` and the bearing noise's
    uniform half-width (rad) and returning an object with ``update(bearings, t_s) -> Estimate`` and
    ``__len__``. It holds for what runs in this interpreter (``run_mission(mode="inprocess")``); a process
    of the multi-process swarm is a fresh interpreter and knows the built-ins only. Raises ValueError for an
    empty name or one that is taken.
    """
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"an estimator's name must be a non-empty string, got {name!r}")
    if name in ESTIMATORS:
        raise ValueError(f"estimator method {name!r} is registered already ({', '.join(ESTIMATORS)})")
    if not callable(factory):
        raise ValueError(f"the factory of estimator {name!r} must be callable (cfg, sigma_m_rad), got {factory!r}")
    ESTIMATORS[name] = factory
    accept_estimator_method(name)


def make_estimator(cfg: EstimatorConfig, sigma_m_rad: float) -> Estimator:
    """The estimator ``cfg.method`` names, for bearings with uniform noise of half-width ``sigma_m_rad`` (rad).

    Raises ``ConfigError`` naming ``estimator.method`` and the allowed names if the name is unknown.
    """
    factory = ESTIMATORS.get(cfg.method)
    if factory is None:
        allowed = ", ".join(repr(name) for name in ESTIMATORS)
        raise ConfigError(f"estimator.method must be one of {allowed}, got {cfg.method!r}")
    return factory(cfg, sigma_m_rad)


__all__ = [
    "ESTIMATORS",
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
