"""Exact DMPC planner of one AUV, eqs. (27)-(50): control set, unscented belief, cost, exact search.

Frames and units: inertial x/y in metres, headings in radians counter-clockwise from +x,
speeds in m/s, times in seconds. The target state is xi = [x, y, vx, vy].

Step model (one planning step of length T_o = ``planner.step_s``, "turn then go"): a control
(dtheta, speed) first turns the heading, theta <- theta + dtheta, then moves the vehicle
p <- p + speed * T_o * [cos theta, sin theta]. The target belief moves with F = [[I, T_o I], [0, I]]
(eq. 50); the unscented sigma points (eqs. 32-33) are propagated with F.

Cost of a control sequence (eqs. 30, 35-38, 50), summed over the steps h = 1..H and averaged
over the sigma points with the unscented weights:

- geometry ``alpha / sigma_min(Phi)`` (eqs. 34-35), Phi built from the bearings of all agents
  (own and neighbours at step h) to the sigma point; ``sigma_min`` is floored at ``SIGMA_FLOOR``
  and is 0 (so the cost is ``alpha / SIGMA_FLOOR``) when a bearing is undefined (an agent within
  ``MIN_BEARING_RANGE_M`` of the sigma point). A lone agent (no neighbours) has the one singular
  value of its 1 x 2 Phi, which is 1;
- distance ``(1 - alpha) d / d*`` (eq. 36), d the range of this agent to the sigma point;
- connectivity ``gamma / max(lambda_2(L), LAMBDA_FLOOR)`` (eq. 37) with L the SNR-weighted
  normalised Laplacian (eqs. 22-26) of all agents' predicted positions (0 for a lone agent);
- soft range constraints of eq. (50): ``soft_penalty * (max(0, d* - d) / d* + max(0, d - d_M) / d_M)``;
- terminal cost at h = H: ``terminal_weight * |d - d*| / d*`` (eq. 38's last term, normalised by d*).

Hard constraint: the inter-vehicle safety distance ``||p_i,h - p_j,h|| >= d_S`` for every
neighbour j and step h (eq. 50 prints ``d_ij < d_S``, a typo). Speed and turn bounds hold by
construction of the control set. When every sequence violates the safety distance, the plan
minimises the total violation (metres, summed over steps and neighbours), then the cost.

Exact search: see :func:`plan` and the README section "Planner".
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from channel_sim import acoustics
from contract.config import ChannelConfig, ConfigError, PlannerConfig, Scenario, check_range

N_XI = 4
"""Dimension n of the target state xi (eq. 33)."""

SIGMA_FLOOR = 1e-3
"""Floor of sigma_min(Phi) in the geometry cost (dimensionless): caps it at alpha / SIGMA_FLOOR."""

LAMBDA_FLOOR = 1e-3
"""Floor of lambda_2(L) in the connectivity cost: a disconnected graph costs gamma / LAMBDA_FLOOR."""

MIN_BEARING_RANGE_M = 1e-3
"""Below this range (m) an agent is on the sigma point and its bearing is undefined."""

_R2_MIN = MIN_BEARING_RANGE_M**2
_PRUNE_RTOL = 1e-9  # relative margin of every pruning test, far above rounding, so pruning stays exact
_ROLLOUTS = 8  # greedy completions tried when the incumbent (upper bound) is updated
_REFINE_MIN = 400  # live states at level H - 1 from which the incumbent is refined by a second rollout
_BOUND_LEVELS = 2  # the remaining-cost bound is used when expanding the last levels, where the graph is wide
_PACK_LIMIT = 2**62  # merge-graph keys below this pack into one int64; longer tuples are compared as rows


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
    of eq. (48) ([0] for one heading); ``speeds`` (m/s, >= 0) is {0, u_e, u_max} of eq. (46).
    Control index = i_heading * len(speeds) + i_speed.
    """

    dtheta: np.ndarray
    speeds: np.ndarray

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
        dtheta.flags.writeable = False
        speeds.flags.writeable = False
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


def control_set(cfg: PlannerConfig, u_e: float, u_max: float, r_max: float) -> ControlSet:
    """Control set of eqs. (46)-(49): headings linspace(-dtheta_max, dtheta_max, n_headings), speeds {0, u_e, u_max}.

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
    return ControlSet(dtheta=dtheta, speeds=np.array([0.0, float(u_e), float(u_max)]))


def check_planner_config(cfg: PlannerConfig) -> None:
    """Raise ConfigError naming ``planner.<field>`` and its range if a field of ``cfg`` is out of range."""
    if not isinstance(cfg, PlannerConfig):
        raise ValueError(f"planner must be a PlannerConfig, got {type(cfg).__name__}")
    for f in dataclasses.fields(PlannerConfig):
        meta = dict(f.metadata)
        value = getattr(cfg, f.name)
        if meta.get("choices"):
            if value not in meta["choices"]:
                raise ConfigError(
                    f"planner.{f.name} must be one of {', '.join(map(repr, meta['choices']))}, got {value!r}"
                )
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"planner.{f.name} must be a number, got {value!r}")
        check_range(f"planner.{f.name}", float(value), meta)
    for name in ("horizon", "n_headings", "central_orders", "dpso_particles", "dpso_iterations"):
        if isinstance(getattr(cfg, name), float):
            raise ConfigError(f"planner.{name} must be an integer")
    if cfg.d_max_m <= cfg.d_star_m:
        raise ConfigError(f"planner.d_max_m must be > planner.d_star_m = {cfg.d_star_m:g}, got {cfg.d_max_m:g}")


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


def least_singular_value(bearings_rad: np.ndarray) -> np.ndarray | float:
    """Least singular value sigma_min of Phi (eq. 34) for bearings (..., n) in rad, vectorised.

    Phi has unit rows [sin b, -cos b]; sigma_min^2 = 2 sum_{j<k} sin^2(b_j - b_k) / (n + |z|) with
    z = sum_j exp(2 i b_j), the cancellation-free form of (n - |z|) / 2. One bearing gives 1.
    """
    b = np.asarray(bearings_rad, dtype=float)
    if b.ndim < 1 or b.shape[-1] < 1 or not np.all(np.isfinite(b)):
        raise ValueError("bearings_rad must be a finite array with at least one bearing on its last axis")
    n = b.shape[-1]
    if n == 1:
        out = np.ones(b.shape[:-1])
        return float(out) if out.ndim == 0 else out
    num = np.zeros(b.shape[:-1])
    for j in range(n):
        for k in range(j + 1, n):
            num = num + np.sin(b[..., j] - b[..., k]) ** 2
    z = np.abs(np.sum(np.exp(2j * b), axis=-1))
    out = np.sqrt(2.0 * num / (n + z))
    return float(out) if out.ndim == 0 else out


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

    def __post_init__(self) -> None:
        check_planner_config(self.planner)
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


# ----------------------------------------------------------------------------- sequential decision making


def policy_of_intent(previous: np.ndarray, base: tuple[float, float]) -> np.ndarray:
    """Policy of intent of eq. (42): drop the first control of ``previous`` (H, 2), append ``base`` (dtheta, speed)."""
    prev = np.asarray(previous, dtype=float)
    if prev.ndim != 2 or prev.shape[1] != 2 or prev.shape[0] < 1:
        raise ValueError(f"previous must be an (H, 2) array of (dtheta, speed) with H >= 1, got shape {prev.shape}")
    b = np.asarray(base, dtype=float).reshape(-1)
    if b.shape != (2,) or not np.all(np.isfinite(b)):
        raise ValueError(f"base must be a finite (dtheta, speed) pair, got {base!r}")
    return np.vstack([prev[1:], b[None, :]])


def compose_neighbours(
    my_id: int,
    slot_order: tuple[int, ...] | list[int],
    positions: dict[int, tuple[float, float, float]],
    fresh: dict[int, np.ndarray],
    intent: dict[int, np.ndarray],
    base: dict[int, tuple[float, float]],
    H: int,
) -> tuple[Neighbour, ...]:
    """Neighbours for sequential decision making, eq. (43), sorted by id.

    Only agents in ``positions`` ((x, y, theta) in m, m, rad) other than ``my_id`` are included.
    Agents before ``my_id`` in ``slot_order`` use their ``fresh`` plan of this round when known,
    else their policy of intent (``intent``, eq. 42); agents after it (or absent from the slot
    order) use their policy of intent. An agent with no known sequence uses H copies of its
    ``base`` control (dtheta, speed), or holds station (0, 0) when that is unknown too. Sequences
    longer than H are cut to H steps; shorter ones are padded with the base control.
    """
    if isinstance(H, bool) or not isinstance(H, (int, np.integer)) or H < 1:
        raise ValueError(f"H must be an integer in [1, inf), got {H!r}")
    order = list(slot_order)
    my_slot = order.index(my_id) if my_id in order else -1
    out = []
    for j in sorted(positions):
        if j == my_id:
            continue
        x, y, theta = (float(v) for v in positions[j])
        before = my_slot >= 0 and j in order and order.index(j) < my_slot
        b = np.asarray(base.get(j, (0.0, 0.0)), dtype=float).reshape(2)
        seq = None
        if before and j in fresh:
            seq = fresh[j]
        elif j in intent:
            seq = intent[j]
        if seq is None:
            seq_arr = np.tile(b, (H, 1))
        else:
            seq_arr = np.asarray(seq, dtype=float).reshape(-1, 2)[:H]
            if seq_arr.shape[0] < H:
                seq_arr = np.vstack([seq_arr, np.tile(b, (H - seq_arr.shape[0], 1))])
        out.append(Neighbour(id=int(j), position=(x, y), heading=theta, sequence=seq_arr))
    return tuple(out)


# ----------------------------------------------------------------------------- merge graph


@dataclass(frozen=True)
class _Graph:
    """Merged search graph, depends only on the control-set shape and H.

    Level h (0..H) holds states (position node, heading class); at level H states are position
    nodes. A position node is the multiset of non-zero (heading class, speed class) steps taken,
    stored as its sorted step types padded with ``len(type_g)`` (the "no step" type); ``pos_cols``
    holds the same digits column by column (H, nodes) for fast gathers. The states of a position
    node are consecutive (``node_start``, ``node_count``), states being sorted by node. The in-edge
    tables (``in_parent``, ``in_start``, ``in_count``) serve the forward values of levels 1..H-1
    and are empty at level H, where the search needs none.
    """

    child: tuple[np.ndarray, ...]
    state_pos: tuple[np.ndarray, ...]
    pos_digits: tuple[np.ndarray, ...]
    pos_cols: tuple[np.ndarray, ...]
    in_parent: tuple[np.ndarray, ...]
    in_start: tuple[np.ndarray, ...]
    in_count: tuple[np.ndarray, ...]
    node_start: tuple[np.ndarray, ...]
    node_count: tuple[np.ndarray, ...]
    type_g: np.ndarray
    type_speed: np.ndarray


def _compress(keys: np.ndarray, space: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct values and inverse of non-negative int64 keys below ``space`` (a lookup table if it is small)."""
    if space > 32 * keys.size + 4096:
        uniq, inverse = np.unique(keys, return_inverse=True)
        return uniq, inverse.reshape(-1)
    keys = keys.astype(np.intp, copy=False)
    seen = np.zeros(space, dtype=bool)
    seen[keys] = True
    uniq = np.flatnonzero(seen)
    lut = np.empty(space, dtype=np.int64)
    lut[uniq] = np.arange(uniq.size)
    return uniq, lut.take(keys)


def _offsets(counts: np.ndarray) -> np.ndarray:
    """Start offsets (int64) of consecutive blocks of the given sizes."""
    out = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(counts[:-1], out=out[1:])
    return out


def _index_bits(n: int) -> int:
    """Bits that hold the indices 0..n-1."""
    return max(int(n - 1).bit_length(), 1)


def _distinct32(keys: np.ndarray, space: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct values and int32 inverse (shaped like ``keys``) of non-negative int64 keys below ``space``."""
    flat = keys.reshape(-1)
    if space <= 8 * flat.size + 4096:
        seen = np.zeros(space, dtype=bool)
        seen[flat] = True
        uniq = np.flatnonzero(seen)
        lut = np.empty(space, dtype=np.int32)
        np.put(lut, uniq, np.arange(uniq.size, dtype=np.int32))
        return uniq, np.take(lut, keys)
    uniq, inverse = np.unique(flat, return_inverse=True)
    return uniq, inverse.reshape(keys.shape).astype(np.int32)


def _stable_order(keys: np.ndarray, space: int) -> np.ndarray:
    """Stable argsort of 1-D non-negative int keys below ``space`` (one sort of the keys tagged with their indices)."""
    bits = _index_bits(keys.size)
    if space.bit_length() + bits > 62:
        return np.argsort(keys, kind="stable")
    tagged = keys.astype(np.int64)
    tagged <<= bits
    tagged |= np.arange(keys.size, dtype=np.int64)
    tagged.sort()
    tagged &= (1 << bits) - 1
    return tagged


def _turned(par_pos: np.ndarray, gcls: np.ndarray, n_pos: int, n_g: int, wrap: int, shifts: list[int]) -> np.ndarray:
    """(heading class, position) table, True where a state of the position turns to the heading class.

    Without wrap the table is shifted, not clipped: no reachable heading class leaves the range.
    """
    here = np.zeros((n_g, n_pos), dtype=bool)
    here.reshape(-1)[gcls * n_pos + par_pos] = True
    out = np.zeros_like(here)
    for mv in shifts:
        if wrap:
            r = mv % wrap
            out[r:] |= here[: n_g - r]
            out[:r] |= here[n_g - r :]
        else:
            lo, hi = max(mv, 0), n_g + min(mv, 0)
            out[lo:hi] |= here[lo - mv : hi - mv]
    return out


def _inserted(cols: np.ndarray, parent: np.ndarray, t: np.ndarray, filled: int, pad: int) -> np.ndarray:
    """Columns (H, n) of the positions ``parent`` of ``cols`` (``filled`` steps at most) with the type t inserted.

    Digit j of a sorted row with t inserted is max(row[j - 1], min(row[j], t)).
    """
    out = np.empty((cols.shape[0], parent.size), dtype=cols.dtype)
    prev = np.take(cols[0], parent)
    np.minimum(prev, t, out=out[0])
    for j in range(1, filled + 1):
        cur = np.take(cols[j], parent)
        np.maximum(prev, np.minimum(cur, t), out=out[j])
        prev = cur
    out[filled + 1 :] = pad
    return out


def _grow(
    cols: np.ndarray,
    codes: np.ndarray,
    turned: np.ndarray,
    labels: np.ndarray,
    pad: int,
    has_pad: bool,
    filled: int,
    weight: np.ndarray,
    packed: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Child positions of one level: digit columns, packed keys (sorted; unpacked: ``codes``) and lookup.

    ``cols`` (H, positions) holds the parent positions' digits (at most ``filled`` steps, padded
    with the label ``pad`` of "no step"), ``codes`` their packed keys. The pairs are the moving
    types ``labels[s, i]`` of every (heading row i, position) of ``turned`` and, if ``has_pad``,
    "no step" (the child is the parent). The child of position p with speed s and heading row i
    lands at slot ``(s * rows + i) * positions + p`` of the int32 lookup, "no step" at slot
    ``n_s * rows * positions + p`` (other entries are undefined).
    """
    horizon, n_pos = cols.shape
    n_s, n_g = labels.shape
    at_turned = np.flatnonzero(turned)
    per_g = np.count_nonzero(turned, axis=1)
    n_sub = at_turned.size
    n_moving = n_sub * n_s
    n = n_moving + (n_pos if has_pad else 0)
    tt = np.empty(n, dtype=cols.dtype)
    for s in range(n_s):
        tt[s * n_sub : (s + 1) * n_sub] = np.repeat(labels[s], per_g)
    tt[n_moving:] = pad
    if packed:
        pm = at_turned - np.repeat(np.arange(n_g, dtype=np.int64) * n_pos, per_g)
        uniq, rep, lookup = _pair_keys(cols, codes, at_turned, pm, tt, labels, pad, filled, weight)
        row, parent = np.divmod(rep, n_pos)
        return _inserted(cols, parent, np.append(labels, pad).astype(cols.dtype)[row], filled, pad), uniq, lookup
    slots = _pair_slots(at_turned, n_s * n_g * n_pos, n_pos, n_s, has_pad)
    rows = cols.T[slots % n_pos]
    rows[:, filled] = tt
    rows.sort(axis=1)
    rows, inverse = np.unique(rows, axis=0, return_inverse=True)
    lookup = np.empty((n_s * n_g + 1) * n_pos, dtype=np.int32)
    lookup[slots] = inverse.reshape(-1)
    return np.ascontiguousarray(rows.T), codes, lookup


def _pair_slots(at_turned: np.ndarray, pad_slot: int, n_pos: int, n_s: int, has_pad: bool) -> np.ndarray:
    """Lookup slots of the pairs of :func:`_grow`, in pair order (speed blocks, then "no step")."""
    blocks = [at_turned + s * (pad_slot // n_s) for s in range(n_s)]
    if has_pad:
        blocks.append(np.arange(pad_slot, pad_slot + n_pos, dtype=np.int64))
    return np.concatenate(blocks)


def _pair_keys(
    cols: np.ndarray,
    codes: np.ndarray,
    at_turned: np.ndarray,
    pm: np.ndarray,
    tt: np.ndarray,
    labels: np.ndarray,
    pad: int,
    filled: int,
    weight: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted distinct packed keys of the pairs of :func:`_grow`, the lookup slot of one pair of each, the lookup.

    A pair's key is that of its parent with the type inserted at its rank among the parent's steps;
    the keys are sorted once, tagged with their slots.
    """
    horizon, n_pos = cols.shape
    n_s, n_g = labels.shape
    n_sub = pm.size
    n_moving = n_sub * n_s
    n = tt.size
    pad_slot = n_s * n_g * n_pos
    # rank (s, i, p): steps of position p below type labels[s, i]; keyed (p, k): key of p with digit k left free
    rank = np.zeros((n_s, n_g, n_pos), dtype=np.uint8 if horizon < 256 else np.int64)
    below = labels.astype(cols.dtype)[:, :, None]
    for j in range(filled):
        rank += cols[j] < below
    keyed = np.zeros((horizon, n_pos), dtype=np.int64)
    for j in range(horizon - 1):
        keyed[j + 1 :] += cols[j] * weight[j]
        keyed[: j + 1] += cols[j] * weight[j + 1]
    keyed = np.ascontiguousarray(keyed.T)
    tagged = np.empty(n, dtype=np.int64)
    flat_rank = rank.reshape(-1)
    at_row = pm * horizon
    for s in range(n_s):
        blk = slice(s * n_sub, (s + 1) * n_sub)
        k = np.take(flat_rank[s * n_g * n_pos :], at_turned)
        tagged[blk] = np.take(keyed, at_row + k)
        k = np.take(weight, k)
        k *= tt[blk]
        tagged[blk] += k
    tagged[n_moving:] = codes[: n - n_moving]
    lookup = np.empty(pad_slot + n_pos, dtype=np.int32)
    bits = _index_bits(lookup.size)
    if (int(weight[0]) * (pad + 1)).bit_length() + bits > 62:
        slots = _pair_slots(at_turned, pad_slot, n_pos, n_s, n > n_moving)
        uniq, rep, inverse = np.unique(tagged, return_index=True, return_inverse=True)
        lookup[slots] = inverse.reshape(-1)
        return uniq, slots[rep], lookup
    tagged <<= bits
    for s in range(n_s):
        blk = tagged[s * n_sub : (s + 1) * n_sub]
        blk += at_turned
        blk += s * n_g * n_pos
    tagged[n_moving:] += np.arange(pad_slot, pad_slot + n - n_moving, dtype=np.int64)
    tagged.sort(kind="stable")  # merges the sorted runs of the (speed, heading row) blocks
    low = tagged & ((1 << bits) - 1)
    tagged >>= bits
    first = np.empty(n, dtype=bool)
    first[:1] = True
    np.not_equal(tagged[1:], tagged[:-1], out=first[1:])
    at_first = np.flatnonzero(first)
    uniq = np.take(tagged, at_first)
    np.cumsum(first, out=tagged)
    tagged -= 1
    np.put(lookup, low, tagged)
    return uniq, np.take(low, at_first), lookup


def _children(lookup: np.ndarray, slots: np.ndarray, gcls: np.ndarray, par_pos: np.ndarray) -> np.ndarray:
    """Child table (states, controls) int32: ``lookup[slots[gcls] + par_pos]``, in blocks of states that stay in cache."""
    out = np.empty((gcls.size, slots.shape[1]), dtype=np.int32)
    step = max(65536 // slots.shape[1], 1)
    for a in range(0, gcls.size, step):
        at = slots[gcls[a : a + step]]
        at += par_pos[a : a + step, None]
        out[a : a + step] = np.take(lookup, at)
    return out


@lru_cache(maxsize=8)
def _graph(m: tuple[int, ...], wrap: int, speed_class: tuple[int, ...], horizon: int) -> _Graph:
    """Build the merge graph for heading offsets m (grid units), wrap modulus (0: none), speed classes, H.

    A position node is keyed by the sorted tuple of its non-zero step types (heading class, speed
    class), padded to H entries; a state by that tuple and its heading class. Step types are
    labelled in order among the types some level can take, "no step" last. Exact integer keys,
    level by level: a child position depends only on (parent position, new step type), so each
    distinct such pair (the parent's heading classes turned by every distinct offset, times the
    speed classes, plus "no step") is keyed once, its sorted tuple packed into one int64 (mixed
    radix, integer order = lexicographic order; tuples too long to pack are compared as rows); a
    (position, type) lookup table then gives every state's child positions. Memoised per process,
    so all agents of a process share the graph of a control-set shape.
    """
    n_speed = len(speed_class)
    n_u = len(m) * n_speed
    moving_ids = sorted({c for c in speed_class if c >= 0})
    n_s = max(len(moving_ids), 1)
    dm = np.repeat(np.asarray(m, dtype=np.int64), n_speed)
    si = np.tile(np.array([moving_ids.index(c) if c >= 0 else -1 for c in speed_class], dtype=np.int64), len(m))
    g_off = 0 if wrap else horizon * max(abs(v) for v in m)
    n_g = wrap if wrap else 2 * g_off + 1
    g_next = np.arange(n_g, dtype=np.int64)[:, None] + dm[None, :]
    if wrap:
        g_next %= wrap
    else:
        g_next = np.clip(g_next, 0, n_g - 1)  # shifted by g_off; |g| <= h max|m| <= g_off at every reachable level
    reach = np.zeros(n_g, dtype=bool)
    reach[g_off] = True
    g_used = np.zeros(n_g, dtype=bool)
    for _ in range(horizon):
        turn = np.zeros(n_g, dtype=bool)
        turn[g_next[reach]] = True
        reach = turn
        g_used |= reach
    headings = np.flatnonzero(g_used)
    n_h = headings.size
    compact = np.zeros(n_g, dtype=np.int64)
    compact[headings] = np.arange(n_h)
    moved = headings if moving_ids else headings[:0]
    types = (moved[:, None] * n_s + np.arange(n_s)).reshape(-1)
    pad = types.size
    base = pad + 1
    labels = np.arange(moved.size, dtype=np.int32)[None, :] * n_s + np.arange(n_s, dtype=np.int32)[:, None]
    packed = base**horizon < _PACK_LIMIT
    weight = np.array([base ** (horizon - 1 - j) if packed else 0 for j in range(horizon)], dtype=np.int64)
    cols = np.full((horizon, 1), pad, dtype=np.int32)
    codes = np.array([pad * int(np.sum(weight))], dtype=np.int64)
    gcls = np.full(1, g_off, dtype=np.int64)
    par_pos = np.zeros(1, dtype=np.int64)
    child_l: list[np.ndarray] = [np.zeros((0, n_u), np.int32)]
    state_pos_l: list[np.ndarray] = [np.zeros(1, np.int32)]
    cols_l: list[np.ndarray] = [cols]
    in_parent_l: list[np.ndarray] = [np.zeros(0, np.int32)]
    in_start_l: list[np.ndarray] = [np.zeros(0, np.int64)]
    in_count_l: list[np.ndarray] = [np.zeros(0, np.int64)]
    node_start_l: list[np.ndarray] = [np.zeros(1, np.int64)]
    node_count_l: list[np.ndarray] = [np.ones(1, np.int64)]
    type_slot = np.where(si >= 0, si * moved.size + compact[g_next], n_s * moved.size)
    h_next = compact[g_next]
    shifts = sorted(set(m)) if moving_ids else []
    for h in range(1, horizon + 1):
        n_prev = cols.shape[1]
        turned = _turned(par_pos, gcls, n_prev, n_g, wrap, shifts)[moved]
        cols, codes, lookup = _grow(cols, codes, turned, labels, pad, bool(np.any(si < 0)), h - 1, weight, packed)
        cols_l.append(cols)
        n_pos = cols.shape[1]
        child_pos = _children(lookup, type_slot * n_prev, gcls, par_pos)
        del lookup
        if h == horizon:
            child_l.append(child_pos)
            state_pos = np.arange(n_pos, dtype=np.int64)
            per_node = np.ones(n_pos, dtype=np.int64)
            in_parent_l.append(np.zeros(0, np.int32))
            in_start_l.append(np.zeros(0, np.int64))
            in_count_l.append(np.zeros(0, np.int64))
        else:
            keys = child_pos.astype(np.int64)
            keys *= n_h
            keys += h_next[gcls]
            states, child = _distinct32(keys, n_pos * n_h)
            del keys
            state_pos, gcls = np.divmod(states, n_h)
            gcls = headings[gcls]
            par_pos = state_pos
            counts = np.bincount(child.reshape(-1), minlength=states.size).astype(np.int64)
            per_node = np.bincount(state_pos, minlength=n_pos).astype(np.int64)
            child_l.append(child)
            order = _stable_order(child.reshape(-1), states.size)
            order //= n_u
            in_parent_l.append(order.astype(np.int32))
            in_start_l.append(_offsets(counts))
            in_count_l.append(counts)
        state_pos_l.append(state_pos.astype(np.int32))
        node_start_l.append(_offsets(per_node))
        node_count_l.append(per_node)
    return _Graph(
        child=tuple(child_l),
        state_pos=tuple(state_pos_l),
        pos_digits=tuple(np.ascontiguousarray(c.T) for c in cols_l),
        pos_cols=tuple(cols_l),
        in_parent=tuple(in_parent_l),
        in_start=tuple(in_start_l),
        in_count=tuple(in_count_l),
        node_start=tuple(node_start_l),
        node_count=tuple(node_count_l),
        type_g=types // n_s - g_off,
        type_speed=np.array(moving_ids, dtype=np.int64)[types % n_s] if moving_ids else np.zeros(0, np.int64),
    )


# ----------------------------------------------------------------------------- per-problem context


class _Context:
    """Everything of one problem that does not depend on the own control sequence."""

    def __init__(self, problem: PlanProblem) -> None:
        cfg = problem.planner
        self.cfg = cfg
        self.ch = problem.channel
        self.H = int(cfg.horizon)
        self.T = float(cfg.step_s)
        self.p0 = (float(problem.position[0]), float(problem.position[1]))
        self.theta0 = float(problem.heading)
        cs = problem.controls
        self.dtheta = cs.dtheta
        self.speeds = cs.speeds
        self.n_speed = cs.speeds.size
        self.n_u = cs.size
        # heading lattice: dtheta[a] = m[a] * unit (eq. 48), headings theta0 + g * unit
        n_h = cs.dtheta.size
        d = float(cs.dtheta[-1])
        if n_h == 1 or d == 0.0:
            self.m = tuple(0 for _ in range(n_h))
            self.unit = 0.0
            self.wrap = 1
        else:
            self.m = tuple(2 * a - (n_h - 1) for a in range(n_h))
            self.unit = d / (n_h - 1)
            turns = 2.0 * math.pi / self.unit
            self.wrap = int(round(turns)) if abs(turns - round(turns)) <= 1e-9 * turns else 0
        first: dict[float, int] = {}
        classes = []
        for s, v in enumerate(cs.speeds.tolist()):
            classes.append(-1 if v == 0.0 else first.setdefault(v, s))
        self.speed_class = tuple(classes)
        # target belief: sigma points propagated with F (eq. 50) to every level h = 0..H
        pts, w = sigma_points(problem.xi, problem.P, cfg.w0)
        self.w = w
        self.L = w.size
        hs = np.arange(self.H + 1)[:, None] * self.T
        self.tx = pts[None, :, 0] + hs * pts[None, :, 2]
        self.ty = pts[None, :, 1] + hs * pts[None, :, 3]
        self.tx0 = self.tx[:, 0].copy()
        self.ty0 = self.ty[:, 0].copy()
        self.w_rest = float(np.sum(w[1:]))
        # neighbours' predicted positions (H+1, k) (level 0 = now) and their bearings to the sigma points
        nbs = problem.neighbours
        self.k = len(nbs)
        self.n_agents = self.k + 1
        nb_pos = np.zeros((self.H + 1, self.k, 2))
        for j, nb in enumerate(nbs):
            nb_pos[0, j] = nb.position
            nb_pos[1:, j] = nb.trajectory(self.T)
        self.nbx = nb_pos[:, :, 0]
        self.nby = nb_pos[:, :, 1]
        vx = self.tx[:, :, None] - self.nbx[:, None, :]
        vy = self.ty[:, :, None] - self.nby[:, None, :]
        r2 = vx * vx + vy * vy
        self.nb_undefined = np.any(r2 < _R2_MIN, axis=2)
        r = np.sqrt(np.where(r2 < _R2_MIN, 1.0, r2))
        ex, ey = vx / r, vy / r
        self.nb_ex_j = [np.ascontiguousarray(ex[:, :, j]) for j in range(self.k)]
        self.nb_ey_j = [np.ascontiguousarray(ey[:, :, j]) for j in range(self.k)]
        self.zr = np.sum(ex * ex - ey * ey, axis=2)
        self.zi = np.sum(2.0 * ex * ey, axis=2)
        pair = np.zeros(self.zr.shape)
        for j in range(self.k):
            for i in range(j + 1, self.k):
                c = ex[:, :, j] * ey[:, :, i] - ey[:, :, j] * ex[:, :, i]
                pair = pair + c * c
        self.pair = pair
        # link model of eqs. (22)-(26) and the neighbour-neighbour link weights (H+1, k, k)
        ch = self.ch
        self.snr_at_1m = ch.source_level_db - ch.noise_level_db + ch.directivity_index_db
        self.absorption_db_per_m = _absorption_db_per_m(ch.frequency_khz)
        rho_m = acoustics.snr_max_db(ch)
        self.inv_snr_max = 1.0 / rho_m if rho_m > 0.0 else 1.0
        dxx = self.nbx[:, :, None] - self.nbx[:, None, :]
        dyy = self.nby[:, :, None] - self.nby[:, None, :]
        self.nb_w = _link_weight(self, np.sqrt(dxx * dxx + dyy * dyy))
        idx = np.arange(self.k)
        self.nb_w[:, idx, idx] = 0.0
        # upper bound of sigma_min per (level, sigma point), for the lower bounds of the pruning
        zabs = np.sqrt(self.zr * self.zr + self.zi * self.zi)
        if self.n_agents == 1:
            sig_up = np.ones(self.zr.shape)
        else:
            sig_up = np.sqrt(np.maximum(self.n_agents - np.abs(zabs - 1.0), 0.0) / 2.0 + 1e-9)
            sig_up = np.where(self.nb_undefined, 0.0, sig_up)
        self.geom_lb_w = (cfg.alpha / np.maximum(sig_up, SIGMA_FLOOR)) @ w
        self.can_prune = bool(np.all(w >= 0.0))
        self.r_step = self.T * float(np.max(self.speeds))
        self.c_dist = (1.0 - cfg.alpha) / cfg.d_star_m
        self.c_term = cfg.terminal_weight / cfg.d_star_m
        self.inv_ds = 1.0 / cfg.d_star_m
        self.inv_dm = 1.0 / cfg.d_max_m
        self._steps: dict[tuple[int, int], tuple[float, float]] = {}
        self.steps = np.zeros(1, dtype=complex)
        # per-level columns (M, 1) of the (M, N) stage-cost layout, indexed by an int level h
        self.tx_c = self.tx[:, :, None]
        self.ty_c = self.ty[:, :, None]
        self.nbx_c = self.nbx[:, :, None]
        self.nby_c = self.nby[:, :, None]
        self._geo_c: dict[int, tuple[np.ndarray, ...]] = {}

    def geometry_columns(self, h: int) -> tuple[np.ndarray, ...]:
        """Columns at level h: undefined-bearing mask, neighbours' pair sum and share of z, then ey_j and ex_j per neighbour."""
        cols = self._geo_c.get(h)
        if cols is None:
            cols = self._geo_c[h] = (
                self.nb_undefined[h][:, None],
                self.pair[h][:, None],
                self.zr[h][:, None],
                self.zi[h][:, None],
                *(a[h][:, None] for a in self.nb_ey_j),
                *(a[h][:, None] for a in self.nb_ex_j),
            )
        return cols

    def step_vector(self, g: int, sc: int) -> tuple[float, float]:
        """Displacement (m) of one step at heading class g with speed class sc (sc < 0: no motion)."""
        if sc < 0:
            return (0.0, 0.0)
        key = (g, sc)
        vec = self._steps.get(key)
        if vec is None:
            heading = self.theta0 + g * self.unit
            dist = self.T * float(self.speeds[sc])
            vec = self._steps[key] = (dist * math.cos(heading), dist * math.sin(heading))
        return vec

    def advance(self, g: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Heading class after turning by dtheta[a] from heading class g."""
        g2 = g + np.asarray(self.m, dtype=np.int64)[a]
        return g2 % self.wrap if self.wrap else g2


@lru_cache(maxsize=64)
def _absorption_db_per_m(f_khz: float) -> float:
    """Thorp absorption (eq. 24) in dB/m at f_khz kHz."""
    return float(acoustics.thorp_absorption_db_per_km(f_khz)) * 1e-3


def _link_weight(ctx: _Context, range_m: np.ndarray) -> np.ndarray:
    """Normalised link weight rho / rho_M of eqs. (22)-(26) for ranges in m; 0 below DT or at rho <= 0 dB.

    Same link model as ``channel_sim.acoustics.snr_laplacian`` (range clamped to ``MIN_RANGE_M`` in
    eq. 23), evaluated without per-call validation because the planner calls it on large batches.
    """
    d = np.maximum(range_m, acoustics.MIN_RANGE_M)
    loss = np.log10(d)
    loss *= 20.0
    d *= ctx.absorption_db_per_m
    loss += d
    rho = np.subtract(ctx.snr_at_1m, loss, out=loss)
    dt = ctx.ch.detection_threshold_db
    off = rho < dt if dt > 0.0 else rho <= 0.0
    rho *= ctx.inv_snr_max
    rho[off] = 0.0
    return rho


def _fiedler(own_w: np.ndarray, nb_w: np.ndarray) -> np.ndarray:
    """lambda_2 of the Laplacian (eq. 26) of the own node and k neighbours; own_w (N, k), nb_w (1 or N, k, k).

    k = 1: 2 w; k = 2: the closed form 3Q / (S + sqrt(S^2 - 3Q)) of ``acoustics.fiedler_value_3``
    (S the sum of the weights, Q the sum of their pairwise products, exactly 0 when disconnected);
    larger teams: eigvalsh.
    """
    n_pts, k = own_w.shape
    if k == 1:
        return 2.0 * own_w[:, 0]
    if k == 2:
        a, b, c = own_w[:, 0], own_w[:, 1], nb_w[:, 0, 1]
        ab = a + b
        q = a * b + ab * c
        q *= 3.0
        d1 = a - b
        d1 *= d1
        d2 = a - c
        d2 *= d2
        d1 += d2
        d2 = np.subtract(b, c, out=d2)
        d2 *= d2
        d1 += d2
        d1 *= 0.5
        den = np.sqrt(d1, out=d1)
        den += ab + c
        return np.divide(q, den, out=np.zeros(q.shape), where=den > 0.0)
    own_w = np.ascontiguousarray(own_w)
    lap = np.zeros((n_pts, k + 1, k + 1))
    lap[:, 0, 1:] = -own_w
    lap[:, 1:, 0] = -own_w
    lap[:, 0, 0] = own_w.sum(axis=1)
    lap[:, 1:, 1:] = -nb_w
    idx = np.arange(1, k + 1)
    lap[:, idx, idx] = nb_w.sum(axis=2) + own_w
    return np.maximum(np.linalg.eigvalsh(lap)[:, 1], 0.0)


# ----------------------------------------------------------------------------- stage cost


def _at(arr: np.ndarray, h: int | np.ndarray) -> np.ndarray:
    """Rows of a per-level array: level h broadcast over the batch (h an int) or one level per point."""
    return arr[h][None] if isinstance(h, (int, np.integer)) else arr[h]


def _col(arr: np.ndarray, h: int | np.ndarray) -> np.ndarray:
    """Values of a per-level (H+1, M) array (M sigma points or neighbours) in the (M, N) layout of the stage cost.

    Level h as one column broadcast over the batch (h an int), or one level per point.
    """
    return arr[h][:, None] if isinstance(h, (int, np.integer)) else arr[h].T


def _sigma_sum(v: np.ndarray) -> np.ndarray:
    """Sum over the sigma points (axis 0) of an (L, N) array, in numpy's pairwise order of a row sum.

    For L = 2n + 1 = 9 this is (((v0 + v1) + (v2 + v3)) + ((v4 + v5) + (v6 + v7))) + v8, the
    order in which ``(N, L).sum(axis=1)`` adds each row, so the result does not depend on the layout.
    """
    if v.shape[0] != 9:
        return np.ascontiguousarray(v.T).sum(axis=1)
    a = v[0] + v[1]
    a += v[2] + v[3]
    b = v[4] + v[5]
    b += v[6] + v[7]
    a += b
    a += v[8]
    return a


def _wsum(ctx: _Context, per_sigma: np.ndarray) -> np.ndarray:
    """UT-weighted sum over the sigma points (eq. 30) of an (L, N) array, (N,); one fixed order per point."""
    return _sigma_sum(per_sigma * ctx.w[:, None])


def _is_last(ctx: _Context, h: int | np.ndarray) -> bool | np.ndarray:
    """Whether step h is the terminal step H: a bool for an int h, a (1, N) mask for per-point levels."""
    return bool(h == ctx.H) if isinstance(h, (int, np.integer)) else (h == ctx.H)[None, :]


def _target_ranges(ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Own range (L, N) in m to every sigma point at step h."""
    dx = px[None, :] - _col(ctx.tx, h)
    dy = py[None, :] - _col(ctx.ty, h)
    return np.sqrt(dx * dx + dy * dy)


def _range_cost(ctx: _Context, r: np.ndarray, last: bool | np.ndarray) -> np.ndarray:
    """Distance (eq. 36) + soft range penalty (eq. 50) + terminal (eq. 38, when ``last``) per sigma point."""
    cfg = ctx.cfg
    v = r * ctx.c_dist + cfg.soft_penalty * (
        np.maximum(cfg.d_star_m - r, 0.0) * ctx.inv_ds + np.maximum(r - cfg.d_max_m, 0.0) * ctx.inv_dm
    )
    if isinstance(last, (bool, np.bool_)):
        return v + np.abs(r - cfg.d_star_m) * ctx.c_term if last else v
    return v + np.where(last, np.abs(r - cfg.d_star_m) * ctx.c_term, 0.0)


def _hypot_inplace(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """sqrt(dx^2 + dy^2) written into ``dx`` (returned); ``dy`` is left as scratch."""
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(dx, out=dx)


def _soft_range_cost(
    ctx: _Context, r: np.ndarray, short: np.ndarray, over: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Distance cost (eq. 36) plus the soft range penalty (eq. 50) at ranges ``r`` (m), in place.

    The same operations as :func:`_range_cost` without the terminal term, written into the scratch
    arrays ``short`` and ``over`` (shape of ``r``); returns (cost in ``over``, ``short``, free again).
    """
    cfg = ctx.cfg
    np.subtract(cfg.d_star_m, r, out=short)
    np.maximum(short, 0.0, out=short)
    short *= ctx.inv_ds
    np.subtract(r, cfg.d_max_m, out=over)
    np.maximum(over, 0.0, out=over)
    over *= ctx.inv_dm
    short += over
    short *= cfg.soft_penalty
    v = np.multiply(r, ctx.c_dist, out=over)
    v += short
    return v, short


def _range_part(ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """UT-weighted distance + penalty + terminal cost (N,) at step h.

    For one level h the same operations as :func:`_range_cost` run in place (fewer temporaries).
    """
    if not isinstance(h, (int, np.integer)):
        return _wsum(ctx, _range_cost(ctx, _target_ranges(ctx, h, px, py), _is_last(ctx, h)))
    cfg = ctx.cfg
    r = px[None, :] - ctx.tx_c[h]
    dy = py[None, :] - ctx.ty_c[h]
    r = _hypot_inplace(r, dy)
    v, short = _soft_range_cost(ctx, r, dy, np.empty_like(r))
    if h == ctx.H:
        term = np.subtract(r, cfg.d_star_m, out=short)
        np.abs(term, out=term)
        term *= ctx.c_term
        v += term
    v *= ctx.w[:, None]
    return _sigma_sum(v)


def _range_terms(ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, ...]:
    """Distance (eq. 36), soft range penalty (eq. 50) and terminal (eq. 38) terms separately, each (N,)."""
    cfg = ctx.cfg
    r = _target_ranges(ctx, h, px, py)
    dist = _wsum(ctx, r * ctx.c_dist)
    pen = _wsum(
        ctx,
        cfg.soft_penalty
        * (np.maximum(cfg.d_star_m - r, 0.0) * ctx.inv_ds + np.maximum(r - cfg.d_max_m, 0.0) * ctx.inv_dm),
    )
    term = _wsum(ctx, np.where(_is_last(ctx, h), np.abs(r - cfg.d_star_m) * ctx.c_term, 0.0))
    return dist, pen, term


def _geometry(ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Geometry term alpha / sigma_min(Phi) (eqs. 34-35), (N,), closed form over the agents' unit bearing vectors.

    sigma_min^2 = 2 (sum of squared cross products of all pairs) / (n + |z|), z = sum exp(2 i b);
    the neighbours' pairs and share of z are precomputed per step and sigma point.
    """
    alpha = ctx.cfg.alpha
    if isinstance(h, (int, np.integer)):
        dx = px[None, :] - ctx.tx_c[h]
        dy = py[None, :] - ctx.ty_c[h]
        und, pair, zr0, zi0, *ej = ctx.geometry_columns(int(h))
    else:
        dx = px[None, :] - _col(ctx.tx, h)
        dy = py[None, :] - _col(ctx.ty, h)
        und, pair, zr0, zi0 = (_col(a, h) for a in (ctx.nb_undefined, ctx.pair, ctx.zr, ctx.zi))
        ej = [_col(a, h) for a in (*ctx.nb_ey_j, *ctx.nb_ex_j)]
    dx2 = dx * dx
    dy2 = dy * dy
    r2 = dx2 + dy2
    if ctx.n_agents == 1:
        return _wsum(ctx, np.where(r2 < _R2_MIN, alpha / SIGMA_FLOOR, alpha))
    bad = r2 < _R2_MIN
    bad |= und
    np.copyto(r2, 1.0, where=bad)
    inv = np.divide(1.0, r2, out=r2)
    num = np.zeros(0)
    for j in range(ctx.k):
        c = dx * ej[j]
        c -= dy * ej[ctx.k + j]
        c *= c
        num = c if j == 0 else np.add(num, c, out=num)
    num *= inv
    num += pair
    zr = np.subtract(dx2, dy2, out=dx2)
    zr *= inv
    zr += zr0
    zi = np.multiply(dx, dy, out=dx)
    inv *= 2.0
    zi *= inv
    zi += zi0
    zr *= zr
    zi *= zi
    zr += zi
    np.sqrt(zr, out=zr)
    zr += ctx.n_agents
    num *= 2.0
    num /= zr
    sig = np.sqrt(num, out=num)
    np.copyto(sig, 0.0, where=bad)
    np.maximum(sig, SIGMA_FLOOR, out=sig)
    return _wsum(ctx, np.divide(alpha, sig, out=sig))


def _neighbour_ranges(
    ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (k, N) to the neighbours at step h and the safety violation sum_j max(0, d_S - range_j) (N,), m."""
    if ctx.k == 0:
        return np.zeros((0, px.size)), np.zeros(px.size)
    if isinstance(h, (int, np.integer)):
        ox = px[None, :] - ctx.nbx_c[h]
        oy = py[None, :] - ctx.nby_c[h]
    else:
        ox = px[None, :] - _col(ctx.nbx, h)
        oy = py[None, :] - _col(ctx.nby, h)
    rng = _hypot_inplace(ox, oy)
    short = np.subtract(ctx.cfg.d_safe_m, rng, out=oy)
    np.maximum(short, 0.0, out=short)
    viol = short[0]
    for j in range(1, ctx.k):
        viol = viol + short[j]
    return rng, viol


def _connectivity(ctx: _Context, h: int | np.ndarray, rng: np.ndarray) -> np.ndarray:
    """Connectivity term gamma / max(lambda_2(L), LAMBDA_FLOOR) of eq. (37), (N,), ranges rng (k, N); 0 if k = 0."""
    if ctx.k == 0:
        return np.zeros(rng.shape[1])
    lam = _fiedler(_link_weight(ctx, rng).T, _at(ctx.nb_w, h))
    return ctx.cfg.gamma / np.maximum(lam, LAMBDA_FLOOR)


def _connectivity_bound(ctx: _Context, h: int, rng: np.ndarray) -> np.ndarray:
    """Lower bound (N,) of the connectivity term from Fiedler's lambda_2 <= n / (n - 1) min_i L_ii; rng (k, N)."""
    w = _link_weight(ctx, rng)
    deg = np.minimum(w.sum(axis=0), np.min(ctx.nb_w[h].sum(axis=1)[:, None] + w, axis=0))
    return ctx.cfg.gamma / np.maximum(deg * (ctx.n_agents / (ctx.n_agents - 1.0)), LAMBDA_FLOOR)


def _stage_cost(
    ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray, chunk: int = 4096
) -> tuple[np.ndarray, np.ndarray]:
    """Stage cost of eq. (38) (N,) = geometry + range terms + connectivity, and the safety violation (N,) in m.

    Element-wise per position (chunked to stay in cache), so a position's cost does not depend on its batch.
    """
    if px.size <= chunk:
        rng, viol = _neighbour_ranges(ctx, h, px, py)
        return (_geometry(ctx, h, px, py) + _range_part(ctx, h, px, py)) + _connectivity(ctx, h, rng), viol
    cost = np.empty(px.size)
    viol = np.empty(px.size)
    for lo in range(0, px.size, chunk):
        x, y = px[lo : lo + chunk], py[lo : lo + chunk]
        hh = h if isinstance(h, (int, np.integer)) else h[lo : lo + chunk]
        rng, v = _neighbour_ranges(ctx, hh, x, y)
        cost[lo : lo + chunk] = (_geometry(ctx, hh, x, y) + _range_part(ctx, hh, x, y)) + _connectivity(ctx, hh, rng)
        viol[lo : lo + chunk] = v
    return cost, viol


def _terms(ctx: _Context, h: int | np.ndarray, px: np.ndarray, py: np.ndarray) -> dict[str, np.ndarray]:
    """The cost terms of eq. (38) separately (for telemetry), each (N,), and the safety violation in m."""
    dist, pen, term = _range_terms(ctx, h, px, py)
    rng, viol = _neighbour_ranges(ctx, h, px, py)
    return {
        "geometry": _geometry(ctx, h, px, py),
        "distance": dist,
        "connectivity": _connectivity(ctx, h, rng),
        "penalty": pen,
        "terminal": term,
        "safety_violation_m": viol,
    }


def _range_min_at(ctx: _Context, last: bool | np.ndarray) -> float | np.ndarray:
    """Range (m) minimising the range terms: d* if their sum decreases below d* (eqs. 36, 38, 50), else 0."""
    cfg = ctx.cfg
    left_slope = 1.0 - cfg.alpha - cfg.soft_penalty - np.where(last, cfg.terminal_weight, 0.0)
    return np.where(left_slope < 0.0, cfg.d_star_m, 0.0)


def _range_bound(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Cheap lower bound (N,) of :func:`_range_part` at step h from the range r0 to the centre sigma point alone.

    The other sigma points come in pairs xi_0 +- d_j of equal weight (eqs. 32-33, propagated
    linearly), so their ranges satisfy r_+ + r_- >= 2 r0 (triangle inequality). The range cost
    f(r) is convex with its minimum at x_min (0 or d*) and non-decreasing beyond, hence
    f(r_+) + f(r_-) >= 2 f(max(r0, x_min)) and the weighted sum is at least
    w0 f(r0) + (1 - w0) f(max(r0, x_min)). Needs non-negative weights (``ctx.can_prune``).
    """
    last = h == ctx.H
    dx = px - ctx.tx0[h]
    dy = py - ctx.ty0[h]
    r0 = np.sqrt(dx * dx + dy * dy)
    x_min = float(_range_min_at(ctx, last))
    return ctx.w[0] * _range_cost(ctx, r0, last) + ctx.w_rest * _range_cost(ctx, np.maximum(r0, x_min), last)


def _lower_bound(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Admissible lower bound (N,) of the cost of steps h+1..H from own positions (px, py) at step h.

    After j more steps the vehicle is within j * T_o * max(speed) of its position; each term is
    bounded over that disc: the range terms exactly on the range interval (their sum is convex and
    piecewise linear in the range with its minimum at d* or 0), geometry by the neighbours'
    bearings alone (sigma_min^2 = (n - |Z + exp(2 i b)|) / 2 <= (n - ||Z| - 1|) / 2, Z the
    neighbours' share of z), connectivity by Fiedler's bound lambda_2 <= n / (n - 1) min_i L_ii
    with the own links at their shortest possible range.
    """
    total = _range_rest(ctx, h, px, py)
    return total + _connectivity_rest(ctx, h, px, py) if ctx.k > 0 else total


def _range_rest(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Range and geometry part (N,) of :func:`_lower_bound`: the range terms per sigma point on the disc."""
    cfg = ctx.cfg
    ds = cfg.d_star_m
    rho = ctx.r_step * np.arange(1, ctx.H - h + 1, dtype=float)[None, :, None]
    last = (np.arange(h + 1, ctx.H + 1) == ctx.H)[None, :, None]
    # layout (L, H - h, N): sigma point, future step, position
    r = px[None, None, :] - ctx.tx[h + 1 :].T[:, :, None]
    dy = py[None, None, :] - ctx.ty[h + 1 :].T[:, :, None]
    r = _hypot_inplace(r, dy)
    lo = r - rho
    np.maximum(lo, 0.0, out=lo)
    hi = np.add(r, rho, out=r)
    left_slope = 1.0 - cfg.alpha - cfg.soft_penalty - np.where(last, cfg.terminal_weight, 0.0)
    x_min = np.where(left_slope < 0.0, ds, 0.0)
    at = np.maximum(x_min, lo, out=lo)
    np.minimum(at, hi, out=at)
    # range cost of eqs. (36), (38), (50) at the clipped range, in place (see _range_cost)
    best, short = _soft_range_cost(ctx, at, dy, hi)
    term = np.subtract(at[:, -1], ds, out=short[:, -1])
    np.abs(term, out=term)
    term *= ctx.c_term
    best[:, -1] += term
    best *= ctx.w[:, None, None]
    return _sigma_sum(best).sum(axis=0) + float(np.sum(ctx.geom_lb_w[h + 1 :]))


def _connectivity_rest(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Lower bound (N,) of the connectivity terms (eq. 37) of steps h+1..H (see :func:`_lower_bound`); k > 0."""
    rho = ctx.r_step * np.arange(1, ctx.H - h + 1, dtype=float)[None, :, None]
    # layout (k, H - h, N): neighbour, future step, position
    ox = px[None, None, :] - ctx.nbx[h + 1 :].T[:, :, None]
    oy = py[None, None, :] - ctx.nby[h + 1 :].T[:, :, None]
    ox = _hypot_inplace(ox, oy)
    ox -= rho
    w = _link_weight(ctx, np.maximum(ox, 0.0, out=ox))
    nb_deg = ctx.nb_w[h + 1 :].sum(axis=2).T[:, :, None]
    deg = np.minimum(w.sum(axis=0), np.min(nb_deg + w, axis=0))
    lam_up = deg * (ctx.n_agents / (ctx.n_agents - 1.0))
    return (ctx.cfg.gamma / np.maximum(lam_up, LAMBDA_FLOOR)).sum(axis=0)


def _range_rest_centre(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Cheap lower bound (N,) of :func:`_range_rest` from the centre sigma point alone.

    Per future step the disc bound g(r) = f(clip(x_min, r - rho, r + rho)) of :func:`_lower_bound`
    is convex, minimal at x_min and non-decreasing beyond, so the pairing argument of
    :func:`_range_bound` (eqs. 32-33) gives w0 g(r0) + (1 - w0) g(max(r0, x_min)). Needs ``ctx.can_prune``.
    """
    cfg = ctx.cfg
    n = ctx.H - h
    rho = ctx.r_step * np.arange(1, n + 1, dtype=float)[:, None]
    # layout (2 (H - h), N): future step at r0, then at max(r0, x_min); position
    x_min = np.full((n, 1), float(_range_min_at(ctx, False)))
    x_min[-1] = float(_range_min_at(ctx, True))
    hi = px[None, :] - ctx.tx0[h + 1 :, None]
    dy = py[None, :] - ctx.ty0[h + 1 :, None]
    hi = _hypot_inplace(hi, dy)
    at = np.empty((2 * n, px.size))
    s1 = np.subtract(hi, rho, out=at[:n])
    np.maximum(s1, 0.0, out=s1)
    np.maximum(s1, x_min, out=s1)
    hi += rho
    np.minimum(s1, hi, out=s1)
    np.maximum(s1, x_min, out=at[n:])
    cost, short = _soft_range_cost(ctx, at, np.empty_like(at), np.empty_like(at))
    ends = [n - 1, 2 * n - 1]
    term = np.subtract(at[ends], cfg.d_star_m, out=short[:2])
    np.abs(term, out=term)
    term *= ctx.c_term
    cost[ends] += term
    total = ctx.w[0] * cost[:n].sum(axis=0)
    total += ctx.w_rest * cost[n:].sum(axis=0)
    total += float(np.sum(ctx.geom_lb_w[h + 1 :]))
    return total


# ----------------------------------------------------------------------------- search


def _step_table(ctx: _Context, g: _Graph) -> np.ndarray:
    """Displacements x + i y in m of every step type of the graph, plus a final zero for "no step"."""
    speeds = ctx.speeds.tolist()
    n = g.type_g.size
    out = np.zeros(n + 1, dtype=complex)
    for i, (a, b) in enumerate(zip(g.type_g.tolist(), g.type_speed.tolist(), strict=True)):
        heading = ctx.theta0 + a * ctx.unit
        dist = ctx.T * speeds[b]
        out[i] = complex(dist * math.cos(heading), dist * math.sin(heading))
    return out


def _positions(ctx: _Context, g: _Graph, h: int, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Own positions (x, y) in m of position nodes at level h: the start plus their steps in sorted order.

    Summed as complex numbers x + i y, which adds the x and the y parts exactly as two real sums.
    """
    steps = ctx.steps
    cols = g.pos_cols[h]
    z = steps.take(cols[0].take(nodes)) + complex(*ctx.p0)
    for j in range(1, h):
        z += steps.take(cols[j].take(nodes))
    return z.real, z.imag


def _rollout(ctx: _Context, g: _Graph, h: int, starts: np.ndarray, base: np.ndarray) -> float:
    """Best total cost of greedy completions (cheapest next step each time) from states ``starts`` at level h."""
    cur = starts
    total = base.copy()
    n_u = g.child[h + 1].shape[1]
    row_at = np.arange(0, starts.size * n_u, n_u)
    for hh in range(h + 1, ctx.H + 1):
        kids = g.child[hh].take(cur, axis=0)
        p, at = np.unique(g.state_pos[hh].take(kids) if hh < ctx.H else kids, return_inverse=True)
        cost, viol = _stage_cost(ctx, hh, *_positions(ctx, g, hh, p))
        cost[viol > 0.0] = np.inf
        cost = cost.take(at.reshape(kids.shape))
        pick = row_at + cost.argmin(axis=1)
        total = total + cost.take(pick)
        cur = kids.take(pick)
    return float(total.min())


def _search(ctx: _Context, g: _Graph) -> tuple[np.ndarray | None, int]:
    """Exact branch and bound over the merge graph: (indices, nodes fully evaluated); None if all infeasible.

    Level by level: the children of the expanded states are first bounded cheaply, cheapest bound
    first (range terms of this and the remaining steps from the centre sigma point alone,
    :func:`_range_bound` and :func:`_range_rest_centre`, with the geometry and connectivity bounds;
    then the remaining steps' connectivity bound; then the exact range terms; then the full bound of
    the remaining steps); only children that can still beat the incumbent (the best greedy
    completion found so far) get their full cost. A child is tested once, with the cheapest
    cost so far among its expanded parents (float addition is monotone, so this keeps exactly the
    children that some in-edge keeps). A state is expanded only if its exact cost so far plus the
    bound of the remaining steps can still beat the incumbent; the incumbent is refined at level
    H - 1 only when that level is wide. Stage costs are kept per candidate node, and the backward
    values reuse the children gathered on the way forward.
    """
    H = ctx.H
    f_prev = np.zeros(1)
    exp_idx = np.zeros(1, dtype=np.int64)
    f_exp = np.zeros(1)
    ub = math.inf
    nodes = 0
    # per level: the expanded states, their stage costs and the children (n_exp, |U|) expanded from the level before
    expanded: list[np.ndarray] = [exp_idx]
    exp_cost: list[np.ndarray] = [np.zeros(1)]
    kid_rows: list[np.ndarray] = [np.zeros((0, 0), dtype=np.int32)]
    # per level 1..H-1: forward values of all states (inf where not expanded), overwritten by the backward values
    values: list[np.ndarray] = [np.zeros(0)] * H
    for h in range(1, H + 1):
        kids = g.child[h].take(exp_idx, axis=0)
        keys = g.state_pos[h].take(kids) if h < H else kids
        cand, kc = _compress(keys.reshape(-1), g.pos_digits[h].shape[0])
        px, py = _positions(ctx, g, h, cand)
        bound_rest = ctx.can_prune and H - _BOUND_LEVELS <= h < H
        if ctx.can_prune and math.isfinite(ub):
            lim = ub + _PRUNE_RTOL * max(1.0, abs(ub))
            # cheapest cost so far into each candidate: f + b <= lim holds for some in-edge iff it does for this one
            f_in = np.full(cand.size, np.inf)
            np.minimum.at(f_in, kc, f_exp.repeat(kids.shape[1]))
            sel, x, y, ranged, conn, rem = _survivors(ctx, h, px, py, f_in, lim, bound_rest)
        else:
            rng, viol = _neighbour_ranges(ctx, h, px, py)
            sel = np.flatnonzero(viol == 0.0)
            x, y = px.take(sel), py.take(sel)
            ranged = _range_part(ctx, h, x, y)
            conn = _connectivity(ctx, h, rng.take(sel, axis=1))
            rem = _lower_bound(ctx, h, x, y) if bound_rest else np.zeros(sel.size)
        cost_sel = (_geometry(ctx, h, x, y) + ranged) + conn
        cost = np.full(cand.size, np.inf)
        cost[sel] = cost_sel
        nodes += sel.size
        kid_rows.append(kc.reshape(kids.shape) if h == H else kids)
        if h == H:
            break
        # forward values (cost so far) of the states at the evaluated nodes (each node's states are contiguous)
        at_node = cand.take(sel)
        st, _ = _spans(g.node_start[h], g.node_count[h], at_node)
        per_node = g.node_count[h].take(at_node)
        cost_st = cost_sel.repeat(per_node)
        edges, first = _spans(g.in_start[h], g.in_count[h], st)
        f_st = cost_st + np.minimum.reduceat(f_prev.take(g.in_parent[h].take(edges)), first) if st.size else cost_st
        bound_st = f_st + rem.repeat(per_node)
        live = np.isfinite(f_st)
        if ctx.can_prune and live.any():
            alive = np.flatnonzero(live)
            # the incumbent is refined before step H only where that level is wide enough to pay off
            if h == min(2, H - 1) or (h == H - 1 and alive.size > _REFINE_MIN):
                if alive.size > _ROLLOUTS:
                    alive = alive.take(bound_st.take(alive).argpartition(_ROLLOUTS - 1)[:_ROLLOUTS])
                ub = min(ub, _rollout(ctx, g, h, st.take(alive), f_st.take(alive)))
            live &= bound_st <= ub + _PRUNE_RTOL * max(1.0, abs(ub))
        exp_idx = st[live]
        f_exp = f_st[live]
        f_prev = values[h] = np.full(g.state_pos[h].size, np.inf)
        f_prev[exp_idx] = f_exp
        expanded.append(exp_idx)
        exp_cost.append(cost_st[live])
    # backward values (cost to go, from the states' own stage cost on) of the expanded states, level by level
    last = cost.take(kid_rows[H])
    kid_vals = last
    for h in range(H - 1, 0, -1):
        v = values[h]
        v[expanded[h]] = exp_cost[h] + kid_vals.min(axis=1)
        kid_vals = v.take(kid_rows[h])
    values[0] = kid_vals.min(axis=1)
    if not np.isfinite(values[0][0]):
        return None, nodes
    return _extract(g, values, None, H, (expanded[H - 1], last)), nodes


def _survivors(
    ctx: _Context, h: int, px: np.ndarray, py: np.ndarray, f_in: np.ndarray, lim: float, bound_rest: bool
) -> tuple[np.ndarray, ...]:
    """Candidates at step h that can still beat the incumbent: (indices, x, y, range terms, connectivity, rest bound).

    The bounds grow in cost order, each tested on the survivors of the one before: range terms
    of the centre sigma point (:func:`_range_bound`) with the geometry bound, then (``bound_rest``)
    the rest from the centre sigma point (:func:`_range_rest_centre`), then the connectivity term
    (its lower bound for k > 2) and the safety distance, then the remaining steps' connectivity
    bound, the exact range terms and the full bound of the remaining steps. Every test adds
    non-negative terms to the one before and float addition is monotone, so a candidate dropped
    early fails every later test too: the survivors are the same as with all tests on all
    candidates. The connectivity returned is the exact term (eq. 37) of the survivors.
    """
    g_lb = ctx.geom_lb_w[h]
    rb = _range_bound(ctx, h, px, py)
    at = np.flatnonzero(f_in + (rb + g_lb) <= lim)
    f, rb, x, y = _pick(at, f_in, rb, px, py)
    if bound_rest:
        rrc = _range_rest_centre(ctx, h, x, y)
        at, f, rb, x, y, rrc = _pick(np.flatnonzero(f + ((rb + g_lb) + rrc) <= lim), at, f, rb, x, y, rrc)
    rng, viol = _neighbour_ranges(ctx, h, x, y)
    exact_conn = ctx.k <= 2
    conn = _connectivity(ctx, h, rng) if exact_conn else _connectivity_bound(ctx, h, rng)
    quick = np.where(viol == 0.0, rb + (g_lb + conn), np.inf)
    if bound_rest:
        quick += rrc
    at, f, x, y, conn, rng, quick = _pick(np.flatnonzero(f + quick <= lim), at, f, x, y, conn, rng, quick)
    rem = np.zeros(at.size)
    if bound_rest and ctx.k > 0:
        rem = _connectivity_rest(ctx, h, x, y)
        at, f, x, y, conn, rng, rem = _pick(np.flatnonzero(f + (quick + rem) <= lim), at, f, x, y, conn, rng, rem)
    ranged = _range_part(ctx, h, x, y)
    bound = (ranged + g_lb) + conn
    keep = f + bound <= lim
    if bound_rest:
        at, f, x, y, conn, rng, rem, ranged, bound = _pick(
            np.flatnonzero(keep), at, f, x, y, conn, rng, rem, ranged, bound
        )
        rem = rem + _range_rest(ctx, h, x, y)
        keep = f + (bound + rem) <= lim
    at, x, y, ranged, conn, rng, rem = _pick(np.flatnonzero(keep), at, x, y, ranged, conn, rng, rem)
    return at, x, y, ranged, conn if exact_conn else _connectivity(ctx, h, rng), rem


def _pick(i: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The entries ``i`` of each array along its last axis."""
    return tuple(a.take(i, axis=-1) for a in arrays)


def _spans(start: np.ndarray, count: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated index ranges [start[i], start[i] + count[i]) for i in ``sel``, and where each begins."""
    c = count.take(sel)
    ends = c.cumsum()
    begins = ends - c
    if ends.size == 0:
        return np.zeros(0, dtype=np.int64), begins
    return (start.take(sel) - begins).repeat(c) + np.arange(ends[-1]), begins


def _extract(
    g: _Graph,
    values: list[np.ndarray],
    second: list[np.ndarray] | None,
    H: int,
    last: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Lexicographically smallest index sequence that follows minimal backward values (then minimal ``second``).

    ``values`` holds levels 0..H; with ``last`` = (sorted states at H - 1, their children's values
    (n, |U|)) the values of step H are read from there and ``values`` needs levels 0..H-1 only.
    """
    s = 0
    out = np.empty(H, dtype=np.int64)
    for h in range(1, H + 1):
        kids = g.child[h][s]
        v = last[1][int(np.searchsorted(last[0], s))] if last is not None and h == H else values[h][kids]
        if second is not None:
            v = np.where(v == v.min(), second[h][kids], np.inf)
        u = int(np.argmin(v))
        out[h - 1] = u
        s = int(kids[u])
    return out


def _fallback(ctx: _Context, g: _Graph) -> tuple[np.ndarray, int]:
    """Every sequence is infeasible: minimise the total safety violation (m), then the cost; exact, no pruning."""
    H = ctx.H
    costs: list[np.ndarray] = [np.zeros(1)]
    viols: list[np.ndarray] = [np.zeros(1)]
    nodes = 0
    for h in range(1, H + 1):
        c, v = _stage_cost(ctx, h, *_positions(ctx, g, h, np.arange(g.pos_digits[h].shape[0])))
        costs.append(c)
        viols.append(v)
        nodes += c.size
    vv: list[np.ndarray] = [np.zeros(0)] * (H + 1)
    vc: list[np.ndarray] = [np.zeros(0)] * (H + 1)
    vv[H], vc[H] = viols[H], costs[H]
    for h in range(H - 1, -1, -1):
        kids = g.child[h + 1]
        a = vv[h + 1][kids]
        amin = a.min(axis=1)
        b = np.where(a == amin[:, None], vc[h + 1][kids], np.inf).min(axis=1)
        sp = g.state_pos[h]
        vv[h] = viols[h][sp] + amin if h > 0 else amin
        vc[h] = costs[h][sp] + b if h > 0 else b
    return _extract(g, vv, vc, H), nodes


def _path(ctx: _Context, indices: np.ndarray) -> np.ndarray:
    """Own positions (H, 2) in m along a control index sequence, headings on the lattice."""
    g = 0
    x, y = ctx.p0
    out = np.empty((ctx.H, 2))
    for h, u in enumerate(indices):
        a, s = divmod(int(u), ctx.n_speed)
        g = (g + ctx.m[a]) % ctx.wrap if ctx.wrap else g + ctx.m[a]
        vx, vy = ctx.step_vector(g, ctx.speed_class[s])
        x, y = x + vx, y + vy
        out[h] = (x, y)
    return out


_TERMS = ("geometry", "distance", "connectivity", "penalty", "terminal")


def _make_plan(ctx: _Context, indices: np.ndarray, nodes: int) -> Plan:
    way = _path(ctx, indices)
    per_step = _terms(ctx, np.arange(1, ctx.H + 1), way[:, 0], way[:, 1])
    terms = {name: float(sum(val.tolist())) for name, val in per_step.items()}
    a, s = np.divmod(indices, ctx.n_speed)
    return Plan(
        controls=np.column_stack([ctx.dtheta[a], ctx.speeds[s]]),
        indices=indices.astype(np.int64),
        cost=float(sum(sum(step) for step in zip(*(per_step[k].tolist() for k in _TERMS), strict=True))),
        terms=terms,
        feasible=terms["safety_violation_m"] == 0.0,
        waypoints=way,
        nodes=nodes,
    )


def warm_up(planner: PlannerConfig, channel: ChannelConfig, u_max: float, r_max: float) -> None:
    """Build the cached merge graphs for every control-set shape an agent can meet.

    The speed set {0, u_e, u_max} has three shapes (0 < u_e < u_max, u_e = u_max, u_e = 0); building
    their graphs at start-up keeps that one-off cost out of the first plans' wall time.
    """
    for u_e in (0.5 * u_max, u_max, 0.0):
        ctx = _Context(
            PlanProblem(
                position=np.zeros(2),
                heading=0.0,
                xi=np.array([planner.d_star_m, 0.0, 0.0, 0.0]),
                P=np.eye(4),
                neighbours=(),
                controls=control_set(planner, u_e, u_max, r_max),
                planner=planner,
                channel=channel,
            )
        )
        _graph(ctx.m, ctx.wrap, ctx.speed_class, ctx.H)


def plan(problem: PlanProblem) -> Plan:
    """Exact minimiser of eq. (38) subject to eq. (50) over all |U|^H control sequences (eqs. 29-31, 43).

    Dynamic programming over merged states with branch and bound: the cost of step h depends
    only on this agent's position at step h (neighbours and target belief are fixed), and a
    position is an order-independent integer combination of step vectors on the heading grid, so
    sequences reaching the same (position, heading) share one state (graph cached per control-set
    shape and H). States and children that provably cannot beat the best complete sequence found
    by greedy completions are skipped (admissible bounds, see :func:`_lower_bound`). The optimum is
    read back with backward values; among exactly equal costs the lexicographically smallest
    index sequence wins. If every sequence violates the safety distance, the least total
    violation, then the least cost, is chosen.
    """
    ctx = _Context(problem)
    g = _graph(ctx.m, ctx.wrap, ctx.speed_class, ctx.H)
    ctx.steps = _step_table(ctx, g)
    indices, nodes = _search(ctx, g)
    if indices is None:
        indices, extra = _fallback(ctx, g)
        nodes += extra
    return _make_plan(ctx, indices, nodes)


class DmpcPlanner:
    """Our DMPC's planner of one AUV: the exact minimiser :func:`plan` (merge graphs built at construction)."""

    shares_plans = True
    """The payload carries the plan."""

    def __init__(self, scenario: Scenario, auv: int) -> None:
        warm_up(scenario.planner, scenario.channel, scenario.agents.u_max_mps, scenario.agents.r_max_radps)

    def plan(self, problem: PlanProblem) -> Plan:
        """Exact DMPC plan of ``problem`` (eqs. 29-31, 43)."""
        return plan(problem)


def brute_force(problem: PlanProblem) -> Plan:
    """Reference search: evaluates every one of the |U|^H sequences (prefixes shared, no merging, no pruning).

    Same model, cost and tie-break as :func:`plan` (lexicographically smallest index sequence
    among exactly equal costs; all infeasible: least total violation, then cost).
    """
    ctx = _Context(problem)
    n_u, H = ctx.n_u, ctx.H
    a_of = np.repeat(np.arange(ctx.dtheta.size), ctx.n_speed)
    s_of = np.tile(np.arange(ctx.n_speed), ctx.dtheta.size)
    g_min = 0 if ctx.wrap else -H * max(abs(v) for v in ctx.m)
    g_count = ctx.wrap if ctx.wrap else 1 - 2 * g_min
    table = np.array(
        [[ctx.step_vector(gi + g_min, ctx.speed_class[s]) for s in range(ctx.n_speed)] for gi in range(g_count)]
    ).reshape(g_count, ctx.n_speed, 2)
    gx = np.array([ctx.p0[0]])
    gy = np.array([ctx.p0[1]])
    gh = np.zeros(1, dtype=np.int64)
    total = np.zeros(1)
    viol = np.zeros(1)
    nodes = 0
    for h in range(1, H + 1):
        gh = ctx.advance(np.repeat(gh, n_u), np.tile(a_of, gh.size))
        step = table[gh - g_min, np.tile(s_of, gx.size)]
        gx = np.repeat(gx, n_u) + step[:, 0]
        gy = np.repeat(gy, n_u) + step[:, 1]
        c, v = _stage_cost(ctx, h, gx, gy)
        total = np.repeat(total, n_u) + c
        viol = np.repeat(viol, n_u) + v
        nodes += gx.size
    feasible = viol == 0.0
    if np.any(feasible):
        flat = int(np.argmin(np.where(feasible, total, np.inf)))
    else:
        flat = int(np.argmin(np.where(viol == viol.min(), total, np.inf)))
    indices = np.array(np.unravel_index(flat, (n_u,) * H), dtype=np.int64)
    return _make_plan(ctx, indices, nodes)


# ----------------------------------------------------------------------------- validation helpers


def _finite_positive(name: str, value: float, unit: str) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be in (0, inf) {unit}, got {value!r}")


def _finite_at_least(name: str, value: float, lo: float, unit: str) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value >= lo):
        raise ValueError(f"{name} must be in [{lo:g}, inf) {unit}, got {value!r}")
