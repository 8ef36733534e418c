"""How the swarm looks in rerun: colours, shapes (covariance ellipses, range circles), entity names, and the
viewer layout (blueprint) built once per recording. Pure functions; :mod:`recorder.core` logs with them."""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Sequence
from typing import Any

import numpy as np
import rerun.blueprint as rrb

from auv_swarm.contract.config import Scenario
from auv_swarm.recorder.viewer import TIMELINE

ELLIPSE_CONFIDENCE = 0.95
ELLIPSE_POINTS = 48

AUV_COLOURS = np.array(
    [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (148, 103, 189),
        (23, 190, 207),
        (227, 119, 194),
        (188, 189, 34),
        (140, 86, 75),
    ],
    dtype=np.uint8,
)
TARGET_COLOUR = (214, 39, 40, 255)
DEAD_COLOUR = (120, 120, 120, 255)
REASON_COLOURS = {
    "random_loss": (200, 200, 200, 200),
    "low_snr": (255, 80, 80, 220),
    "outside_slot": (255, 200, 0, 220),
    "oversize": (255, 0, 255, 220),
    "tx_backlog_full": (160, 0, 255, 220),
    "collision": (255, 140, 0, 220),
    "half_duplex": (0, 200, 255, 220),
    "recipient_dead": (120, 120, 120, 220),
}
OTHER_REASON_COLOUR = (255, 255, 255, 220)
_SEGMENT_BAD = re.compile(r"[^A-Za-z0-9_.-]")


def auv_colour(auv: int, alpha: int = 255) -> tuple[int, int, int, int]:
    """The display colour (RGBA, 0-255) of AUV ``auv``."""
    r, g, b = (int(c) for c in AUV_COLOURS[auv % len(AUV_COLOURS)])
    return (r, g, b, alpha)


def snr_colour(snr_db: float | None, threshold_db: float, span_db: float) -> tuple[int, ...]:
    """RGBA of a delivered packet: red at ``threshold_db`` (DT), yellow half-way, green at DT + ``span_db`` and above."""
    if not span_db > 0.0:
        raise ValueError(f"span_db must be > 0 dB, got {span_db!r}")
    if snr_db is None or not math.isfinite(snr_db):
        return (160, 160, 160, 230)
    s = min(1.0, max(0.0, (snr_db - threshold_db) / span_db))
    r = 255 if s < 0.5 else int(round(255 * 2 * (1.0 - s)))
    g = int(round(255 * 2 * s)) if s < 0.5 else 255
    return (r, g, 40, 230)


def covariance_ellipse(
    center: Sequence[float], cov: Any, confidence: float = ELLIPSE_CONFIDENCE, n_points: int = ELLIPSE_POINTS
) -> np.ndarray:
    """Closed polyline (n_points + 1, 2) of the ``confidence`` region of a 2-D Gaussian (m).

    ``cov`` is the 2x2 position block of the estimate covariance P (eq. 15, m^2),
    symmetrised; negative eigenvalues (round-off) count as zero. The scale is the
    chi-square quantile with 2 degrees of freedom, sqrt(-2 ln(1 - confidence)).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 3:
        raise ValueError(f"n_points must be an integer >= 3, got {n_points!r}")
    c = np.asarray(cov, dtype=float)
    mu = np.asarray(center, dtype=float)
    if c.shape != (2, 2) or mu.shape != (2,):
        raise ValueError(f"cov must be 2x2 and center of length 2, got shapes {c.shape} and {mu.shape}")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(mu))):
        raise ValueError("cov and center must be finite")
    scale = float(np.max(np.abs(c))) or 1.0
    a, b, d = c[0, 0] / scale, 0.5 * (c[0, 1] + c[1, 0]) / scale, c[1, 1] / scale
    mid, half = 0.5 * (a + d), math.hypot(0.5 * (a - d), b)
    k = math.sqrt(-2.0 * math.log1p(-confidence) * scale)
    major, minor = k * math.sqrt(max(mid + half, 0.0)), k * math.sqrt(max(mid - half, 0.0))
    theta = 0.5 * math.atan2(2.0 * b, a - d)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    axes = np.array([[major * cos_t, -minor * sin_t], [major * sin_t, minor * cos_t]])
    return mu + (axes @ unit_circle(n_points)).T


@functools.cache
def unit_circle(n_points: int) -> np.ndarray:
    """(2, n_points + 1) cos/sin of n_points + 1 angles from 0 to 2 pi (closed)."""
    angles = np.linspace(0.0, 2.0 * math.pi, n_points + 1)
    return np.stack([np.cos(angles), np.sin(angles)])


def circle(center: Sequence[float], radius_m: float, n_points: int = 64) -> np.ndarray:
    """Closed polyline (n_points + 1, 2) of the circle of ``radius_m`` (m) around ``center`` (m)."""
    if not (math.isfinite(radius_m) and radius_m >= 0.0):
        raise ValueError(f"radius_m must be a finite number >= 0 m, got {radius_m!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 3:
        raise ValueError(f"n_points must be an integer >= 3, got {n_points!r}")
    return np.asarray(center, dtype=float) + radius_m * unit_circle(n_points).T


def segment(name: str) -> str:
    """``name`` as one entity-path segment (characters other than letters, digits, _ . - become _)."""
    return _SEGMENT_BAD.sub("_", name) or "_"


def counter_entity(name: str) -> str:
    """Packet counters (sent, delivered, deferred, dropped_<reason>) under plots/channel, the rest under channel_other."""
    packet = name in ("sent", "delivered", "deferred") or name.startswith("dropped_")
    return f"plots/{'channel' if packet else 'channel_other'}/{segment(name)}"


TRACKING_ERROR_RANGE_M = 100.0
"""Upper end of the tracking-error plot's initial y range (m): the 15 m bound and the 50 m track-lost level in view."""


def blueprint(scenario: Scenario) -> rrb.Blueprint:
    """The viewer layout: the 2-D map on the left, the plots and the event log in a grid on the right."""
    mission = rrb.TimeRange(
        start=rrb.TimeRangeBoundary.absolute(seconds=0.0),
        end=rrb.TimeRangeBoundary.absolute(seconds=scenario.run.duration_s),
    )

    def plot(name: str, origin: str, axis_y: rrb.ScalarAxis | None = None) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(
            name=name,
            origin=origin,
            plot_legend=rrb.PlotLegend(visible=True),
            axis_x=rrb.TimeAxis(view_range=mission),
            axis_y=axis_y,
        )

    plots = [
        # a fixed 0-100 m y range (zoomable): one early spike of hundreds of metres no longer flattens the rest
        plot("tracking error (m)", "plots/tracking_error", rrb.ScalarAxis(range=(0.0, TRACKING_ERROR_RANGE_M))),
        plot("Fiedler value lambda_2 (eq. 37)", "plots/fiedler"),
        plot("cost: geometry (eq. 35)", "plots/cost/geometry"),
        plot("cost: distance (eq. 36)", "plots/cost/distance"),
        plot("cost: connectivity (eq. 37)", "plots/cost/connectivity"),
        plot("planning time (ms, wall clock)", "plots/plan_ms"),
        plot("channel counters (cumulative)", "plots/channel"),
        rrb.TextLogView(name="events", origin="events"),
    ]
    if not scenario.navigation.perfect:
        plots.insert(1, plot("navigation error (m, believed - true position)", "plots/nav_error"))
    title = f"map: {scenario.name} (m, x east, y north)"
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name=title, origin="/", contents=["world/**"]),
            rrb.Grid(*plots, grid_columns=2),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=TIMELINE, play_state="following", state="collapsed"),
        collapse_panels=True,
    )
