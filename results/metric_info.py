"""The one table of ``metrics.json``'s names: each metric's human label, unit, kind and meaning (:data:`METRIC_INFO`).

docs/results.md's metric table is generated from it (tools/gendocs.py), the sweep store's metric columns and the
sweep summary's labels come from it, and a unit test fails when ``metrics.json`` holds a name it lacks. Adding a
metric is one line here. Nested names are dotted (``channel.delivery_ratio``); ``<id>`` stands for an AUV id
under ``agents`` and ``<reason>`` for a drop reason under ``channel.dropped``. The definitions in full are in
docs/results.md.
"""

from __future__ import annotations

from dataclasses import dataclass

KINDS = {
    "real": "REAL",
    "fraction": "REAL",
    "count": "INTEGER",
    "flag": "INTEGER",
    "text": "TEXT",
    "list": "",
    "table": "",
}
"""Each kind and the SQLite type of its store column ("" for a kind the store keeps only in the metrics JSON).
real: a measured quantity in ``unit``; fraction: a share in [0, 1], printed as one; count: a whole number;
flag: true or false; text; list; table: an object of further metrics."""

NUMBER_KINDS = ("real", "fraction", "count", "flag")
"""Kinds whose top-level metrics are columns of the sweep store and can be summarised over seeds."""


@dataclass(frozen=True)
class Metric:
    """One name of ``metrics.json``: a short human label, its unit ("" for none), kind (:data:`KINDS`), meaning."""

    label: str
    unit: str
    kind: str
    meaning: str

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {self.kind!r}")

    def axis_label(self) -> str:
        """The label with its unit, for a figure's axis: ``mean tracking error (m)``."""
        return f"{self.label} ({self.unit})" if self.unit else self.label


M = Metric

# fmt: off
METRIC_INFO: dict[str, Metric] = {
    "scenario": M("scenario", "", "text", "the scenario's name"),
    "seed": M("seed", "", "count", "run.seed"),
    "mode": M("mode", "", "text", "inprocess or processes"),
    "n_agents": M("AUVs", "", "count", "number of AUVs"),
    "complete": M("complete", "", "flag", "the mission ran to run.duration_s"),
    "incomplete_reason": M("incomplete reason", "", "text", "null, or why the mission ended early"),
    "exit_code": M("exit code", "", "count", "the code auv-swarm run exits with"),
    "error": M("error", "", "text", "null, or the message of a plug-in method that raised (method_error)"),
    "plugins": M("plug-ins", "", "list", "{kind, name, ref, package, version} of each plug-in method the mission ran"),
    "sim_duration_s": M("sim time", "s", "real", "last tick minus first (sim time)"),
    "wall_time_s": M("mission wall", "s", "real", "wall time of the mission's lockstep loop, first tick to last"),
    "run_wall_time_s": M("run wall", "s", "real", "wall time of the run: the command (or run_mission call) to metrics.json"),
    "ticks": M("ticks", "", "count", "world ticks run"),
    "tracking_error_mean_m": M("mean tracking error", "m", "real", "mean over live (AUV, tick) samples with an estimate"),
    "tracking_error_std_m": M("tracking error std", "m", "real", "population std (ddof 0) of those samples"),
    "tracking_error_samples": M("error samples", "", "count", "number of those samples"),
    "no_estimate_fraction": M("no estimate", "", "fraction", "share of live samples without an estimate"),
    "convergence_error_m": M("convergence bound", "m", "real", "run.convergence_error_m"),
    "convergence_hold_s": M("convergence hold", "s", "real", "how long the bound must hold"),
    "convergence_time_s": M("convergence time", "s", "real", "first time the team-mean error holds the bound"),
    "tracking_error_steady_mean_m": M("steady error", "m", "real", "mean tracking error after convergence"),
    "tracking_error_p95_m": M("tracking error p95", "m", "real", "95th percentile of every valid sample"),
    "under_15m_after_convergence_fraction": M("under 15 m after convergence", "", "fraction", "share of samples <= 15 m"),
    "longest_excursion_s": M("longest excursion", "s", "real", "longest time one AUV spent over 15 m"),
    "nees_mean": M("NEES mean", "", "real", "mean position NEES after convergence (2: consistent)"),
    "nees_in_band_fraction": M("NEES in band", "", "fraction", "share of NEES samples in the 95 % chi-square band"),
    "nees_samples": M("NEES samples", "", "count", "number of NEES samples"),
    "fqi": M("FQI", "", "real", "formation quality index (1: optimal geometry)"),
    "fqi_degenerate_ticks": M("degenerate ticks", "", "count", "ticks with parallel bearings, left out of FQI"),
    "plan_count": M("plans", "", "count", "optimisations of every AUV"),
    "plan_time_median_ms": M("plan time median", "ms", "real", "median wall time of an optimisation"),
    "plan_time_max_ms": M("plan time max", "ms", "real", "longest optimisation"),
    "kills": M("losses", "", "list", "{agent, t_s} of every lost AUV, in time order"),
    "after_first_kill": M("after the first loss", "", "table", "the survivors' error after the first loss"),
    "after_first_kill.t_s": M("first loss", "s", "real", "time of the first loss"),
    "after_first_kill.samples": M("samples after the loss", "", "count", "survivors' samples after it"),
    "after_first_kill.tracking_error_mean_m": M("survivors' error", "m", "real", "their mean tracking error"),
    "after_first_kill.tracking_error_p95_m": M("survivors' error p95", "m", "real", "its 95th percentile"),
    "after_first_kill.fraction_below_threshold": M("survivors under the bound", "", "fraction", "share <= the bound"),
    "duplicate_logins": M("duplicate logins", "", "count", "AUVs found with a second login (issue 44)"),
    "compromised_auvs": M("compromised AUVs", "", "list", "ids of the AUVs quarantined for a second login"),
    "nav_error_mean_m": M("navigation error mean", "m", "real", "believed against true position, live AUVs and ticks"),
    "nav_error_max_m": M("navigation error max", "m", "real", "the largest of those (0.0 under perfect navigation)"),
    "agents": M("per AUV", "", "table", "one table per AUV id"),
    "agents.<id>": M("one AUV", "", "table", "that AUV's own figures"),
    "agents.<id>.alive_until_s": M("alive until", "s", "real", "time of the AUV's loss (null: survived)"),
    "agents.<id>.alive_intervals_s": M("alive intervals", "s", "list", "[start, end] of each stretch alive"),
    "agents.<id>.hung_intervals_s": M("hung intervals", "s", "list", "[start, end] of each stretch hung"),
    "agents.<id>.tracking_error_mean_m": M("mean tracking error", "m", "real", "the AUV's own samples"),
    "agents.<id>.tracking_error_std_m": M("tracking error std", "m", "real", "population std of them"),
    "agents.<id>.tracking_error_p95_m": M("tracking error p95", "m", "real", "their 95th percentile"),
    "agents.<id>.track_lost": M("tracks lost", "", "count", "times the error stayed over 50 m for 60 s"),
    "agents.<id>.longest_excursion_s": M("longest excursion", "s", "real", "longest time over 15 m"),
    "agents.<id>.no_estimate_fraction": M("no estimate", "", "fraction", "share of live samples without one"),
    "agents.<id>.no_estimate_fraction_after_300s": M("no estimate after 300 s", "", "fraction", "the same at t >= 300 s"),
    "agents.<id>.plans": M("plans", "", "count", "the AUV's optimisations"),
    "agents.<id>.plan_time_median_ms": M("plan time median", "ms", "real", "their median wall time"),
    "agents.<id>.duplicate_logins": M("duplicate logins", "", "count", "1 when found with a second login, else 0"),
    "channel": M("channel", "", "table", "the channel's counts over the run"),
    "channel.sent": M("frames sent", "", "count", "frames put on the channel"),
    "channel.delivered": M("links delivered", "", "count", "receptions (one per sender-recipient pair)"),
    "channel.deferred": M("deferred", "", "count", "transmissions deferred to the sender's slot"),
    "channel.in_flight_at_end": M("in flight at the end", "", "count", "links on their way when it ended"),
    "channel.dropped": M("dropped by reason", "", "table", "link (or frame) drops by reason"),
    "channel.dropped.<reason>": M("dropped", "", "count", "drops for that reason (docs/channel.md)"),
    "channel.dropped_total": M("links dropped", "", "count", "every drop"),
    "channel.delivery_ratio": M("delivery ratio", "", "fraction", "delivered / (delivered + dropped_total)"),
    "channel.latency_mean_s": M("latency mean", "s", "real", "airtime plus propagation, delivered links"),
    "channel.latency_max_s": M("latency max", "s", "real", "the longest of them"),
}
# fmt: on
"""Every name ``metrics.json`` holds (dotted for nested ones), in the file's order."""


def metric_name(path: tuple[str, ...]) -> str:
    """The :data:`METRIC_INFO` name of a key path of ``metrics.json``: AUV ids as ``<id>``, drop reasons as
    ``<reason>``."""
    parts = list(path)
    if len(parts) >= 2 and parts[0] == "agents":
        parts[1] = "<id>"
    if len(parts) >= 3 and parts[:2] == ["channel", "dropped"]:
        parts[2] = "<reason>"
    return ".".join(parts)


def metric_names(metrics: dict, prefix: tuple[str, ...] = ()) -> set[str]:
    """Every :data:`METRIC_INFO` name a ``metrics.json`` object uses (tables and their members)."""
    names = set()
    for key, value in metrics.items():
        path = (*prefix, str(key))
        names.add(metric_name(path))
        if isinstance(value, dict):
            names |= metric_names(value, path)
    return names


def label(name: str) -> str:
    """A metric's human label with its unit (:meth:`Metric.axis_label`); the name itself if it has no entry."""
    info = METRIC_INFO.get(name)
    return info.axis_label() if info is not None else name


def store_columns() -> tuple[tuple[str, str], ...]:
    """(name, SQLite type) of every top-level number of ``metrics.json`` but the seed: the store's metric columns."""
    return tuple(
        (name, KINDS[m.kind])
        for name, m in METRIC_INFO.items()
        if "." not in name and m.kind in NUMBER_KINDS and name != "seed"
    )


def table_markdown() -> str:
    """docs/results.md's metric table (tools/gendocs.py)."""
    lines = ["| name | label | unit | kind | meaning |", "|---|---|---|---|---|"]
    for name, m in METRIC_INFO.items():
        meaning = m.meaning.replace("|", "\\|")
        lines.append(f"| `{name}` | {m.label} | {m.unit or '-'} | {m.kind} | {meaning} |")
    return "\n".join(lines)
