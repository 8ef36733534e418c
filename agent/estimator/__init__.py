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

``make_estimator`` builds the estimator a scenario names in ``estimator.method``; adding one
means a class with the ``Estimator`` verb, an entry in ``ESTIMATORS`` and its name in
``contract.config.ESTIMATOR_METHODS`` (see docs/estimator.md).
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
from auv_swarm.contract.config import ESTIMATOR_METHODS, ConfigError, EstimatorConfig

ESTIMATORS: dict[str, Callable[[EstimatorConfig, float], Estimator]] = {
    "wls-cv": BearingEstimator,
    "adaptive-window": AdaptiveWindowEstimator,
}
"""Estimator factories by ``estimator.method`` name; each takes the config and sigma_m (rad)."""


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
    "not_ok",
    "transition",
]
