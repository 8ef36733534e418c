"""The planning problem of one AUV, eqs. (27)-(33), (43)-(49): control set, unscented belief, problem, plan.

Frames and units: inertial x/y in metres, headings in radians counter-clockwise from +x,
speeds in m/s, times in seconds. The target state is xi = [x, y, vx, vy].

Step model (one planning step of length T_o = ``planner.step_s``, "turn then go"): a control
(dtheta, speed) first turns the heading, theta <- theta + dtheta, then moves the vehicle
p <- p + speed * T_o * [cos theta, sin theta]. The target belief moves with F = [[I, T_o I], [0, I]]
(eq. 50); the unscented sigma points (eqs. 32-33) are propagated with F.

The cost these problems are solved for is in :mod:`agent.planner.reference` (plainly, from
the equations) and :mod:`agent.planner.cost` (the fast evaluation the search uses);
docs/planner.md lists where it departs from the paper's eqs. (34)-(38).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from auv_swarm.contract.config import ChannelConfig, ConfigError, PlannerConfig, check_range

N_XI = 4
"""Dimension n of the target state xi (eq. 33)."""

SIGMA_FLOOR = 1e-3
"""Floor of sigma_min(Phi) in the geometry cost (dimensionless): caps it at alpha / SIGMA_FLOOR."""

LAMBDA_FLOOR = 1e-3
"""Floor of lambda_2(L) in the connectivity cost: a disconnected graph costs gamma / LAMBDA_FLOOR."""

MIN_BEARING_RANGE_M = 1e-3
"""Below this range (m) an agent is on the sigma point and its bearing is undefined."""

LEG_TOL_M = 1e-9
"""A dip of the first leg towards a neighbour or the target smaller than this (m) is rounding, not a violation."""
ARC_CHORDS = 32
"""``planner.leg_constraint = "arc"`` flies the first leg's turn as this many chords, equal in turn angle: at
most pi / 32 rad each, so a chord is within R delta^2 / 8 (R = u / r_max the turn radius; 2.4 cm for a
pi turn at 1 m/s and 0.05 rad/s) of the arc."""
HALF_TURN_TOL_RAD = 1e-6
"""A first step's turn within this much of +-pi (rad) is a half turn, flown to the right (-pi, the [-pi, pi) of
``guidance.wrap_pi``) by the flown leg of ``planner.leg_constraint``: dtheta = +pi and -pi reach the same
heading, and the turn read back from the planned end (atan2) would take its side from the rounding of that end.
The turns of the heading grid of eq. (48) are at least 2 pi / 255 rad apart, so only a half turn is this close."""


TERMS = ("geometry", "distance", "connectivity", "penalty", "terminal")
"""The terms of eq. (38) as :attr:`Plan.terms` names them (beside ``safety_violation_m``), in summation order."""


# ----------------------------------------------------------------------------- control set


def base_speed(range_hat_m: float, d_star_m: float, target_speed_mps: float, step_s: float, u_max: float) -> float:
    """Base speed u_e of eq. (47), m/s: |d* - d_hat| / T_o + |v_hat|, clipped to [0, u_max]."""
    _finite_at_least("range_hat_m", range_hat_m, 0.0, "m")
    _finite_positive("d_star_m", d_star_m, "m")
    _finite_at_least("target_speed_mps", target_speed_mps, 0.0, "m/s")
    _finite_positive("step_s", step_s, "s")
    _finite_positive("u_max", u_max, "m/s")
    return float(min(max(abs(d_star_m - range_hat_m) / step_s + target_speed_mps, 0.0), u_max))


@dataclass(frozen=True, eq=False)
class ControlSet:
    """Control set U = U_theta x U_u of eqs. (46)-(49).

    ``dtheta`` (rad) is the uniform symmetric grid linspace(-dtheta_max, dtheta_max, n_headings)
    of eq. (48) ([0] for one heading); ``speeds`` (m/s, >= 0) is :func:`speed_set` (eq. 46).
    Control index = i_heading * len(speeds) + i_speed. ``r_max`` (rad/s) is the vehicle's largest turn
    rate (eq. 1), which ``planner.leg_constraint = "arc"`` uses for the executed first leg; infinite
    (the default) is the step model's instantaneous turn.
    """

    dtheta: np.ndarray
    speeds: np.ndarray
    r_max: float = math.inf

    def __post_init__(self) -> None:
        dtheta = np.array(self.dtheta, dtype=float).reshape(-1) if np.ndim(self.dtheta) <= 1 else None
        speeds = np.array(self.speeds, dtype=float).reshape(-1) if np.ndim(self.speeds) <= 1 else None
        if dtheta is None or dtheta.size < 1:
            raise ValueError("dtheta must be a non-empty 1-D array of heading changes (rad)")
        if speeds is None or speeds.size < 1:
            raise ValueError("speeds must be a non-empty 1-D array of speeds (m/s)")
        if not np.all(np.isfinite(dtheta)):
            raise ValueError("dtheta must be finite")
        if not np.all(np.isfinite(speeds)) or np.any(speeds < 0.0):
            raise ValueError(f"speeds must be finite and in [0, inf) m/s, got {speeds.tolist()}")
        n = dtheta.size
        d = float(dtheta[-1])
        grid = np.linspace(-d, d, n) if n > 1 else np.zeros(1)
        if d < 0.0 or np.max(np.abs(dtheta - grid)) > 1e-9 * max(1.0, abs(d)):
            raise ValueError(
                f"dtheta must be the uniform grid linspace(-dtheta_max, dtheta_max, n) of eq. (48), got {dtheta.tolist()}"
            )
        if not (isinstance(self.r_max, (int, float)) and float(self.r_max) > 0.0 and not math.isnan(self.r_max)):
            raise ValueError(f"r_max must be a turn rate > 0 rad/s (inf: instantaneous), got {self.r_max!r}")
        dtheta.flags.writeable = False
        speeds.flags.writeable = False
        object.__setattr__(self, "r_max", float(self.r_max))
        object.__setattr__(self, "dtheta", dtheta)
        object.__setattr__(self, "speeds", speeds)

    @property
    def controls(self) -> np.ndarray:
        """All controls (m, 2) as rows (dtheta rad, speed m/s), index i_heading * len(speeds) + i_speed."""
        return np.column_stack([np.repeat(self.dtheta, self.speeds.size), np.tile(self.speeds, self.dtheta.size)])

    @property
    def size(self) -> int:
        """Number of controls |U|."""
        return int(self.dtheta.size * self.speeds.size)


N_SPEED_SLOTS = 8
"""Speed indices a plan may use on the wire (the payload's 3-bit speed index); :func:`speed_set` uses at most 6."""

LADDER_FRACTIONS = (0.25, 0.5, 1.0)
"""Legs of the ladder speed set as fractions of d* per step T_o (``planner.speed_set = "ladder"``)."""
LADDER_BELOW = 0.75
"""A ladder speed is kept below this fraction of u_max: one nearly as fast as u_max adds little but search time."""


def speed_set(cfg: PlannerConfig, u_e: float, u_max: float) -> tuple[float, ...]:
    """Surge speeds (m/s) of the control set, in speed-index order, for ``planner.speed_set``.

    ``"ladder"`` (default): where a step at u_max is longer than d* (u_max T_o > d*: section 3.1,
    two d* a step), {0, u_e, f d* / T_o for f in :data:`LADDER_FRACTIONS` where below
    :data:`LADDER_BELOW` u_max, u_max}: steps a quarter, half and whole d* long between the paper's
    u_e (about |v_hat| at d*) and u_max, so a team at d* can still move round the circle to the
    geometry optimum of Fig. 3 (docs/planner.md); elsewhere (sections 3.2, 3.3: half a d* a step)
    the paper's set. The ladder depends only on the configuration, so sender and receiver build
    the same indices. ``"paper"``: {0, u_e, u_max} of eq. (46).
    ``"dstar"``: {0, u_e, u_d, u_max} with u_d = min(u_max, d* / T_o).
    """
    if cfg.speed_set == "ladder" and u_max * cfg.step_s > cfg.d_star_m:
        ladder = tuple(f * cfg.d_star_m / cfg.step_s for f in LADDER_FRACTIONS)
        return (0.0, float(u_e), *(v for v in ladder if v < LADDER_BELOW * u_max), float(u_max))
    if cfg.speed_set == "dstar":
        u_d = min(float(u_max), cfg.d_star_m / cfg.step_s)
        return (0.0, float(u_e), u_d, float(u_max))
    return (0.0, float(u_e), float(u_max))


def control_set(cfg: PlannerConfig, u_e: float, u_max: float, r_max: float) -> ControlSet:
    """Control set of eqs. (46)-(49): headings linspace(-dtheta_max, dtheta_max, n_headings), speeds :func:`speed_set`.

    ``u_e`` and ``u_max`` in m/s, ``r_max`` in rad/s. A heading change must be reachable within one
    step at the maximum turn rate: dtheta_max <= r_max * T_o.
    """
    check_planner_config(cfg)
    _finite_positive("u_max", u_max, "m/s")
    _finite_positive("r_max", r_max, "rad/s")
    if not (math.isfinite(u_e) and 0.0 <= u_e <= u_max):
        raise ValueError(f"u_e must be in [0, u_max = {u_max:g}] m/s, got {u_e!r}")
    reach = r_max * cfg.step_s
    if cfg.dtheta_max_rad > reach:
        raise ConfigError(
            f"planner.dtheta_max_rad must be in [0, r_max * step_s = {reach:g}] rad, got {cfg.dtheta_max_rad!r}"
        )
    n = cfg.n_headings
    dtheta = np.linspace(-cfg.dtheta_max_rad, cfg.dtheta_max_rad, n) if n > 1 else np.zeros(1)
    return ControlSet(dtheta=dtheta, speeds=np.array(speed_set(cfg, u_e, u_max)), r_max=float(r_max))


def check_planner_config(cfg: PlannerConfig) -> None:
    """Raise ConfigError naming ``planner.<field>`` and its range if a field of ``cfg`` is out of range."""
    if not isinstance(cfg, PlannerConfig):
        raise ValueError(f"planner must be a PlannerConfig, got {type(cfg).__name__}")
    for f in dataclasses.fields(PlannerConfig):
        meta = dict(f.metadata)
        value = getattr(cfg, f.name)
        if meta.get("choices"):
            if value not in meta["choices"]:
                allowed = ", ".join(repr(c) for c in meta["choices"])
                raise ConfigError(f"planner.{f.name} must be one of {allowed}, got {value!r}")
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"planner.{f.name} must be a number, got {value!r}")
        check_range(f"planner.{f.name}", float(value), meta)
    for name in ("horizon", "n_headings", "central_orders", "dpso_particles", "dpso_iterations"):
        if isinstance(getattr(cfg, name), float):
            raise ConfigError(f"planner.{name} must be an integer")
    if cfg.d_max_m <= cfg.d_star_m:
        raise ConfigError(f"planner.d_max_m must be > planner.d_star_m = {cfg.d_star_m:g}, got {cfg.d_max_m:g}")


# ----------------------------------------------------------------------------- the first leg's rule


@dataclass(frozen=True)
class LegRule:
    """Where eq. (50)'s d_S and d* are checked beside the ends of the steps (``planner.leg_constraint``).

    - ``on_leg``: also along the first step's leg, the one executed before the next plan (all but "ends");
    - ``flown``: that leg as the vehicle flies it, a turn at r_max then straight, instead of the straight one
      ("arc");
    - ``turn_margin``: the limits on the straight leg grow by the turn's margin u dtheta^2 / (2 r_max), how far
      the flown leg can stray from it ("first", "first-arc");
    - ``flown_safety``: d_S also on the flown leg, besides the grown limit on the straight one ("first-arc").

    The flown leg and the margin need a finite r_max: with an infinite one (the step model's instant turn) the
    straight leg is the flown one, and those three are False.
    """

    on_leg: bool
    flown: bool
    turn_margin: bool
    flown_safety: bool


_LEG_RULES = {  # leg_constraint: (on_leg, flown, turn_margin, flown_safety), the last three with a finite r_max
    "first-arc": (True, False, True, True),
    "first": (True, False, True, False),
    "straight": (True, False, False, False),
    "arc": (True, True, False, False),
    "ends": (False, False, False, False),
}


def leg_rule(cfg: PlannerConfig, r_max: float) -> LegRule:
    """The :class:`LegRule` of ``cfg.leg_constraint`` for a vehicle turning at most ``r_max`` (rad/s)."""
    on_leg, flown, margin, flown_safety = _LEG_RULES[cfg.leg_constraint]
    finite = math.isfinite(r_max)
    return LegRule(on_leg, flown and finite, margin and finite, flown_safety and finite)


# ----------------------------------------------------------------------------- unscented transform


def sigma_points(xi: np.ndarray, P: np.ndarray, w0: float) -> tuple[np.ndarray, np.ndarray]:
    """Sigma points (2n+1, n) and weights (2n+1,) of eqs. (32)-(33) for the belief (xi, P), n = 4.

    xi_0 = xi, xi_+-j = xi +- sqrt(n / (1 - w0)) k_j with k_j the j-th column of the lower
    Cholesky factor K of P (P = K K^T; the paper's "K = P P^T" is a typo). Weights: w0 and
    (1 - w0) / (2n). P is symmetrised; if it is not positive definite, its negative eigenvalues
    are clipped to 0 and a relative jitter of 1e-12 is added before the factorisation.
    """
    x = np.asarray(xi, dtype=float)
    cov = np.asarray(P, dtype=float)
    if x.shape != (N_XI,) or not np.all(np.isfinite(x)):
        raise ValueError(f"xi must be a finite array of shape ({N_XI},), got shape {x.shape}")
    if cov.shape != (N_XI, N_XI) or not np.all(np.isfinite(cov)):
        raise ValueError(f"P must be a finite array of shape ({N_XI}, {N_XI}), got shape {cov.shape}")
    if not (math.isfinite(w0) and w0 < 1.0):
        raise ValueError(f"w0 must be in (-inf, 1), got {w0!r}")
    k = _robust_cholesky(cov)
    scale = math.sqrt(N_XI / (1.0 - w0))
    points = np.empty((2 * N_XI + 1, N_XI))
    points[0] = x
    points[1 : N_XI + 1] = x + scale * k.T
    points[N_XI + 1 :] = x - scale * k.T
    weights = np.full(2 * N_XI + 1, (1.0 - w0) / (2 * N_XI))
    weights[0] = w0
    return points, weights


def _robust_cholesky(cov: np.ndarray) -> np.ndarray:
    sym = 0.5 * (cov + cov.T)
    try:
        return np.linalg.cholesky(sym)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(sym)
        psd = (vecs * np.maximum(vals, 0.0)) @ vecs.T
        jitter = 1e-12 * max(float(np.trace(psd)) / N_XI, 1e-12)
        return np.linalg.cholesky(0.5 * (psd + psd.T) + jitter * np.eye(N_XI))


# ----------------------------------------------------------------------------- problem and result


@dataclass(frozen=True, eq=False)
class Neighbour:
    """Another agent as seen by the planner: position (m), heading (rad) and its (H, 2) (dtheta, speed) sequence."""

    id: int
    position: tuple[float, float]
    heading: float
    sequence: np.ndarray

    def __post_init__(self) -> None:
        pos = tuple(float(v) for v in np.asarray(self.position, dtype=float).reshape(-1))
        if len(pos) != 2 or not all(math.isfinite(v) for v in pos):
            raise ValueError(f"neighbour {self.id}: position must be two finite numbers (m), got {self.position!r}")
        if not math.isfinite(self.heading):
            raise ValueError(f"neighbour {self.id}: heading must be finite (rad), got {self.heading!r}")
        seq = np.array(self.sequence, dtype=float)
        if seq.ndim != 2 or seq.shape[1] != 2 or seq.shape[0] < 1 or not np.all(np.isfinite(seq)):
            raise ValueError(f"neighbour {self.id}: sequence must be a finite (H, 2) array of (dtheta, speed)")
        seq.flags.writeable = False
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "heading", float(self.heading))
        object.__setattr__(self, "sequence", seq)

    def trajectory(self, step_s: float) -> np.ndarray:
        """Predicted positions (H, 2) in m after each step, with the planner's turn-then-go step model."""
        x, y = self.position
        heading = self.heading
        out = np.empty((self.sequence.shape[0], 2))
        for h, (dtheta, speed) in enumerate(self.sequence):
            heading = heading + float(dtheta)
            x = x + float(speed) * step_s * math.cos(heading)
            y = y + float(speed) * step_s * math.sin(heading)
            out[h] = (x, y)
        return out


@dataclass(frozen=True, eq=False)
class PlanProblem:
    """One agent's planning problem at a planning instant (eq. 43)."""

    position: np.ndarray
    heading: float
    xi: np.ndarray
    P: np.ndarray
    neighbours: tuple[Neighbour, ...]
    controls: ControlSet
    planner: PlannerConfig
    channel: ChannelConfig
    anchor_m: tuple[float, ...] | None = None
    """Reference pair distance (m) to each neighbour, in ``neighbours`` order, for the formation readings of
    eq. (37); None: the distances at the plan start."""
    link: object | None = None
    """A physical ocean's ``contract.modem.LinkModel``: its SNR, DT and rho_M replace eqs. (22)-(24) in the
    connectivity graph of eqs. (25)-(26); None: the paper's link budget from ``channel``."""

    def __post_init__(self) -> None:
        check_planner_config(self.planner)
        if self.anchor_m is not None:
            anchor = tuple(float(v) for v in self.anchor_m)
            if len(anchor) != len(tuple(self.neighbours)) or not all(math.isfinite(v) and v >= 0 for v in anchor):
                raise ValueError("anchor_m must hold one finite distance >= 0 (m) per neighbour")
            object.__setattr__(self, "anchor_m", anchor)
        if not isinstance(self.channel, ChannelConfig):
            raise ValueError(f"channel must be a ChannelConfig, got {type(self.channel).__name__}")
        if not isinstance(self.controls, ControlSet):
            raise ValueError(f"controls must be a ControlSet, got {type(self.controls).__name__}")
        pos = np.array(self.position, dtype=float).reshape(-1)
        if pos.shape != (2,) or not np.all(np.isfinite(pos)):
            raise ValueError(f"position must be two finite numbers (m), got {self.position!r}")
        if not math.isfinite(self.heading):
            raise ValueError(f"heading must be finite (rad), got {self.heading!r}")
        xi = np.array(self.xi, dtype=float)
        cov = np.array(self.P, dtype=float)
        if xi.shape != (N_XI,) or not np.all(np.isfinite(xi)):
            raise ValueError(f"xi must be a finite array of shape ({N_XI},)")
        if cov.shape != (N_XI, N_XI) or not np.all(np.isfinite(cov)):
            raise ValueError(f"P must be a finite array of shape ({N_XI}, {N_XI})")
        nbs = tuple(self.neighbours)
        ids = [nb.id for nb in nbs]
        if len(set(ids)) != len(ids):
            raise ValueError(f"neighbours must have distinct ids, got {ids}")
        for nb in nbs:
            if not isinstance(nb, Neighbour):
                raise ValueError(f"neighbours must be Neighbour objects, got {type(nb).__name__}")
            if nb.sequence.shape[0] != self.planner.horizon:
                raise ValueError(
                    f"neighbour {nb.id}: sequence must have planner.horizon = {self.planner.horizon} rows, "
                    f"got {nb.sequence.shape[0]}"
                )
        for arr in (pos, xi, cov):
            arr.flags.writeable = False
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "heading", float(self.heading))
        object.__setattr__(self, "xi", xi)
        object.__setattr__(self, "P", cov)
        object.__setattr__(self, "neighbours", nbs)

    @cached_property
    def leg_rule(self) -> LegRule:
        """The first leg's rule (:func:`leg_rule`) of this problem's planner and vehicle."""
        return leg_rule(self.planner, self.controls.r_max)


@dataclass(frozen=True, eq=False)
class Plan:
    """The optimal control sequence and what it costs.

    ``controls`` (H, 2) rows (dtheta rad, speed m/s); ``indices`` (H,) control indices into
    ``ControlSet.controls``; ``cost`` the total of eq. (38) with the terms in ``terms``
    (geometry, distance, connectivity, penalty, terminal); ``feasible`` False when every sequence
    violates the safety distance (then ``terms['safety_violation_m']`` is the violation);
    ``waypoints`` (H, 2) the own predicted positions (m); ``nodes`` the states evaluated.
    """

    controls: np.ndarray
    indices: np.ndarray
    cost: float
    terms: dict[str, float]
    feasible: bool
    waypoints: np.ndarray
    nodes: int


# ----------------------------------------------------------------------------- validation helpers


def _finite_positive(name: str, value: float, unit: str) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be in (0, inf) {unit}, got {value!r}")


def _finite_at_least(name: str, value: float, lo: float, unit: str) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value >= lo):
        raise ValueError(f"{name} must be in [{lo:g}, inf) {unit}, got {value!r}")
