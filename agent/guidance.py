"""Line-of-sight guidance: turns the first planned step into surge and yaw-rate commands for eq. (1).

The planner's first step is a leg from ``leg_start`` (where the vehicle was when it planned)
through ``waypoint`` (its predicted position after one step). The vehicle follows the infinite
line through the leg, so after the waypoint it keeps going along the leg direction instead of
circling a reached point. Frames: inertial x/y in metres, headings in radians counter-clockwise
from +x; u in m/s, r in rad/s.
"""

from __future__ import annotations

import math

import numpy as np

MIN_LEG_M = 1e-6
"""Legs shorter than this (m) count as "stay here": the vehicle stops and holds its heading."""


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
    leg_start: np.ndarray | tuple[float, float],
    waypoint: np.ndarray | tuple[float, float],
    speed: float,
    u_max: float,
    r_max: float,
    k_heading: float = 0.2,
    lookahead_m: float = 100.0,
) -> tuple[float, float]:
    """Surge and yaw-rate command (u m/s, r rad/s) that tracks the leg leg_start -> waypoint and its extension.

    Line of sight: with path direction chi and signed cross-track error e (positive left of the
    path), the desired heading is psi_los = chi - atan(e / lookahead_m). Then
    r = clip(k_heading * wrap(psi_los - theta), -r_max, r_max) and
    u = clip(speed, 0, u_max) * max(0, cos(psi_los - theta)): the vehicle slows while it turns and
    turns on the spot when it faces more than 90 degrees away from the line of sight, which
    approximates the planner's turn-then-go step. A zero-length leg or a zero speed gives (0, 0).
    """
    s = _finite_floats(state, 3, "state", "three finite numbers (x m, y m, theta rad)")
    a = _finite_floats(leg_start, 2, "leg_start", "two finite numbers (m)")
    b = _finite_floats(waypoint, 2, "waypoint", "two finite numbers (m)")
    for name, value, unit in (
        ("u_max", u_max, "m/s"),
        ("r_max", r_max, "rad/s"),
        ("k_heading", k_heading, "1/s"),
        ("lookahead_m", lookahead_m, "m"),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be in (0, inf) {unit}, got {value!r}")
    if not math.isfinite(speed):
        raise ValueError(f"speed must be finite (m/s), got {speed!r}")
    leg = (b[0] - a[0], b[1] - a[1])
    length = math.hypot(leg[0], leg[1])
    if speed <= 0.0 or length < MIN_LEG_M:
        return 0.0, 0.0
    tx, ty = leg[0] / length, leg[1] / length
    cross = tx * (s[1] - a[1]) - ty * (s[0] - a[0])
    psi_los = math.atan2(ty, tx) - math.atan(cross / lookahead_m)
    err = wrap_pi(psi_los - s[2])
    r = min(max(k_heading * err, -r_max), r_max)
    u = min(speed, u_max) * max(0.0, math.cos(err))
    return float(u), float(r)
