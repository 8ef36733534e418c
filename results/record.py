"""What a run leaves behind, as columns (``RunRecord``): per tick the truth and the true geometry cost, per AUV
and tick its state and estimate, every plan, event and channel count; filled by :mod:`auv_swarm.results.collect`,
read by :mod:`auv_swarm.results.metrics`."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from auv_swarm.contract.config import Scenario
from auv_swarm.contract.geometry import least_singular_value

PARALLEL_SIGMA_MIN = 1e-9
"""sigma_min(Phi) at or below which the bearings count as parallel (rounding level): geometry cost inf."""

PLAN_TERMS = ("geometry", "distance", "connectivity", "terminal", "penalty")
"""Cost terms a plan reports: eqs. (35), (36), (37), the terminal cost of (38), soft-constraint penalty."""

STATE = ("x", "y", "vx", "vy")
"""The target state xi of eq. (14): position (m) and velocity (m/s), local frame."""

COV_TERMS = tuple((STATE[i], STATE[j]) for i in range(4) for j in range(i, 4))
"""The ten upper-triangle entries of the 4x4 covariance P (eq. 15), row by row: (x, x), (x, y), ..., (vy, vy)."""

COV_INDEX = tuple(4 * i + j for i in range(4) for j in range(i, 4))
"""Where each of :data:`COV_TERMS` sits in P flattened row-major (``Telemetry.P``)."""


def true_geometry_cost(target_xy: Iterable[float], positions: Iterable[Iterable[float]]) -> float:
    """1/sigma_min(Phi) of eqs. (34)-(35) for sensors at ``positions`` about ``target_xy`` (m).

    Phi has unit rows [sin b, -cos b], b the bearing from sensor to target; sigma_min is
    ``contract.geometry.least_singular_value`` (cancellation-free for nearly parallel bearings).
    Optimum sqrt(2/n); NaN with fewer than 2 sensors; inf when all bearings are parallel
    (sigma_min <= :data:`PARALLEL_SIGMA_MIN`, i.e. parallel up to rounding).
    """
    tgt = np.asarray(target_xy, dtype=float).reshape(2)
    pos = np.asarray(list(positions), dtype=float).reshape(-1, 2)
    n = len(pos)
    if n < 2 or not np.isfinite(pos).all() or not np.isfinite(tgt).all():
        return math.nan
    d = tgt - pos
    sigma_min = float(least_singular_value(np.arctan2(d[:, 1], d[:, 0])))
    if sigma_min <= PARALLEL_SIGMA_MIN:
        return math.inf
    return 1.0 / sigma_min


class _Column:
    """Append-only array, amortised O(1) growth along axis 0."""

    def __init__(self, data: np.ndarray) -> None:
        self._buf = np.array(data, copy=True)
        self._n = len(self._buf)
        self.last_view = self._buf[: self._n]

    def append(self, row: Any) -> np.ndarray:
        """Append one row; return the view of all rows so far."""
        if self._n == len(self._buf):
            grown = np.empty((max(16, 2 * self._n),) + self._buf.shape[1:], dtype=self._buf.dtype)
            grown[: self._n] = self._buf[: self._n]
            self._buf = grown
        self._buf[self._n] = row
        self._n += 1
        self.last_view = self._buf[: self._n]
        return self.last_view


def _append_rows(owner: Any, rows: Iterable[tuple[str, Any]]) -> None:
    """Append one row to each named array attribute of ``owner``, keeping it exactly T long.

    A column is (re)built from the attribute when the attribute was replaced from
    outside since the last append, so direct assignment stays safe.
    """
    cols: dict[str, _Column] = owner._cols
    for name, value in rows:
        col = cols.get(name)
        if col is None or col.last_view is not getattr(owner, name):
            col = cols[name] = _Column(getattr(owner, name))
        setattr(owner, name, col.append(value))


@dataclass(frozen=True)
class AgentTick:
    """One AUV's state at one tick, as the runner hands it to :meth:`RunRecord.append_tick`.

    ``position`` (m) and ``heading`` (rad) are the true vehicle state; ``estimate``
    is the AUV's own target position estimate (m), or None when it has no valid one;
    ``estimate_cov`` its position covariance (Pxx, Pxy, Pyy) in m^2, or None if not known;
    ``velocity`` the estimate's (vx, vy) in m/s and ``covariance`` the ten entries of its 4x4
    covariance in :data:`COV_TERMS` order, each None if not known (recorded as NaN).
    """

    position: tuple[float, float]
    heading: float
    estimate: tuple[float, float] | None
    alive: bool = True
    estimate_cov: tuple[float, float, float] | None = None
    velocity: tuple[float, float] | None = None
    covariance: tuple[float, ...] | None = None
    believed: tuple[float, float] | None = None


@dataclass(eq=False)
class AgentSeries:
    """Everything recorded about one AUV: per-tick arrays (length T) and per-plan lists.

    ``velocity`` (T, 2) and ``covariance`` (T, 10, :data:`COV_TERMS`) complete the estimate; NaN where
    ``estimate`` is."""

    position: np.ndarray
    heading: np.ndarray
    estimate: np.ndarray
    estimate_ok: np.ndarray
    alive: np.ndarray
    estimate_cov: np.ndarray
    velocity: np.ndarray
    covariance: np.ndarray
    believed: np.ndarray
    plan_times_s: list[float] = field(default_factory=list)
    plan_wall_ms: list[float] = field(default_factory=list)
    plan_terms: list[dict[str, float]] = field(default_factory=list)
    alive_until_s: float | None = None
    hung_intervals_s: list[list[float | None]] = field(default_factory=list)
    _cols: dict[str, _Column] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def empty(cls) -> AgentSeries:
        """A series with no ticks yet."""
        return cls(
            position=np.empty((0, 2)),
            heading=np.empty(0),
            estimate=np.empty((0, 2)),
            estimate_ok=np.empty(0, dtype=bool),
            alive=np.empty(0, dtype=bool),
            estimate_cov=np.empty((0, 3)),
            velocity=np.empty((0, 2)),
            covariance=np.empty((0, len(COV_TERMS))),
            believed=np.empty((0, 2)),
        )

    def _append(self, tick: AgentTick | None) -> None:
        names = (
            "position",
            "heading",
            "estimate",
            "estimate_ok",
            "alive",
            "estimate_cov",
            "velocity",
            "covariance",
            "believed",
        )
        nan2, nan3, nan10 = (math.nan,) * 2, (math.nan,) * 3, (math.nan,) * len(COV_TERMS)
        if tick is None:
            row = (nan2, math.nan, nan2, False, False, nan3, nan2, nan10, nan2)
        else:
            est = nan2 if tick.estimate is None else (float(tick.estimate[0]), float(tick.estimate[1]))
            ok = bool(tick.alive) and tick.estimate is not None and all(math.isfinite(v) for v in est)
            cov = nan3 if tick.estimate_cov is None or not ok else tuple(float(v) for v in tick.estimate_cov)
            vel = nan2 if tick.velocity is None or not ok else tick.velocity
            full = nan10 if tick.covariance is None or not ok else tick.covariance
            believed = nan2 if tick.believed is None else (float(tick.believed[0]), float(tick.believed[1]))
            row = (tick.position, tick.heading, est if ok else nan2, ok, bool(tick.alive), cov, vel, full, believed)
        _append_rows(self, zip(names, row, strict=True))


@dataclass(frozen=True)
class Bearing:
    """One bearing of eq. (2): taken by AUV ``auv`` at sim time ``t_s`` (s) from ``sensor_xy`` (m, local frame),
    ``bearing_rad`` (rad from +x, counter-clockwise).

    ``recipient`` is -1 for the bearing as taken (the world's ``Sensor`` message; ``sensor_xy`` the AUV's true
    position), else the AUV it was delivered to in frame ``frame`` at ``t_delivered_s`` (s), with the time,
    position and angle as the acoustic payload carries them (0.1 s, 1 m, 0.1 deg steps).
    """

    t_s: float
    auv: int
    bearing_rad: float
    sensor_xy: tuple[float, float]
    recipient: int = -1
    t_delivered_s: float = math.nan
    frame: str = ""


INCOMPLETE_REASONS = (
    "world_died",
    "router_lost",
    "channel_lost",
    "central_lost",
    "start_failed",
    "interrupted",
    "method_error",
    "compromised",
)
"""Why a run can end incomplete (metrics.json ``incomplete_reason``)."""


@dataclass(eq=False)
class RunRecord:
    """What one mission produced.

    Per-tick arrays share the time axis ``times`` (T,): ``target`` (T, 4) is the
    true target state [x, y, vx, vy] (m, m/s); ``geometry_cost`` (T,) is
    1/sigma_min(Phi) (eqs. 34-35) of the true team geometry about the true target,
    over the live AUVs (NaN with fewer than two alive, inf when all bearings are
    parallel). ``events`` are JSON-ready dicts each with "t_s" and "kind"; ``bearings`` every bearing
    taken and every one delivered to another AUV (:class:`Bearing`).
    Build with :meth:`new`, then :meth:`append_tick`, :meth:`add_plan`,
    :meth:`add_packet`, :meth:`mark_killed`, :meth:`add_event` and :meth:`finish`.
    """

    scenario: Scenario
    mode: str
    wall_time_s: float
    times: np.ndarray
    target: np.ndarray
    agents: dict[int, AgentSeries]
    geometry_cost: np.ndarray
    channel_counters: dict[str, int] = field(default_factory=dict)
    latencies_s: list[float] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    bearings: list[Bearing] = field(default_factory=list)
    complete: bool = True
    incomplete_reason: str | None = None
    exit_code: int = 0
    run_wall_time_s: float | None = None
    """Wall time of the whole run (s): the command, or the run_mission call, to its metrics; None if not timed."""
    error: str | None = None
    """The message of a plug-in method that raised (``incomplete_reason = "method_error"``), else None."""
    _cols: dict[str, _Column] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def new(cls, scenario: Scenario, mode: str, agent_ids: Iterable[int]) -> RunRecord:
        """An empty record for the AUVs ``agent_ids`` ("inprocess", "multiprocess", ... in ``mode``)."""
        ids = sorted(int(i) for i in agent_ids)
        if len(set(ids)) != len(ids):
            raise ValueError(f"agent_ids must be distinct, got {ids}")
        return cls(
            scenario=scenario,
            mode=str(mode),
            wall_time_s=0.0,
            times=np.empty(0),
            target=np.empty((0, 4)),
            agents={i: AgentSeries.empty() for i in ids},
            geometry_cost=np.empty(0),
        )

    def append_tick(
        self,
        t_s: float,
        target: Iterable[float],
        agents: Mapping[int, AgentTick],
        geometry_cost: float | None = None,
    ) -> None:
        """Record one tick at sim time ``t_s`` (s, strictly increasing).

        ``target`` is the true state [x, y, vx, vy]; ``agents`` maps AUV id to its
        :class:`AgentTick` (an AUV left out is recorded as not alive, position NaN).
        ``geometry_cost`` defaults to :func:`true_geometry_cost` of the live AUVs.
        """
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if len(self.times) and t <= self.times[-1]:
            raise ValueError(f"t_s must increase: got {t:g} after {float(self.times[-1]):g}")
        unknown = set(agents) - set(self.agents)
        if unknown:
            raise ValueError(f"agents has ids {sorted(unknown)} not in the record's agent ids {sorted(self.agents)}")
        tgt = np.asarray(target, dtype=float).reshape(-1)
        if tgt.shape != (4,):
            raise ValueError(f"target must be [x, y, vx, vy], got shape {tgt.shape}")
        if geometry_cost is None:
            live = [a.position for a in agents.values() if a.alive]
            geometry_cost = true_geometry_cost(tgt[:2], live)
        _append_rows(self, (("times", t), ("target", tgt), ("geometry_cost", float(geometry_cost))))
        for i, series in self.agents.items():
            series._append(agents.get(i))

    def add_plan(self, agent: int, t_s: float, wall_ms: float, terms: Mapping[str, float]) -> None:
        """Record one optimisation of AUV ``agent`` at sim time ``t_s``: wall time (ms) and its cost terms.

        ``terms`` holds the chosen plan's cost terms as the planner reports them, keys
        from :data:`PLAN_TERMS` (missing keys are recorded as NaN). Also logs a "plan" event.
        """
        series = self._series(agent)
        row = {k: float(terms.get(k, math.nan)) for k in PLAN_TERMS}
        series.plan_times_s.append(float(t_s))
        series.plan_wall_ms.append(float(wall_ms))
        series.plan_terms.append(row)
        self.events.append({"t_s": float(t_s), "kind": "plan", "agent": int(agent), "wall_ms": float(wall_ms), **row})

    def mark_killed(self, agent: int, t_s: float, kind: str = "kill", reason: str | None = None) -> None:
        """AUV ``agent`` stopped at sim time ``t_s``: sets ``alive_until_s`` and logs the event.

        ``kind`` is "kill" for a failure the scenario planned, "death" for a crash or a hang
        nobody planned (with its ``reason``).
        """
        if kind not in ("kill", "death"):
            raise ValueError(f"kind must be 'kill' or 'death', got {kind!r}")
        self._series(agent).alive_until_s = float(t_s)
        event = {"t_s": float(t_s), "kind": kind, "agent": int(agent)}
        if reason is not None:
            event["reason"] = str(reason)
        self.events.append(event)

    def mark_hung(self, agent: int, t_s: float, hung: bool, reason: str = "") -> None:
        """AUV ``agent`` stopped answering (``hung``) or answers again at sim time ``t_s``: its hung intervals and
        a "hung" / "resume" event."""
        series = self._series(agent)
        if hung:
            series.hung_intervals_s.append([float(t_s), None])
        elif series.hung_intervals_s and series.hung_intervals_s[-1][1] is None:
            series.hung_intervals_s[-1][1] = float(t_s)
        event = {"t_s": float(t_s), "kind": "hung" if hung else "resume", "agent": int(agent)}
        if reason:
            event["reason"] = reason
        self.events.append(event)

    def mark_rejoined(self, agent: int, t_s: float) -> None:
        """A restarted AUV ``agent`` was re-admitted at sim time ``t_s``: alive again, a "rejoin" event."""
        self._series(agent).alive_until_s = None
        self.events.append({"t_s": float(t_s), "kind": "rejoin", "agent": int(agent)})

    def set_outcome(self, complete: bool, incomplete_reason: str | None, exit_code: int) -> None:
        """How the run ended: ``complete`` or not, and why (one of :data:`INCOMPLETE_REASONS`), and its exit code."""
        if complete != (incomplete_reason is None):
            raise ValueError(f"an incomplete run needs a reason and a complete one none, got {incomplete_reason!r}")
        if incomplete_reason is not None and incomplete_reason not in INCOMPLETE_REASONS:
            raise ValueError(f"incomplete_reason must be one of {INCOMPLETE_REASONS}, got {incomplete_reason!r}")
        self.complete = bool(complete)
        self.incomplete_reason = incomplete_reason
        self.exit_code = int(exit_code)

    def add_packet(self, event: Any) -> None:
        """Log one channel event (a ``ChannelEvent`` dataclass or a mapping with t_s, kind, ...).

        Stored with kind "packet_<kind>" (packet_sent, packet_delivered, packet_dropped);
        the latency of a delivered packet is appended to ``latencies_s``.
        """
        data = dataclasses.asdict(event) if dataclasses.is_dataclass(event) else dict(event)
        if "t_s" not in data or "kind" not in data:
            raise ValueError(f"a channel event needs t_s and kind, got keys {sorted(data)}")
        kind = str(data.pop("kind"))
        self.events.append({"t_s": float(data.pop("t_s")), "kind": f"packet_{kind}", **data})
        latency = data.get("latency_s")
        if kind == "delivered" and latency is not None:
            self.latencies_s.append(float(latency))

    def add_bearing(self, bearing: Bearing) -> None:
        """Record one bearing, taken by its AUV or delivered to another (:class:`Bearing`)."""
        self.bearings.append(bearing)

    def add_event(self, t_s: float, kind: str, **fields: Any) -> None:
        """Log any other event (JSON-serialisable fields)."""
        self.events.append({"t_s": float(t_s), "kind": str(kind), **fields})

    def finish(self, wall_time_s: float, channel_counters: Mapping[str, int] | None = None) -> None:
        """Set the run's wall-clock duration (s) and the channel's final counters."""
        self.wall_time_s = float(wall_time_s)
        if channel_counters is not None:
            self.channel_counters = {str(k): int(v) for k, v in channel_counters.items()}

    def _series(self, agent: int) -> AgentSeries:
        if agent not in self.agents:
            raise ValueError(f"agent must be one of {sorted(self.agents)}, got {agent!r}")
        return self.agents[agent]
