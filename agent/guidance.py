"""Heading-hold guidance: executes one planned control (heading change, surge) under eq. (1).

The planner's step model (eqs. 46-49) is "turn by dtheta, then run a straight leg at the chosen
speed for T_o". The vehicle of eq. (1) turns at a finite rate, at most r_max, and may turn at any
surge in [0, u_max], including zero (a turn in place). Guidance therefore holds the plan's heading
chi = theta_plan + dtheta at the plan's speed: it turns towards chi as fast as r_max allows,
reaching it exactly (dead-beat over one tick), and keeps the speed throughout. The executed step
then differs from the planned one only during the turn; docs/planner.md ("Executed motion") derives
the bound :func:`step_position_bound`. Frames: inertial x/y in metres, headings in radians
counter-clockwise from +x; u in m/s, r in rad/s.
"""

from __future__ import annotations

import math

import numpy as np


def wrap_pi(angle: float) -> float:
    """Angle wrapped to [-pi, pi) (rad)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _finite_floats(value: object, size: int, name: str, what: str) -> tuple[float, ...]:
    """``value`` (a sequence or array of ``size`` numbers) as Python floats, or ValueError naming ``name``."""
    if type(value) is tuple and all(type(v) is float for v in value):
        out = value
    else:
        try:
            out = tuple(np.asarray(value, dtype=float).reshape(-1).tolist())
        except (TypeError, ValueError):
            out = ()
    if len(out) != size or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be {what}, got {value!r}")
    return out


def guidance(
    state: np.ndarray | tuple[float, float, float],
    heading: float,
    speed: float,
    u_max: float,
    r_max: float,
    dt_s: float,
) -> tuple[float, float]:
    """Surge and yaw-rate command (u m/s, r rad/s) that holds heading ``heading`` (rad) at surge ``speed``.

    r = clip(wrap(heading - theta) / dt_s, -r_max, r_max): the vehicle turns at r_max until the
    heading is less than one tick's turn away, then lands on it in that tick (``dt_s`` is the tick
    over which the world integrates a constant command, s). u = clip(speed, 0, u_max) throughout,
    so a zero speed turns the vehicle in place, as eq. (1) allows.
    """
    s = _finite_floats(state, 3, "state", "three finite numbers (x m, y m, theta rad)")
    for name, value, unit in (("u_max", u_max, "m/s"), ("r_max", r_max, "rad/s"), ("dt_s", dt_s, "s")):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be in (0, inf) {unit}, got {value!r}")
    if not math.isfinite(speed):
        raise ValueError(f"speed must be finite (m/s), got {speed!r}")
    if not math.isfinite(heading):
        raise ValueError(f"heading must be finite (rad), got {heading!r}")
    err = wrap_pi(heading - s[2])
    r = min(max(err / dt_s, -r_max), r_max)
    u = min(max(speed, 0.0), u_max)
    return float(u), float(r)


def step_position_bound(dtheta: float, speed: float, r_max: float, dt_s: float) -> float:
    """Largest distance (m) between the executed and the planned end of one step (docs/planner.md).

    The planned step turns by ``dtheta`` (rad) at once, then runs at ``speed`` (m/s); the executed one
    turns at r_max (rad/s) under :func:`guidance` with ticks of ``dt_s`` (s), at the same speed. The
    headings differ only during the turn, by at most |dtheta| - r_max t, so the positions differ by at most
    speed * (dtheta^2 / (2 r_max) + r_max dt_s^2 / 2) (the second term: the last tick's slower landing).
    Requires |dtheta| <= r_max * T_o (``planner.control_set`` enforces it).
    """
    a = abs(dtheta)
    if a == 0.0:
        return 0.0
    return abs(speed) * (a * a / (2.0 * r_max) + 0.5 * r_max * dt_s * dt_s)
