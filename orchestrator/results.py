"""Run record, metrics, event log, plots and console summary of one mission.

A runner (in-process or multi-process) fills a :class:`RunRecord` tick by tick
(:meth:`RunRecord.append_tick`), plan by plan (:meth:`RunRecord.add_plan`) and
event by event; :func:`write_results` turns it into ``metrics.json``,
``events.jsonl`` and three PNG figures. Pure: numpy,
matplotlib (Agg canvas, no pyplot, imported only when a figure is drawn) and json; no clock, no I/O except in
:func:`write_results`.

Frames and units: positions in metres in the inertial frame, headings in rad
from +x counter-clockwise, times in seconds of simulated time, planner wall
times in milliseconds.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from contract.config import Scenario
from contract.geometry import least_singular_value
from orchestrator.tracking import position_nees, tracking_metrics

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PAPER_ERROR_BOUND_M = 15.0
"""The 15 m acceptable tracking-error bound drawn in the paper's Fig. 7b (m)."""

CONVERGENCE_HOLD_S = 60.0
"""How long the team-mean error must stay within run.convergence_error_m to count as converged (s)."""

PARALLEL_SIGMA_MIN = 1e-9
"""sigma_min(Phi) at or below which the bearings count as parallel (rounding level): geometry cost inf."""

PLAN_TERMS = ("geometry", "distance", "connectivity", "terminal", "penalty")
"""Cost terms a plan reports: eqs. (35), (36), (37), the terminal cost of (38), soft-constraint penalty."""


# ---------------------------------------------------------------------------- record


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
    ``estimate_cov`` its position covariance (Pxx, Pxy, Pyy) in m^2, or None if not known.
    """

    position: tuple[float, float]
    heading: float
    estimate: tuple[float, float] | None
    alive: bool = True
    estimate_cov: tuple[float, float, float] | None = None


@dataclass(eq=False)
class AgentSeries:
    """Everything recorded about one AUV: per-tick arrays (length T) and per-plan lists."""

    position: np.ndarray
    heading: np.ndarray
    estimate: np.ndarray
    estimate_ok: np.ndarray
    alive: np.ndarray
    estimate_cov: np.ndarray
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
        )

    def _append(self, tick: AgentTick | None) -> None:
        names = ("position", "heading", "estimate", "estimate_ok", "alive", "estimate_cov")
        nan2, nan3 = (math.nan, math.nan), (math.nan, math.nan, math.nan)
        if tick is None:
            row = (nan2, math.nan, nan2, False, False, nan3)
        else:
            est = nan2 if tick.estimate is None else (float(tick.estimate[0]), float(tick.estimate[1]))
            ok = bool(tick.alive) and tick.estimate is not None and all(math.isfinite(v) for v in est)
            cov = nan3 if tick.estimate_cov is None or not ok else tuple(float(v) for v in tick.estimate_cov)
            row = (tick.position, tick.heading, est if ok else nan2, ok, bool(tick.alive), cov)
        _append_rows(self, zip(names, row, strict=True))


INCOMPLETE_REASONS = ("world_died", "router_lost", "channel_lost", "central_lost", "start_failed", "interrupted")
"""Why a run can end incomplete (metrics.json ``incomplete_reason``)."""


@dataclass(eq=False)
class RunRecord:
    """What one mission produced.

    Per-tick arrays share the time axis ``times`` (T,): ``target`` (T, 4) is the
    true target state [x, y, vx, vy] (m, m/s); ``geometry_cost`` (T,) is
    1/sigma_min(Phi) (eqs. 34-35) of the true team geometry about the true target,
    over the live AUVs (NaN with fewer than two alive, inf when all bearings are
    parallel). ``events`` are JSON-ready dicts each with "t_s" and "kind".
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
    complete: bool = True
    incomplete_reason: str | None = None
    exit_code: int = 0
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


# ---------------------------------------------------------------------------- metrics


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


def tracking_errors(rec: RunRecord) -> dict[int, np.ndarray]:
    """Per-AUV tracking error |estimate - true position| (m) per tick; NaN when dead or without an estimate."""
    truth = rec.target[:, :2] if len(rec.times) else np.empty((0, 2))
    out = {}
    for i, s in rec.agents.items():
        err = np.linalg.norm(s.estimate - truth, axis=1) if len(truth) else np.empty(0)
        out[i] = np.where(s.alive & s.estimate_ok, err, np.nan)
    return out


def team_error(errors: Mapping[int, np.ndarray], n_ticks: int) -> np.ndarray:
    """Team-mean tracking error per tick (m): mean over AUVs with a valid error, NaN where none has one."""
    if not errors or n_ticks == 0:
        return np.full(n_ticks, np.nan)
    stack = np.vstack([errors[i] for i in sorted(errors)])
    valid = np.isfinite(stack)
    count = valid.sum(axis=0)
    total = np.where(valid, stack, 0.0).sum(axis=0)
    return np.divide(total, count, out=np.full(n_ticks, np.nan), where=count > 0)


def convergence_time(
    times: np.ndarray, error: np.ndarray, threshold_m: float, hold_s: float = CONVERGENCE_HOLD_S
) -> float | None:
    """Earliest sample time t_c whose window [t_c, t_c + hold_s] lies inside the run and holds only
    samples with error <= threshold_m (a NaN sample, i.e. no estimate, breaks the window).

    Returns t_c (s, on the ``times`` axis) or None if no such window exists.
    """
    if threshold_m <= 0 or not math.isfinite(threshold_m):
        raise ValueError(f"threshold_m must be in (0, inf), got {threshold_m!r}")
    if hold_s < 0 or not math.isfinite(hold_s):
        raise ValueError(f"hold_s must be in [0, inf), got {hold_s!r}")
    t = np.asarray(times, dtype=float)
    e = np.asarray(error, dtype=float)
    if len(t) == 0:
        return None
    good = np.isfinite(e) & (e <= threshold_m)
    bad_idx = np.flatnonzero(~good)
    eps = 1e-9 * max(1.0, abs(float(t[-1])))
    for k in np.flatnonzero(good):
        end = t[k] + hold_s
        if end > t[-1] + eps:
            return None
        last = np.searchsorted(t, end + eps, side="right")
        nxt = np.searchsorted(bad_idx, k)
        if nxt == len(bad_idx) or bad_idx[nxt] >= last:
            return float(t[k])
    return None


def _n_alive(rec: RunRecord) -> np.ndarray:
    """Number of live AUVs per tick."""
    if not rec.agents:
        return np.zeros(len(rec.times), dtype=int)
    return np.sum([s.alive for s in rec.agents.values()], axis=0).astype(int)


def _stats(values: np.ndarray) -> tuple[float | None, float | None]:
    v = values[np.isfinite(values)]
    if len(v) == 0:
        return None, None
    return float(np.mean(v)), float(np.std(v))


def compute_metrics(rec: RunRecord, hold_s: float = CONVERGENCE_HOLD_S) -> dict[str, Any]:
    """The run's figures of merit as JSON-safe data (None where undefined). See the README section "Results and metrics".

    Tracking error: over every (live AUV, tick) sample with a valid estimate
    (population std). Convergence: :func:`convergence_time` of the team-mean error
    against run.convergence_error_m. FQI: time-average of geometry_cost /
    sqrt(2 / n_alive) over ticks with >= 2 live AUVs (1 = optimal geometry).
    """
    n_ticks = len(rec.times)
    errors = tracking_errors(rec)
    all_err = np.concatenate([errors[i] for i in sorted(errors)]) if errors else np.empty(0)
    err_mean, err_std = _stats(all_err)
    alive_samples = int(sum(int(np.sum(s.alive)) for s in rec.agents.values()))
    missing = int(sum(int(np.sum(s.alive & ~s.estimate_ok)) for s in rec.agents.values()))

    team = team_error(errors, n_ticks)
    threshold = rec.scenario.run.convergence_error_m
    t_conv = convergence_time(rec.times, team, threshold, hold_s)
    t0 = float(rec.times[0]) if n_ticks else 0.0
    steady_mean = None
    if t_conv is not None:
        after = rec.times >= t_conv
        steady_mean, _ = _stats(np.concatenate([errors[i][after] for i in sorted(errors)]))

    n_alive = _n_alive(rec)
    use = n_alive >= 2
    ratio = rec.geometry_cost[use] / np.sqrt(2.0 / n_alive[use])
    degenerate = int(np.sum(~np.isfinite(ratio)))
    fqi = float(np.mean(ratio[np.isfinite(ratio)])) if np.any(np.isfinite(ratio)) else None

    truth = rec.target[:, :2] if n_ticks else np.empty((0, 2))
    nees = {i: position_nees(s.estimate - truth, s.estimate_cov) for i, s in rec.agents.items()}
    alive = {i: s.alive for i, s in rec.agents.items()}
    team_track, per_track = tracking_metrics(rec.times, errors, alive, nees, t_conv, rec.scenario.run.tick_s)

    wall = np.array([w for s in rec.agents.values() for w in s.plan_wall_ms], dtype=float)
    agents = {}
    end_s = float(rec.times[-1]) if n_ticks else 0.0
    for i in sorted(rec.agents):
        s = rec.agents[i]
        m, sd = _stats(errors[i])
        alive_i = int(np.sum(s.alive))
        agents[str(i)] = {
            "alive_until_s": s.alive_until_s,
            "alive_intervals_s": alive_intervals(rec.times, s.alive),
            "hung_intervals_s": [[a, b if b is not None else end_s] for a, b in s.hung_intervals_s],
            "tracking_error_mean_m": m,
            "tracking_error_std_m": sd,
            **per_track[i],
            "no_estimate_fraction": (int(np.sum(s.alive & ~s.estimate_ok)) / alive_i) if alive_i else None,
            "plans": len(s.plan_wall_ms),
            "plan_time_median_ms": float(np.median(s.plan_wall_ms)) if s.plan_wall_ms else None,
        }

    metrics = {
        "scenario": rec.scenario.name,
        "seed": rec.scenario.run.seed,
        "mode": rec.mode,
        "n_agents": len(rec.agents),
        "complete": rec.complete,
        "incomplete_reason": rec.incomplete_reason,
        "exit_code": rec.exit_code,
        "sim_duration_s": float(rec.times[-1] - rec.times[0]) if n_ticks else 0.0,
        "wall_time_s": rec.wall_time_s,
        "ticks": n_ticks,
        "tracking_error_mean_m": err_mean,
        "tracking_error_std_m": err_std,
        "tracking_error_samples": int(np.sum(np.isfinite(all_err))),
        "no_estimate_fraction": missing / alive_samples if alive_samples else None,
        "convergence_error_m": threshold,
        "convergence_hold_s": hold_s,
        "convergence_time_s": None if t_conv is None else t_conv - t0,
        "tracking_error_steady_mean_m": steady_mean,
        **team_track,
        "fqi": fqi,
        "fqi_degenerate_ticks": degenerate,
        "plan_count": int(len(wall)),
        "plan_time_median_ms": float(np.median(wall)) if len(wall) else None,
        "plan_time_max_ms": float(np.max(wall)) if len(wall) else None,
        "kills": sorted(
            (
                {"agent": i, "t_s": rec.agents[i].alive_until_s}
                for i in rec.agents
                if rec.agents[i].alive_until_s is not None
            ),
            key=lambda k: (k["t_s"], k["agent"]),
        ),
        "after_first_kill": _after_first_kill(rec, errors, threshold),
        "agents": agents,
        "channel": _channel_metrics(rec),
    }
    return json_safe(metrics)


def alive_intervals(times: np.ndarray, alive: np.ndarray) -> list[list[float]]:
    """[start, end] sim times (s) of each stretch an AUV was alive: from its first live tick to the first tick
    it was not (a death at t ends the stretch at t), or to the last tick of the run."""
    out: list[list[float]] = []
    start = None
    for t, up in zip(times.tolist(), alive.tolist(), strict=True):
        if up and start is None:
            start = t
        elif not up and start is not None:
            out.append([start, t])
            start = None
    if start is not None:
        out.append([start, float(times[-1])])
    return out


def _after_first_kill(rec: RunRecord, errors: dict[int, np.ndarray], threshold_m: float) -> dict[str, Any] | None:
    """Tracking error of the survivors after the first AUV loss (the paper's Fig. 7b check); None if nobody died."""
    kill_times = [s.alive_until_s for s in rec.agents.values() if s.alive_until_s is not None]
    if not kill_times:
        return None
    t_kill = min(kill_times)
    after = rec.times > t_kill
    samples = np.concatenate([errors[i][after] for i in sorted(errors)])
    samples = samples[np.isfinite(samples)]
    if samples.size == 0:
        return {"t_s": t_kill, "samples": 0}
    return {
        "t_s": t_kill,
        "samples": int(samples.size),
        "tracking_error_mean_m": float(np.mean(samples)),
        "tracking_error_p95_m": float(np.percentile(samples, 95)),
        "fraction_below_threshold": float(np.mean(samples <= threshold_m)),
    }


def _channel_metrics(rec: RunRecord) -> dict[str, Any]:
    c = rec.channel_counters
    dropped = {k[len("dropped_") :]: int(v) for k, v in sorted(c.items()) if k.startswith("dropped_")}
    delivered = int(c.get("delivered", 0))
    attempts = delivered + sum(dropped.values())
    lat = np.asarray(rec.latencies_s, dtype=float)
    return {
        "sent": int(c.get("sent", 0)),
        "delivered": delivered,
        "deferred": int(c.get("deferred", 0)),
        "dropped": dropped,
        "dropped_total": sum(dropped.values()),
        "delivery_ratio": delivered / attempts if attempts else None,
        "latency_mean_s": float(np.mean(lat)) if len(lat) else None,
        "latency_max_s": float(np.max(lat)) if len(lat) else None,
    }


def json_safe(obj: Any) -> Any:
    """Recursively convert to JSON-ready data: numpy scalars/arrays to Python, NaN/inf to None, tuples to lists."""
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


# ---------------------------------------------------------------------------- files


def write_results(rec: RunRecord, out_dir: Path) -> dict[str, Any]:
    """Write metrics.json, events.jsonl, trajectories.png, tracking_error.png and costs.png into
    ``out_dir`` (created if needed); return the metrics."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = compute_metrics(rec)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    events = sorted(rec.events, key=lambda e: e["t_s"])
    with (out / "events.jsonl").open("w", encoding="utf-8") as fh:
        for ev in events:
            fh.write(json.dumps(json_safe(ev), allow_nan=False, separators=(",", ":")) + "\n")
    errors = tracking_errors(rec)
    _save(plot_trajectories(rec), out / "trajectories.png")
    _save(plot_tracking_error(rec, errors, metrics), out / "tracking_error.png")
    _save(plot_costs(rec), out / "costs.png")
    return metrics


def _figure(**kwargs: Any) -> Figure:
    """A matplotlib figure on an Agg canvas (matplotlib is imported on first use, not with this module)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> None:
    fig.savefig(path, dpi=110)


def _colour(k: int) -> str:
    return f"C{k % 10}"


def _kill_times(rec: RunRecord) -> list[tuple[int, float]]:
    return [(i, s.alive_until_s) for i, s in sorted(rec.agents.items()) if s.alive_until_s is not None]


def plot_trajectories(rec: RunRecord) -> Figure:
    """Plan view: each AUV's path while alive (o start, s end, x where it was lost) and the target's true path."""
    fig = _figure(figsize=(7.5, 7.0))
    ax = fig.add_subplot()
    if len(rec.times):
        tx, ty = rec.target[:, 0], rec.target[:, 1]
        ax.plot(tx, ty, "k--", lw=1.5, label="target (truth)")
        ax.plot(tx[0], ty[0], "ko", ms=6)
        ax.plot(tx[-1], ty[-1], "k*", ms=10)
    for k, (i, s) in enumerate(sorted(rec.agents.items())):
        idx = np.flatnonzero(s.alive & np.all(np.isfinite(s.position), axis=1))
        if len(idx) == 0:
            continue
        p = s.position[idx]
        c = _colour(k)
        ax.plot(p[:, 0], p[:, 1], "-", color=c, lw=1.2, label=f"AUV {i}")
        ax.plot(p[0, 0], p[0, 1], "o", color=c, ms=6)
        if s.alive_until_s is not None:
            ax.plot(p[-1, 0], p[-1, 1], "x", color=c, ms=12, mew=3, label=f"AUV {i} lost at {s.alive_until_s:g} s")
        else:
            ax.plot(p[-1, 0], p[-1, 1], "s", color=c, ms=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{rec.scenario.name}: trajectories (o start, s end, x lost)")
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig


def plot_tracking_error(
    rec: RunRecord, errors: Mapping[int, np.ndarray] | None = None, metrics: Mapping[str, Any] | None = None
) -> Figure:
    """Tracking error of every AUV vs sim time, the paper's 15 m bound, kill times and the convergence time."""
    errors = tracking_errors(rec) if errors is None else errors
    fig = _figure(figsize=(9.0, 4.8))
    ax = fig.add_subplot()
    peak = 0.0
    for k, i in enumerate(sorted(errors)):
        e = errors[i]
        if np.any(np.isfinite(e)):
            peak = max(peak, float(np.nanmax(e)))
        ax.plot(rec.times, e, "-", color=_colour(k), lw=1.0, label=f"AUV {i}")
        ax.plot(rec.times, e, ".", color=_colour(k), ms=2.0)  # every sample, also one isolated between gaps
    ax.axhline(
        PAPER_ERROR_BOUND_M, color="red", ls="--", lw=1.2, label=f"{PAPER_ERROR_BOUND_M:g} m bound (paper, Fig. 7b)"
    )
    for i, t in _kill_times(rec):
        ax.axvline(t, color="0.3", ls=":", lw=1.2)
        ax.annotate(
            f"AUV {i} lost", (t, 1.0), xycoords=("data", "axes fraction"), rotation=90, va="top", ha="right", fontsize=8
        )
    t_conv = None if metrics is None else metrics.get("convergence_time_s")
    if t_conv is not None and len(rec.times):
        ax.axvline(float(rec.times[0]) + t_conv, color="green", ls="-.", lw=1.0, label=f"converged at {t_conv:g} s")
    if peak > 20 * PAPER_ERROR_BOUND_M:
        ax.set_yscale("log")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("tracking error (m)")
    ax.set_title(f"{rec.scenario.name}: tracking error per AUV")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def plot_costs(rec: RunRecord) -> Figure:
    """Each AUV's planned cost terms (geometry, distance, connectivity) per plan, and the true-geometry cost."""
    fig = _figure(figsize=(9.0, 9.0))
    axes = fig.subplots(4, 1, sharex=True)
    panels = (
        ("geometry", "geometry cost (35)"),
        ("distance", "distance cost (36)"),
        ("connectivity", "connectivity cost (37)"),
    )
    for ax, (key, label) in zip(axes[:3], panels, strict=True):
        for k, (i, s) in enumerate(sorted(rec.agents.items())):
            if not s.plan_times_s:
                continue
            v = np.array([row.get(key, math.nan) for row in s.plan_terms], dtype=float)
            v[~np.isfinite(v)] = np.nan
            ax.plot(s.plan_times_s, v, ".-", color=_colour(k), lw=1.0, label=f"AUV {i}")
        ax.set_ylabel(label, fontsize=9)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=8)
    ax = axes[3]
    g = np.where(np.isfinite(rec.geometry_cost), rec.geometry_cost, np.nan)
    ax.plot(rec.times, g, "k-", lw=1.0, label="1/sigma_min(Phi), true geometry")
    n_alive = _n_alive(rec)
    optimum = np.where(n_alive >= 2, np.sqrt(2.0 / np.maximum(n_alive, 1)), np.nan)
    ax.plot(rec.times, optimum, color="green", ls="--", lw=1.0, label="optimum sqrt(2/n_alive)")
    positive = g[np.isfinite(g) & (g > 0)]
    if len(positive) and positive.max() > 20 * positive.min():
        ax.set_yscale("log")
    ax.set_ylabel("true geometry cost", fontsize=9)
    ax.set_xlabel("sim time (s)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    for _, t in _kill_times(rec):
        for a in axes:
            a.axvline(t, color="0.3", ls=":", lw=1.0)
    axes[0].set_title(f"{rec.scenario.name}: planned cost terms (per plan) and true geometry")
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------- console


def _fmt(value: Any, spec: str = ".1f", unit: str = "") -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:{spec}}{unit}"
    return f"{value}{unit}"


def summary_table(metrics: Mapping[str, Any]) -> str:
    """The console summary of one run's metrics (as returned by :func:`compute_metrics`)."""
    m = metrics
    ch = m.get("channel", {})
    err = (
        "-"
        if m.get("tracking_error_mean_m") is None
        else (f"{m['tracking_error_mean_m']:.1f} +/- {m['tracking_error_std_m']:.1f} m")
    )
    drops = ", ".join(f"{k} {v}" for k, v in ch.get("dropped", {}).items() if v) or "none"
    rows = [
        ("scenario", f"{m.get('scenario')}  (seed {m.get('seed')}, mode {m.get('mode')})"),
        (
            "sim / wall time",
            f"{_fmt(m.get('sim_duration_s'), '.0f', ' s')} / {_fmt(m.get('wall_time_s'), '.1f', ' s')}",
        ),
        ("tracking error", f"{err}  (no estimate {_fmt(_pct(m.get('no_estimate_fraction')), '.1f', ' %')} of samples)"),
        (
            "convergence",
            f"{'never' if m.get('convergence_time_s') is None else _fmt(m['convergence_time_s'], '.0f', ' s')} "
            f"(team-mean error <= {_fmt(m.get('convergence_error_m'), 'g', ' m')} held "
            f"{_fmt(m.get('convergence_hold_s'), 'g', ' s')}); "
            f"steady error {_fmt(m.get('tracking_error_steady_mean_m'), '.1f', ' m')}",
        ),
        (
            "after convergence",
            f"{_fmt(_pct(m.get('under_15m_after_convergence_fraction')), '.1f', ' %')} of samples <= 15 m, "
            f"longest excursion {_fmt(m.get('longest_excursion_s'), '.0f', ' s')}; "
            f"error p95 {_fmt(m.get('tracking_error_p95_m'), '.1f', ' m')}",
        ),
        (
            "NEES (position)",
            f"mean {_fmt(m.get('nees_mean'), '.2f')} (2 = consistent), "
            f"{_fmt(_pct(m.get('nees_in_band_fraction')), '.1f', ' %')} in the 95 % band [0.05, 7.38]",
        ),
        ("FQI", f"{_fmt(m.get('fqi'), '.2f')}  (1 = optimal geometry)"),
    ]
    after = m.get("after_first_kill")
    if after and after.get("samples"):
        rows.append(
            (
                "after 1st loss",
                f"t > {_fmt(after['t_s'], 'g', ' s')}: survivors' error {_fmt(after['tracking_error_mean_m'], '.1f', ' m')} "
                f"mean, {_fmt(after['tracking_error_p95_m'], '.1f', ' m')} p95, "
                f"{_fmt(_pct(after['fraction_below_threshold']), '.1f', ' %')} of samples <= "
                f"{_fmt(m.get('convergence_error_m'), 'g', ' m')}",
            )
        )
    rows += [
        (
            "plan time",
            f"median {_fmt(m.get('plan_time_median_ms'), '.1f', ' ms')}, max {_fmt(m.get('plan_time_max_ms'), '.1f', ' ms')} "
            f"({m.get('plan_count', 0)} plans)",
        ),
        (
            "channel",
            f"frames: {ch.get('sent', 0)} sent, {ch.get('deferred', 0)} deferred; "
            f"links (frame to one recipient): {ch.get('delivered', 0)} delivered, "
            f"{ch.get('dropped_total', 0)} dropped ({drops}), "
            f"{_fmt(_pct(ch.get('delivery_ratio')), '.0f', ' %')} delivered; "
            f"latency {_fmt(ch.get('latency_mean_s'), '.2f', ' s')}",
        ),
    ]
    width = max(len(k) for k, _ in rows)
    lines = [f"{k:<{width}}  {v}" for k, v in rows]
    header = ("AUV", "alive until", "error mean", "error std", "p95", "lost", "no est.", "plans", "plan median")
    table = [header]
    for i, a in m.get("agents", {}).items():
        table.append(
            (
                i,
                _fmt(a.get("alive_until_s"), "g", " s") if a.get("alive_until_s") is not None else "end",
                _fmt(a.get("tracking_error_mean_m"), ".1f", " m"),
                _fmt(a.get("tracking_error_std_m"), ".1f", " m"),
                _fmt(a.get("tracking_error_p95_m"), ".1f", " m"),
                _fmt(a.get("track_lost"), "d"),
                _fmt(_pct(a.get("no_estimate_fraction")), ".1f", " %"),
                str(a.get("plans", 0)),
                _fmt(a.get("plan_time_median_ms"), ".1f", " ms"),
            )
        )
    widths = [max(len(r[c]) for r in table) for c in range(len(header))]
    lines.append("")
    for r in table:
        lines.append("  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)).rstrip())
    return "\n".join(lines)


def _pct(fraction: float | None) -> float | None:
    return None if fraction is None else 100.0 * fraction


WALL_CLOCK_KEYS = ("wall_time_s", "plan_time_median_ms", "plan_time_max_ms", "mode")


def comparable(metrics: dict) -> dict:
    """Metrics without wall-clock figures (and the mode), for determinism checks."""
    out = {k: v for k, v in metrics.items() if k not in WALL_CLOCK_KEYS}
    out["agents"] = {
        a: {k: v for k, v in m.items() if "ms" not in k and "wall" not in k} for a, m in metrics["agents"].items()
    }
    return out
