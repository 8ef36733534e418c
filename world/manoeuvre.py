"""Manoeuvring source paths: piecewise constant speed and turn rate, integrated exactly (arcs and legs).

Every manoeuvring target model (``waypoints``, ``stop_and_go``, ``constant_turn``, ``random_turn``)
is a sequence of segments; within a segment the speed v (m/s) and the turn rate w (rad/s) are
constant, so the heading is psi(s) = psi_k + w s and the position is an exact arc,
p(s) = p_k + (v / w) [sin psi(s) - sin psi_k, cos psi_k - cos psi(s)], evaluated as the chord
v s sinc(w s / 2) along psi_k + w s / 2 (exact, and a straight leg when w = 0).
After the last segment the last (v, w) holds for ever.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from auv_swarm.contract.config import TargetConfig

STEP_S = 1.0
"""Control period (s) of the waypoint follower and the granularity of stop-and-go and random-turn timings."""

CAPTURE_FRACTION = 1.0
"""A waypoint counts as reached within this many turn radii (at least 2 m)."""


class Segments:
    """A path of constant-(v, w) segments starting at ``t_k`` from ``(p_k, psi_k)``."""

    def __init__(self, p0: np.ndarray, psi0: float) -> None:
        self.t: list[float] = [0.0]
        self.p: list[tuple[float, float]] = [(float(p0[0]), float(p0[1]))]
        self.psi: list[float] = [psi0]
        self.v: list[float] = []
        self.w: list[float] = []

    def append(self, v: float, w: float, duration_s: float) -> None:
        """Run at speed ``v`` and turn rate ``w`` for ``duration_s`` from the end of the path."""
        p, psi = _arc(np.array(self.p[-1]), self.psi[-1], v, w, duration_s)
        self.v.append(v)
        self.w.append(w)
        self.t.append(self.t[-1] + duration_s)
        self.p.append((float(p[0]), float(p[1])))
        self.psi.append(psi)

    def end(self) -> tuple[np.ndarray, float, float]:
        """Position, heading and time at the end of the path."""
        return np.array(self.p[-1]), self.psi[-1], self.t[-1]

    def freeze(self) -> None:
        """Turn the lists into arrays for ``state``; the last (v, w) continues after the end."""
        if not self.v:
            self.v, self.w = [0.0], [0.0]
        self._t = np.array(self.t[: len(self.v)])
        self._p = np.array(self.p[: len(self.v)])
        self._psi = np.array(self.psi[: len(self.v)])
        self._v = np.array(self.v)
        self._w = np.array(self.w)

    def state(self, t: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and velocity (m/s) at sim time ``t`` (s); shapes t.shape + (2,)."""
        tt = np.asarray(t, dtype=float)
        k = np.clip(np.searchsorted(self._t, tt, side="right") - 1, 0, self._v.size - 1)
        s = tt - self._t[k]
        v, w, psi0 = self._v[k], self._w[k], self._psi[k]
        psi = psi0 + w * s
        chord = v * s * np.sinc(w * s / (2.0 * math.pi))  # |p(s) - p_k| of the arc, exact also for w = 0
        mid = psi0 + 0.5 * w * s
        pos = np.stack((self._p[k, 0] + chord * np.cos(mid), self._p[k, 1] + chord * np.sin(mid)), axis=-1)
        vel = np.stack((v * np.cos(psi), v * np.sin(psi)), axis=-1)
        return pos, vel


def _arc(p: np.ndarray, psi: float, v: float, w: float, s: float) -> tuple[np.ndarray, float]:
    """Position and heading after ``s`` seconds at speed ``v`` and turn rate ``w`` from ``(p, psi)``: the chord
    ``v s sinc(w s / 2)`` along the mean heading ``psi + w s / 2`` (the arc, without cancellation for small w)."""
    chord = v * s * float(np.sinc(w * s / (2.0 * math.pi)))
    mid = psi + 0.5 * w * s
    return p + chord * np.array([math.cos(mid), math.sin(mid)]), psi + w * s


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def waypoints(cfg: TargetConfig, p0: np.ndarray, psi0: float, duration_s: float) -> Segments:
    """Follow ``cfg.waypoints_m`` in order (again from the first if ``cfg.loop``) at the leg speeds.

    Each ``STEP_S`` the follower turns towards the current waypoint at the largest rate the turn radius
    allows (v / R), less when the heading error is smaller. After the last waypoint the source keeps
    its heading and the last leg's speed.
    """
    seg = Segments(p0, psi0)
    pts = [np.array(w, dtype=float) for w in cfg.waypoints_m]
    speeds = list(cfg.leg_speeds_mps) or [cfg.speed_mps]
    if len(speeds) == 1:
        speeds = speeds * len(pts)
    leg = 0
    while seg.end()[2] < duration_s and leg < len(pts) * (10**6 if cfg.loop else 1):
        target = pts[leg % len(pts)]
        v = speeds[leg % len(pts)]
        p, psi, _ = seg.end()
        d = target - p
        if math.hypot(*d) <= max(2.0, CAPTURE_FRACTION * cfg.turn_radius_m) or v == 0.0:
            leg += 1
            continue
        error = _wrap(math.atan2(d[1], d[0]) - psi)
        w_max = v / cfg.turn_radius_m
        w = max(-w_max, min(w_max, error / STEP_S))
        seg.append(v, w, STEP_S)
    if seg.end()[2] < duration_s:
        last = speeds[(len(pts) - 1) % len(speeds)] if not cfg.loop else speeds[leg % len(pts)]
        seg.append(last, 0.0, duration_s - seg.end()[2] + STEP_S)
    return seg


def stop_and_go(cfg: TargetConfig, p0: np.ndarray, psi0: float, duration_s: float) -> Segments:
    """Run ``go_s`` at ``speed_mps``, stop ``stop_s``, turn by ``stop_turn_rad`` while stopped; repeat."""
    seg = Segments(p0, psi0)
    while seg.end()[2] < duration_s:
        seg.append(cfg.speed_mps, 0.0, cfg.go_s)
        seg.append(0.0, 0.0, cfg.stop_s)
        if cfg.stop_turn_rad:
            seg.append(0.0, cfg.stop_turn_rad / STEP_S, STEP_S)  # a turn on the spot takes one step
    return seg


def constant_turn(cfg: TargetConfig, p0: np.ndarray, psi0: float) -> Segments:
    """A circle (or straight line) at ``speed_mps`` and ``turn_rate_radps`` for ever."""
    seg = Segments(p0, psi0)
    seg.append(cfg.speed_mps, cfg.turn_rate_radps, 1.0)
    return seg


def random_turn(
    cfg: TargetConfig, p0: np.ndarray, psi0: float, duration_s: float, rng: np.random.Generator
) -> Segments:
    """Random-turn model: at speed ``speed_mps``, hold a turn rate for an exponential time of mean
    ``manoeuvre_interval_s`` (rounded up to ``STEP_S``), then draw a new one uniformly in
    [-v/R, v/R] with R = ``turn_radius_m`` or go straight with probability 1/2. Seeded by ``rng``."""
    seg = Segments(p0, psi0)
    v = cfg.speed_mps
    w_max = v / cfg.turn_radius_m
    while seg.end()[2] < duration_s:
        hold = max(STEP_S, STEP_S * math.ceil(float(rng.exponential(cfg.manoeuvre_interval_s)) / STEP_S))
        straight = bool(rng.random() < 0.5)
        w = 0.0 if straight else float(rng.uniform(-w_max, w_max))
        seg.append(v, w, hold)
    return seg
