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

Exact search: see :func:`plan` and docs/planner.md.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from auv_core import acoustics
from auv_core.config import ChannelConfig, ConfigError, PlannerConfig, check_range

N_XI = 4
"""Dimension n of the target state xi (eq. 33)."""

SIGMA_FLOOR = 1e-3
"""Floor of sigma_min(Phi) in the geometry cost (dimensionless): caps it at alpha / SIGMA_FLOOR."""

LAMBDA_FLOOR = 1e-3
"""Floor of lambda_2(L) in the connectivity cost: a disconnected graph costs gamma / LAMBDA_FLOOR."""

MIN_BEARING_RANGE_M = 1e-3
"""Below this range (m) an agent is on the sigma point and its bearing is undefined."""

_R2_MIN = MIN_BEARING_RANGE_M**2
_PRUNE_RTOL = 1e-9
_ROLLOUTS = 8


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
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"planner.{f.name} must be a number, got {value!r}")
        check_range(f"planner.{f.name}", float(value), meta)
    if isinstance(cfg.horizon, float) or isinstance(cfg.n_headings, float):
        raise ConfigError("planner.horizon and planner.n_headings must be integers")
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
    nodes. A position node is the multiset of non-zero (heading class, speed class) steps taken.
    """

    child: tuple[np.ndarray, ...]
    state_pos: tuple[np.ndarray, ...]
    pos_parent: tuple[np.ndarray, ...]
    pos_type: tuple[np.ndarray, ...]
    in_parent: tuple[np.ndarray, ...]
    in_start: tuple[np.ndarray, ...]
    type_g: np.ndarray
    type_speed: np.ndarray


@lru_cache(maxsize=16)
def _graph(m: tuple[int, ...], wrap: int, speed_class: tuple[int, ...], horizon: int) -> _Graph:
    """Build the merge graph for heading offsets m (units of the grid), wrap modulus (0: none), speed classes, H."""
    base = horizon + 1
    n_speed = len(speed_class)
    controls = [(m[a], speed_class[s]) for a in range(len(m)) for s in range(n_speed)]
    n_u = len(controls)
    type_index: dict[tuple[int, int], int] = {}
    powers: list[int] = []
    states: list[tuple[int, int]] = [(0, 0)]
    prev_pos = [0]
    child_l: list[np.ndarray] = [np.zeros((0, n_u), np.int32)]
    state_pos_l: list[np.ndarray] = [np.zeros(1, np.int32)]
    pos_parent_l: list[np.ndarray] = [np.zeros(0, np.int32)]
    pos_type_l: list[np.ndarray] = [np.zeros(0, np.int32)]
    in_parent_l: list[np.ndarray] = [np.zeros(0, np.int32)]
    in_start_l: list[np.ndarray] = [np.zeros(0, np.int64)]
    for h in range(1, horizon + 1):
        last = h == horizon
        state_index: dict = {}
        new_states: list[tuple[int, int]] = []
        new_state_pos: list[int] = []
        pos_index: dict[int, int] = {}
        pos_parent: list[int] = []
        pos_type: list[int] = []
        table = []
        for s, (key, g) in enumerate(states):
            parent_pos = prev_pos[s]
            row = []
            for dm, sc in controls:
                g2 = g + dm
                if wrap:
                    g2 %= wrap
                if sc < 0:
                    key2, t = key, -1
                else:
                    t = type_index.get((g2, sc))
                    if t is None:
                        t = type_index[(g2, sc)] = len(type_index)
                        powers.append(base**t)
                    key2 = key + powers[t]
                p = pos_index.get(key2)
                if p is None:
                    p = pos_index[key2] = len(pos_parent)
                    pos_parent.append(parent_pos)
                    pos_type.append(t)
                skey = key2 if last else (key2, g2)
                si = state_index.get(skey)
                if si is None:
                    si = state_index[skey] = len(new_states)
                    new_states.append((key2, g2))
                    new_state_pos.append(p)
                row.append(si)
            table.append(row)
        child = np.array(table, dtype=np.int32).reshape(len(states), n_u)
        order = np.argsort(child.ravel(), kind="stable")
        counts = np.bincount(child.ravel(), minlength=len(new_states))
        child_l.append(child)
        state_pos_l.append(np.array(new_state_pos, dtype=np.int32))
        pos_parent_l.append(np.array(pos_parent, dtype=np.int32))
        pos_type_l.append(np.array(pos_type, dtype=np.int32))
        in_parent_l.append((order // n_u).astype(np.int32))
        in_start_l.append(np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64))
        states, prev_pos = new_states, new_state_pos
    types = sorted(type_index.items(), key=lambda kv: kv[1])
    type_g = np.array([k[0] for k, _ in types], dtype=np.int64)
    type_speed = np.array([k[1] for k, _ in types], dtype=np.int64)
    return _Graph(
        child=tuple(child_l),
        state_pos=tuple(state_pos_l),
        pos_parent=tuple(pos_parent_l),
        pos_type=tuple(pos_type_l),
        in_parent=tuple(in_parent_l),
        in_start=tuple(in_start_l),
        type_g=type_g,
        type_speed=type_speed,
    )


# ----------------------------------------------------------------------------- per-problem context


class _Context:
    """Everything of one problem that does not depend on the own control sequence."""

    def __init__(self, problem: PlanProblem) -> None:
        cfg = problem.planner
        self.problem = problem
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
        self.w_list = w.tolist()
        self.L = w.size
        hs = np.arange(self.H + 1)[:, None] * self.T
        self.tx = pts[None, :, 0] + hs * pts[None, :, 2]
        self.ty = pts[None, :, 1] + hs * pts[None, :, 3]
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
        self.nb_ex, self.nb_ey = ex, ey
        self.zr = np.sum(ex * ex - ey * ey, axis=2)
        self.zi = np.sum(2.0 * ex * ey, axis=2)
        pair = np.zeros(self.zr.shape)
        for j in range(self.k):
            for i in range(j + 1, self.k):
                c = ex[:, :, j] * ey[:, :, i] - ey[:, :, j] * ex[:, :, i]
                pair = pair + c * c
        self.pair = pair
        # neighbour-neighbour link weights (H+1, k, k) of eqs. (22)-(26)
        dxx = self.nbx[:, :, None] - self.nbx[:, None, :]
        dyy = self.nby[:, :, None] - self.nby[:, None, :]
        self.nb_w = _link_weight(np.sqrt(dxx * dxx + dyy * dyy), self.ch)
        idx = np.arange(self.k)
        self.nb_w[:, idx, idx] = 0.0
        # upper bound of sigma_min per (level, sigma point), for the lower bounds of the pruning
        zabs = np.sqrt(self.zr * self.zr + self.zi * self.zi)
        if self.n_agents == 1:
            sig_up = np.ones(self.zr.shape)
        else:
            sig_up = np.sqrt(np.maximum(self.n_agents - np.maximum(zabs - 1.0, 0.0), 0.0) / 2.0)
            sig_up = np.where(self.nb_undefined, 0.0, sig_up)
        self.geom_lb = cfg.alpha / np.maximum(sig_up, SIGMA_FLOOR)
        self.can_prune = bool(np.all(w >= 0.0))
        self.r_step = self.T * float(np.max(self.speeds))
        self._steps: dict[tuple[int, int], tuple[float, float]] = {}

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


def _link_weight(range_m: np.ndarray, ch: ChannelConfig) -> np.ndarray:
    """Normalised link weight rho / rho_M of eqs. (22)-(26); 0 below the detection threshold or at rho <= 0 dB."""
    rho = np.asarray(
        acoustics.snr_db(range_m, ch.source_level_db, ch.noise_level_db, ch.directivity_index_db, ch.frequency_khz)
    )
    rho_m = acoustics.snr_max_db(ch)
    scale = rho_m if rho_m > 0.0 else 1.0
    return np.where((rho >= ch.detection_threshold_db) & (rho > 0.0), rho / scale, 0.0)


def _fiedler(own_w: np.ndarray, nb_w: np.ndarray) -> np.ndarray:
    """lambda_2 of the Laplacian (eq. 26) of own node + k neighbours; own_w (N, k), nb_w (k, k)."""
    n_pts, k = own_w.shape
    if k == 1:
        return 2.0 * own_w[:, 0]
    if k == 2:
        return np.asarray(acoustics.fiedler_value_3(own_w[:, 0], own_w[:, 1], np.full(n_pts, nb_w[0, 1])))
    lap = np.zeros((n_pts, k + 1, k + 1))
    lap[:, 0, 1:] = -own_w
    lap[:, 1:, 0] = -own_w
    lap[:, 0, 0] = own_w.sum(axis=1)
    lap[:, 1:, 1:] = -nb_w
    idx = np.arange(1, k + 1)
    lap[:, idx, idx] = nb_w.sum(axis=1) + own_w
    return np.maximum(np.linalg.eigvalsh(lap)[:, 1], 0.0)


# ----------------------------------------------------------------------------- stage cost


def _stage(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """Cost terms of eq. (38) at step h for own positions (px, py) (N,), and the safety violation (N,) in m.

    Terms: geometry, distance, connectivity, penalty, terminal (each (N,), UT-weighted over the
    sigma points, eq. 30). Element-wise only, so a position's cost does not depend on the batch.
    """
    cfg = ctx.cfg
    n_pts = px.size
    dx = px[:, None] - ctx.tx[h]
    dy = py[:, None] - ctx.ty[h]
    dx2 = dx * dx
    dy2 = dy * dy
    r2 = dx2 + dy2
    r = np.sqrt(r2)
    if ctx.n_agents == 1:
        geom = np.where(r2 < _R2_MIN, cfg.alpha / SIGMA_FLOOR, cfg.alpha)
    else:
        bad = (r2 < _R2_MIN) | ctx.nb_undefined[h]
        inv = 1.0 / np.where(bad, 1.0, r2)
        num = None
        for j in range(ctx.k):
            c = dx * ctx.nb_ey[h, :, j] - dy * ctx.nb_ex[h, :, j]
            num = c * c if num is None else num + c * c
        num = num * inv + ctx.pair[h]
        zr = (dx2 - dy2) * inv + ctx.zr[h]
        zi = (dx * dy) * (2.0 * inv) + ctx.zi[h]
        s2 = (2.0 * num) / (ctx.n_agents + np.sqrt(zr * zr + zi * zi))
        sig = np.where(bad, 0.0, np.sqrt(s2))
        geom = cfg.alpha / np.maximum(sig, SIGMA_FLOOR)
    dist = r * ((1.0 - cfg.alpha) / cfg.d_star_m)
    pen = cfg.soft_penalty * (
        np.maximum(cfg.d_star_m - r, 0.0) / cfg.d_star_m + np.maximum(r - cfg.d_max_m, 0.0) / cfg.d_max_m
    )
    term = None
    if h == ctx.H:
        term = np.abs(r - cfg.d_star_m) * (cfg.terminal_weight / cfg.d_star_m)
    w = ctx.w_list
    g_sum = geom[:, 0] * w[0]
    d_sum = dist[:, 0] * w[0]
    p_sum = pen[:, 0] * w[0]
    t_sum = term[:, 0] * w[0] if term is not None else np.zeros(n_pts)
    for col in range(1, ctx.L):
        g_sum = g_sum + geom[:, col] * w[col]
        d_sum = d_sum + dist[:, col] * w[col]
        p_sum = p_sum + pen[:, col] * w[col]
        if term is not None:
            t_sum = t_sum + term[:, col] * w[col]
    if ctx.k == 0:
        conn = np.zeros(n_pts)
        viol = np.zeros(n_pts)
    else:
        ox = px[:, None] - ctx.nbx[h]
        oy = py[:, None] - ctx.nby[h]
        rng = np.sqrt(ox * ox + oy * oy)
        lam = _fiedler(_link_weight(rng, ctx.ch), ctx.nb_w[h])
        conn = cfg.gamma / np.maximum(lam, LAMBDA_FLOOR)
        short = np.maximum(cfg.d_safe_m - rng, 0.0)
        viol = short[:, 0]
        for j in range(1, ctx.k):
            viol = viol + short[:, j]
    return (g_sum, d_sum, conn, p_sum, t_sum), viol


def _total(terms: tuple[np.ndarray, ...]) -> np.ndarray:
    g, d, c, p, t = terms
    return g + d + c + p + t


def _stage_cost(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    terms, viol = _stage(ctx, h, px, py)
    return _total(terms), viol


def _lower_bound(ctx: _Context, h: int, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Admissible lower bound (N,) of the cost of steps h+1..H from own positions (px, py) at step h.

    After j more steps the vehicle is within j * T_o * max(speed) of its position; each term is
    bounded over that disc: range terms exactly on the range interval (they are convex and
    piecewise linear in the range), geometry by the neighbours' bearings alone, connectivity by
    Fiedler's bound lambda_2 <= n / (n - 1) min_i L_ii with the own links at their shortest range.
    """
    cfg = ctx.cfg
    total = np.zeros(px.size)
    ds, dm = cfg.d_star_m, cfg.d_max_m

    def ranged(x: np.ndarray, last: bool) -> np.ndarray:
        v = x * ((1.0 - cfg.alpha) / ds) + cfg.soft_penalty * (
            np.maximum(ds - x, 0.0) / ds + np.maximum(x - dm, 0.0) / dm
        )
        if last:
            v = v + np.abs(x - ds) * (cfg.terminal_weight / ds)
        return v

    for hh in range(h + 1, ctx.H + 1):
        rho = ctx.r_step * (hh - h)
        dx = px[:, None] - ctx.tx[hh]
        dy = py[:, None] - ctx.ty[hh]
        r = np.sqrt(dx * dx + dy * dy)
        lo = np.maximum(r - rho, 0.0)
        hi = r + rho
        last = hh == ctx.H
        best = np.minimum(ranged(lo, last), ranged(hi, last))
        best = np.minimum(best, ranged(np.clip(ds, lo, hi), last))
        best = np.minimum(best, ranged(np.clip(dm, lo, hi), last))
        total = total + (best + ctx.geom_lb[hh]) @ ctx.w
        if ctx.k > 0:
            ox = px[:, None] - ctx.nbx[hh]
            oy = py[:, None] - ctx.nby[hh]
            w_up = _link_weight(np.maximum(np.sqrt(ox * ox + oy * oy) - rho, 0.0), ctx.ch)
            deg = np.minimum(w_up.sum(axis=1), np.min(ctx.nb_w[hh].sum(axis=1)[None, :] + w_up, axis=1))
            lam_up = deg * (ctx.n_agents / (ctx.n_agents - 1.0))
            total = total + cfg.gamma / np.maximum(lam_up, LAMBDA_FLOOR)
    return total


# ----------------------------------------------------------------------------- search


def _node_positions(ctx: _Context, g: _Graph) -> list[tuple[np.ndarray, np.ndarray]]:
    """Own position (x, y) of every position node, level by level (level 0 = now)."""
    vecs = np.array([ctx.step_vector(int(a), int(b)) for a, b in zip(g.type_g, g.type_speed, strict=True)] + [(0.0, 0.0)])
    out = [(np.array([ctx.p0[0]]), np.array([ctx.p0[1]]))]
    for h in range(1, ctx.H + 1):
        px, py = out[-1]
        par = g.pos_parent[h]
        t = g.pos_type[h]
        out.append((px[par] + vecs[t, 0], py[par] + vecs[t, 1]))
    return out


def _rollout(ctx: _Context, g: _Graph, pos: list, h: int, starts: np.ndarray, base: np.ndarray) -> float:
    """Best total cost of greedy completions (best next step each time) from states ``starts`` at level h."""
    cur = starts
    total = base.copy()
    for hh in range(h + 1, ctx.H + 1):
        kids = g.child[hh][cur]
        p = g.state_pos[hh][kids] if hh < ctx.H else kids
        px, py = pos[hh]
        cost, viol = _stage_cost(ctx, hh, px[p.ravel()], py[p.ravel()])
        cost = np.where(viol > 0.0, np.inf, cost).reshape(kids.shape)
        pick = np.argmin(cost, axis=1)
        rows = np.arange(kids.shape[0])
        total = total + cost[rows, pick]
        cur = kids[rows, pick]
    return float(np.min(total))


def _search(ctx: _Context, g: _Graph, pos: list) -> tuple[np.ndarray | None, int]:
    """Exact branch and bound over the merge graph; (indices, nodes evaluated), indices None if all infeasible."""
    H = ctx.H
    f_prev = np.zeros(1)
    expand = np.ones(1, dtype=bool)
    ub = np.inf
    nodes = 0
    costs: list[np.ndarray] = [np.zeros(1)]
    expanded: list[np.ndarray] = [expand]
    for h in range(1, H + 1):
        kids = g.child[h][expand]
        n_pos = g.pos_parent[h].size
        need = np.zeros(n_pos, dtype=bool)
        need[(g.state_pos[h][kids] if h < H else kids).ravel()] = True
        idx = np.flatnonzero(need)
        nodes += idx.size
        px, py = pos[h]
        c, viol = _stage_cost(ctx, h, px[idx], py[idx])
        cost = np.full(n_pos, np.inf)
        cost[idx] = np.where(viol > 0.0, np.inf, c)
        costs.append(cost)
        if h == H:
            break
        f = cost[g.state_pos[h]] + np.minimum.reduceat(f_prev[g.in_parent[h]], g.in_start[h])
        live = np.isfinite(f)
        if ctx.can_prune and np.any(live):
            lb_pos = np.zeros(n_pos)
            lb_pos[idx] = _lower_bound(ctx, h, px[idx], py[idx])
            bound = f + lb_pos[g.state_pos[h]]
            cand = np.flatnonzero(live)
            top = cand[np.argsort(bound[cand], kind="stable")[:_ROLLOUTS]]
            ub = min(ub, _rollout(ctx, g, pos, h, top, f[top]))
            expand = live & (bound <= ub + _PRUNE_RTOL * max(1.0, abs(ub)))
        else:
            expand = live
        expanded.append(expand)
        f_prev = f
    # backward values over the expanded states, then the lexicographically smallest optimal path
    values: list[np.ndarray] = [np.zeros(0)] * (H + 1)
    values[H] = costs[H]
    for h in range(H - 1, -1, -1):
        v = np.full(expanded[h].size, np.inf)
        sel = np.flatnonzero(expanded[h])
        best = values[h + 1][g.child[h + 1][sel]].min(axis=1)
        v[sel] = costs[h][g.state_pos[h][sel]] + best if h > 0 else best
        values[h] = v
    if not np.isfinite(values[0][0]):
        return None, nodes
    return _extract(g, values, None, H), nodes


def _extract(g: _Graph, values: list[np.ndarray], second: list[np.ndarray] | None, H: int) -> np.ndarray:
    """Lexicographically smallest index sequence following minimal backward values (then ``second``)."""
    s = 0
    out = np.empty(H, dtype=np.int64)
    for h in range(1, H + 1):
        kids = g.child[h][s]
        v = values[h][kids]
        if second is not None:
            v2 = np.where(v == v.min(), second[h][kids], np.inf)
            u = int(np.argmin(v2))
        else:
            u = int(np.argmin(v))
        out[h - 1] = u
        s = int(kids[u])
    return out


def _fallback(ctx: _Context, g: _Graph, pos: list) -> tuple[np.ndarray, int]:
    """All sequences infeasible: minimise the total safety violation, then the cost (exact, no pruning)."""
    H = ctx.H
    costs: list[np.ndarray] = [np.zeros(1)]
    viols: list[np.ndarray] = [np.zeros(1)]
    nodes = 0
    for h in range(1, H + 1):
        px, py = pos[h]
        c, v = _stage_cost(ctx, h, px, py)
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
    """Own positions (H, 2) along a control index sequence, on the heading lattice."""
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


_TERM_NAMES = ("geometry", "distance", "connectivity", "penalty", "terminal")


def _make_plan(ctx: _Context, indices: np.ndarray, nodes: int) -> Plan:
    way = _path(ctx, indices)
    sums = dict.fromkeys(_TERM_NAMES, 0.0)
    cost = 0.0
    violation = 0.0
    for h in range(1, ctx.H + 1):
        terms, viol = _stage(ctx, h, way[h - 1 : h, 0], way[h - 1 : h, 1])
        for name, val in zip(_TERM_NAMES, terms, strict=True):
            sums[name] += float(val[0])
        cost += float(_total(terms)[0])
        violation += float(viol[0])
    sums["safety_violation_m"] = violation
    a, s = np.divmod(indices, ctx.n_speed)
    controls = np.column_stack([ctx.dtheta[a], ctx.speeds[s]])
    return Plan(
        controls=controls,
        indices=indices.astype(np.int64),
        cost=cost,
        terms=sums,
        feasible=violation == 0.0,
        waypoints=way,
        nodes=nodes,
    )


def plan(problem: PlanProblem) -> Plan:
    """Exact minimiser of eq. (38) subject to eq. (50) over all |U|^H control sequences (eqs. 29-31, 43).

    Forward dynamic programming over merged states with branch and bound: the cost of step h
    depends only on this agent's position at step h (neighbours and target are fixed), and a
    position is an order-independent integer combination of step vectors on the heading grid, so
    sequences reaching the same (position, heading) share one state (graph cached per control-set
    shape and H). States whose cost so far plus an admissible lower bound of the remaining cost
    exceed the best complete sequence found by greedy completions are not expanded. The optimum
    is then read back with backward values; among exactly equal costs the lexicographically
    smallest index sequence wins.
    """
    ctx = _Context(problem)
    g = _graph(ctx.m, ctx.wrap, ctx.speed_class, ctx.H)
    pos = _node_positions(ctx, g)
    indices, nodes = _search(ctx, g, pos)
    if indices is None:
        indices, extra = _fallback(ctx, g, pos)
        nodes += extra
    return _make_plan(ctx, indices, nodes)


def brute_force(problem: PlanProblem, chunk: int = 1 << 15) -> Plan:
    """Reference search: evaluates every one of the |U|^H sequences (prefixes shared, no merging).

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
        c = np.empty(gx.size)
        v = np.empty(gx.size)
        for lo in range(0, gx.size, chunk):
            c[lo : lo + chunk], v[lo : lo + chunk] = _stage_cost(ctx, h, gx[lo : lo + chunk], gy[lo : lo + chunk])
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
