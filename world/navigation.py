"""Each AUV's own navigation: dead reckoning with a log and compass bias between position fixes.

The model (docs/navigation.md), per AUV, in the complex notation z = x + i y of the inertial frame (m):

- Over a tick the vehicle moves by the true displacement dp (eq. (1), integrated by the world). Its
  dead reckoning (a Doppler log and a compass) adds g dp to the position it believes, with the gain
  g = exp(i b_h) (1 + s + i m): ``b_h`` the compass bias (rad, ``navigation.heading_bias_deg``), ``s`` the
  log's along-track scale error and ``m`` its cross-track misalignment (dimensionless, body frame). The
  vehicle of eq. (1) has no sway, so the body-frame error is the same complex factor whatever the heading.
- ``s`` and ``m`` are drawn independently from N(0, drift^2 / 2) (``navigation.drift_fraction``), so
  E|s + i m|^2 = drift^2: on a straight leg of length D the error is |s + i m| D and its radial RMS over
  vehicles is exactly drift * D. The error is a fixed linear map of the displacement since the last fix, so on
  a curved path it is at most |g - 1| times the distance travelled (equal on a straight leg).
- At every multiple of ``navigation.fix_period_s`` (at the first tick at or after it) a position fix sets the
  error to a draw of N(0, fix_sigma^2 / 2) per axis (radial RMS ``navigation.fix_sigma_m``) and draws the
  log's errors afresh. The compass bias stays.
- The AUV believes its heading is theta + b_h, and it measures bearings (eq. 4) against that compass, so its
  bearings are turned by b_h too.

Every draw comes from the navigation's own generator (``contract.rng.stream(seed, "navigation")``): per AUV id
in order, alive or dead, (s, m) at the start and (e_x, e_y, s, m) at each fix, so failures never shift it and
no other random stream moves. Pure: numpy only, time and the generator passed in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from auv_swarm.contract.config import NavigationConfig
from auv_swarm.contract.geometry import wrap_angle

_TIME_TOL_S = 1e-9


class DeadReckoning:
    """Where each AUV believes it is, given where it truly is (see the module docstring)."""

    def __init__(self, cfg: NavigationConfig, ids: Sequence[int], rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.ids = tuple(ids)
        self._row = {a: k for k, a in enumerate(self.ids)}
        self._rng = rng
        self.heading_bias_rad = math.radians(cfg.heading_bias_deg)
        self._turn = complex(math.cos(self.heading_bias_rad), math.sin(self.heading_bias_rad))
        self.error = np.zeros((len(self.ids), 2))
        """Believed minus true position (m), one row per AUV id."""
        self.log_error = np.zeros(len(self.ids), dtype=complex)
        """The log's s + i m per AUV (dimensionless)."""
        self.fixes = 0
        self._draw_log_errors()

    def _draw_log_errors(self) -> None:
        scale = self.cfg.drift_fraction / math.sqrt(2.0)
        draws = self._rng.standard_normal((len(self.ids), 2)) * scale
        self.log_error = draws[:, 0] + 1j * draws[:, 1]

    def gain(self, agent: int) -> complex:
        """g = exp(i b_h) (1 + s + i m) of ``agent``: its dead-reckoned displacement over the true one."""
        return self._turn * (1.0 + self.log_error[self._row[agent]])

    def move(self, agents: Sequence[int], displacement: ArrayLike) -> None:
        """Dead-reckon the true displacements (k, 2) in m of ``agents`` (k ids) over one tick: e += (g - 1) dp."""
        dp = np.asarray(displacement, dtype=float).reshape(len(agents), 2)
        rows = [self._row[a] for a in agents]
        g1 = self._turn * (1.0 + self.log_error[rows]) - 1.0
        z = dp[:, 0] + 1j * dp[:, 1]
        step = g1 * z
        self.error[rows, 0] += step.real
        self.error[rows, 1] += step.imag

    def fix_due(self, t_s: float) -> bool:
        """True when a fix falls in the tick that ended at ``t_s`` (s): a multiple of ``fix_period_s`` not yet made."""
        period = self.cfg.fix_period_s
        return period > 0.0 and (self.fixes + 1) * period <= t_s + _TIME_TOL_S

    def fix(self) -> None:
        """A position fix for every AUV: error drawn with radial RMS ``fix_sigma_m``, the log's errors drawn afresh."""
        sigma = self.cfg.fix_sigma_m / math.sqrt(2.0)
        scale = self.cfg.drift_fraction / math.sqrt(2.0)
        draws = self._rng.standard_normal((len(self.ids), 4))
        self.error = draws[:, :2] * sigma
        self.log_error = (draws[:, 2] + 1j * draws[:, 3]) * scale
        self.fixes += 1

    def believed(self, agent: int, state: ArrayLike) -> np.ndarray:
        """The pose (x m, y m, theta rad) ``agent`` believes it has when its true pose is ``state``."""
        x, y, theta = np.asarray(state, dtype=float).reshape(3).tolist()
        ex, ey = self.error[self._row[agent]].tolist()
        return np.array([x + ex, y + ey, wrap_angle(theta + self.heading_bias_rad)])

    def bearing(self, bearing_rad: float) -> float:
        """A bearing (rad, eq. 4) as the AUV measures it against its biased compass, wrapped to (-pi, pi]."""
        return float(wrap_angle(bearing_rad + self.heading_bias_rad))
