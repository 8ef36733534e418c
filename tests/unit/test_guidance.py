"""Line-of-sight guidance: bounded commands, convergence onto the planned leg under eq. (1)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auv_swarm.agent.guidance import guidance

U_MAX = 2.0
R_MAX = 0.05

coord = st.floats(-5e3, 5e3, allow_nan=False)


def _simulate(state: np.ndarray, leg_start, waypoint, speed: float, seconds: float, dt: float = 0.5) -> np.ndarray:
    """Integrate the kinematics of eq. (1) (surge u along the heading, yaw rate r) under the guidance law."""
    s = state.astype(float).copy()
    out = [s.copy()]
    for _ in range(int(seconds / dt)):
        u, r = guidance(s, leg_start, waypoint, speed, U_MAX, R_MAX)
        s = s + dt * np.array([u * math.cos(s[2]), u * math.sin(s[2]), r])
        out.append(s.copy())
    return np.array(out)


@settings(max_examples=300, deadline=None)
@given(
    x=coord,
    y=coord,
    theta=st.floats(-20.0, 20.0),
    ax=coord,
    ay=coord,
    bx=coord,
    by=coord,
    speed=st.floats(-1.0, 5.0),
    k=st.floats(1e-3, 10.0),
    lookahead=st.floats(1.0, 1e3),
)
def test_commands_stay_within_bounds(x, y, theta, ax, ay, bx, by, speed, k, lookahead) -> None:
    u, r = guidance((x, y, theta), (ax, ay), (bx, by), speed, U_MAX, R_MAX, k_heading=k, lookahead_m=lookahead)
    assert 0.0 <= u <= min(U_MAX, max(speed, 0.0)) + 1e-12
    assert -R_MAX <= r <= R_MAX
    assert math.isfinite(u) and math.isfinite(r)


def test_converges_onto_a_straight_leg_from_an_offset_start() -> None:
    leg_start, waypoint = np.array([0.0, 0.0]), np.array([260.0, 0.0])
    track = _simulate(np.array([-50.0, 150.0, -math.pi / 2]), leg_start, waypoint, 2.0, 900.0)
    cross = track[:, 1]
    assert abs(cross[-1]) < 1.0
    assert abs(math.remainder(track[-1, 2], 2 * math.pi)) < 0.02
    late = track[len(track) // 2 :]
    assert np.all(np.diff(late[:, 0]) > 0.0)
    assert np.max(np.abs(late[:, 1])) < 20.0


def test_keeps_going_along_the_leg_after_the_waypoint() -> None:
    leg_start, waypoint = (
        np.array([100.0, 100.0]),
        np.array([100.0 + 50.0 * math.sqrt(0.5), 100.0 + 50.0 * math.sqrt(0.5)]),
    )
    track = _simulate(np.array([100.0, 100.0, math.pi / 4]), leg_start, waypoint, 1.5, 400.0)
    along = (track[:, :2] - leg_start) @ np.array([math.sqrt(0.5), math.sqrt(0.5)])
    assert along[-1] > 500.0
    assert np.all(np.diff(along) >= 0.0)
    assert np.allclose(track[:, 2], math.pi / 4, atol=1e-9)


def test_zero_leg_or_zero_speed_stops_the_vehicle() -> None:
    assert guidance((5.0, 5.0, 1.0), (0.0, 0.0), (0.0, 0.0), 2.0, U_MAX, R_MAX) == (0.0, 0.0)
    assert guidance((5.0, 5.0, 1.0), (0.0, 0.0), (100.0, 0.0), 0.0, U_MAX, R_MAX) == (0.0, 0.0)


def test_turns_on_the_spot_when_facing_away() -> None:
    u, r = guidance((0.0, 0.0, math.pi), (0.0, 0.0), (100.0, 0.0), 2.0, U_MAX, R_MAX)
    assert u == 0.0 and abs(r) == R_MAX


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"u_max": 0.0}, "u_max"),
        ({"r_max": -1.0}, "r_max"),
        ({"k_heading": 0.0}, "k_heading"),
        ({"lookahead_m": math.inf}, "lookahead_m"),
    ],
)
def test_invalid_parameters_name_the_parameter(kwargs: dict, name: str) -> None:
    args = {"u_max": U_MAX, "r_max": R_MAX, **kwargs}
    with pytest.raises(ValueError, match=f"{name} must be in"):
        guidance((0.0, 0.0, 0.0), (0.0, 0.0), (1.0, 0.0), 1.0, **args)
    with pytest.raises(ValueError, match="state"):
        guidance((0.0, math.nan, 0.0), (0.0, 0.0), (1.0, 0.0), 1.0, U_MAX, R_MAX)
