"""Everything of one planning problem that does not depend on the own control sequence, and the link model.

Sigma points propagated over the horizon (eqs. 32-33, 50), the neighbours' predicted positions
and bearings to every sigma point, the link weights of eqs. (22)-(26) and lambda_2 (eq. 26).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from auv_swarm.agent.planner.problem import MIN_BEARING_RANGE_M, SIGMA_FLOOR, PlanProblem, sigma_points
from auv_swarm.contract import acoustics

_R2_MIN = MIN_BEARING_RANGE_M**2

# ----------------------------------------------------------------------------- per-problem context


class Context:
    """Everything of one problem that does not depend on the own control sequence."""

    def __init__(self, problem: PlanProblem) -> None:
        cfg = problem.planner
        self.cfg = cfg
        self.ch = problem.channel
        self.link = problem.link
        self.H = int(cfg.horizon)
        self.T = float(cfg.step_s)
        self.p0 = (float(problem.position[0]), float(problem.position[1]))
        self.theta0 = float(problem.heading)
        cs = problem.controls
        self.dtheta = cs.dtheta
        self.speeds = cs.speeds
        self.n_speed = cs.speeds.size
        self.n_u = cs.size
        self._heading_lattice(cs.dtheta)
        self._speed_classes(cs.speeds)
        self._target_belief(problem)
        self._neighbours(problem)
        self._bearing_sums()
        self._link_model()
        self._geometry_bound()
        # eq. (50)'s d_S and d* also along the first leg (p0 -> p_1), the one executed before the next plan
        self.leg = problem.leg_rule
        self.r_max = float(cs.r_max)
        self.worst = cfg.range_constraint == "worst"
        self.r_step = self.T * float(np.max(self.speeds))
        self.c_dist = (1.0 - cfg.alpha) / cfg.d_star_m
        self.c_term = cfg.terminal_weight / cfg.d_star_m
        self.inv_ds = 1.0 / cfg.d_star_m
        self.inv_dm = 1.0 / cfg.d_max_m
        self._steps: dict[tuple[int, int], tuple[float, float]] = {}
        self.steps = (np.zeros(1), np.zeros(1))  # x and y of each step type of the merge graph (search.plan)

    def _heading_lattice(self, dtheta: np.ndarray) -> None:
        """dtheta[a] = m[a] * unit (eq. 48), headings theta0 + g * unit; ``wrap`` classes make a full turn (0:
        the headings never meet again)."""
        n_h = dtheta.size
        d = float(dtheta[-1])
        if n_h == 1 or d == 0.0:
            self.m = tuple(0 for _ in range(n_h))
            self.unit = 0.0
            self.wrap = 1
        else:
            self.m = tuple(2 * a - (n_h - 1) for a in range(n_h))
            self.unit = d / (n_h - 1)
            turns = 2.0 * math.pi / self.unit
            self.wrap = int(round(turns)) if abs(turns - round(turns)) <= 1e-9 * turns else 0

    def _speed_classes(self, speeds: np.ndarray) -> None:
        """Speed class of each speed index: the first index of that speed, -1 for standing still."""
        first: dict[float, int] = {}
        classes = []
        for s, v in enumerate(speeds.tolist()):
            classes.append(-1 if v == 0.0 else first.setdefault(v, s))
        self.speed_class = tuple(classes)

    def _target_belief(self, problem: PlanProblem) -> None:
        """Sigma points (eqs. 32-33) propagated with F (eq. 50) to every level h = 0..H: tx, ty (H+1, L) in m."""
        pts, w = sigma_points(problem.xi, problem.P, self.cfg.w0)
        self.w = w
        self.L = w.size
        hs = np.arange(self.H + 1)[:, None] * self.T
        self.tx = pts[None, :, 0] + hs * pts[None, :, 2]
        self.ty = pts[None, :, 1] + hs * pts[None, :, 3]
        self.tx0 = self.tx[:, 0].copy()
        self.ty0 = self.ty[:, 0].copy()
        self.w_rest = float(np.sum(w[1:]))

    def _neighbours(self, problem: PlanProblem) -> None:
        """The neighbours' predicted positions nbx, nby (H+1, k) (level 0 = now), their distances at the plan start
        (or the anchor) for the formation readings, and the connectivity scales of eq. (37)."""
        cfg = self.cfg
        nbs = problem.neighbours
        self.k = len(nbs)
        self.n_agents = self.k + 1
        nb_pos = np.zeros((self.H + 1, self.k, 2))
        for j, nb in enumerate(nbs):
            nb_pos[0, j] = nb.position
            nb_pos[1:, j] = nb.trajectory(self.T)
        self.nbx = nb_pos[:, :, 0]
        self.nby = nb_pos[:, :, 1]
        # pair distances (k,) at the plan start, for planner.connectivity = "formation"
        self.nb_r0 = np.hypot(self.nbx[0] - self.p0[0], self.nby[0] - self.p0[1])
        if problem.anchor_m is not None:
            self.nb_r0 = np.array(problem.anchor_m, dtype=float)
        self.formation = cfg.connectivity in ("formation", "topology")
        self.c_form = cfg.gamma / cfg.d_star_m
        # eq. (37) sums gamma / lambda_2 over the |N_i| = k neighbours; lambda_2 is the whole graph's
        self.c_conn = cfg.gamma * self.k

    def _bearing_sums(self) -> None:
        """The neighbours' unit bearings to every sigma point (H+1, L) per neighbour, and their sums zr, zi and
        pair term of the Fisher information, without the own vehicle (eqs. 34-35)."""
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

    def _link_model(self) -> None:
        """The link model of eqs. (22)-(26) (a physical ocean's, if any) and the neighbour-neighbour link weights
        nb_w (H+1, k, k)."""
        ch = self.ch
        self.snr_at_1m = ch.source_level_db - ch.noise_level_db + ch.directivity_index_db
        self.absorption_db_per_m = _absorption_db_per_m(ch.frequency_khz)
        rho_m = acoustics.snr_max_db(ch)
        self.inv_snr_max = 1.0 / rho_m if rho_m > 0.0 else 1.0
        dxx = self.nbx[:, :, None] - self.nbx[:, None, :]
        dyy = self.nby[:, :, None] - self.nby[:, None, :]
        self.nb_w = link_weight(self, np.sqrt(dxx * dxx + dyy * dyy))
        idx = np.arange(self.k)
        self.nb_w[:, idx, idx] = 0.0

    def _geometry_bound(self) -> None:
        """An upper bound of sigma_min per (level, sigma point), for the lower bounds of the pruning."""
        zabs = np.sqrt(self.zr * self.zr + self.zi * self.zi)
        if self.n_agents == 1:
            sig_up = np.ones(self.zr.shape)
        else:
            sig_up = np.sqrt(np.maximum(self.n_agents - np.abs(zabs - 1.0), 0.0) / 2.0 + 1e-9)
            sig_up = np.where(self.nb_undefined, 0.0, sig_up)
        self.geom_lb_w = (self.cfg.alpha / np.maximum(sig_up, SIGMA_FLOOR)) @ self.w
        self.can_prune = bool(np.all(self.w >= 0.0))

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


def link_weight(ctx: Context, range_m: np.ndarray) -> np.ndarray:
    """Normalised link weight rho / rho_M of eqs. (22)-(26) for ranges in m; 0 below DT or at rho <= 0 dB.

    Same link model as ``contract.acoustics.snr_laplacian`` (range clamped to ``MIN_RANGE_M`` in
    eq. 23), evaluated without per-call validation because the planner calls it on large batches; a physical
    ocean's link model (``ctx.link``) when the problem has one.
    """
    if ctx.link is not None:
        return ctx.link.weight(range_m)
    d = np.maximum(range_m, acoustics.MIN_RANGE_M)
    rho = ctx.snr_at_1m - (np.log10(d) * 20.0 + d * ctx.absorption_db_per_m)
    dt = ctx.ch.detection_threshold_db
    off = rho < dt if dt > 0.0 else rho <= 0.0
    return np.where(off, 0.0, rho * ctx.inv_snr_max)


def link_weight_bound(ctx: Context, range_m: np.ndarray) -> np.ndarray:
    """An upper bound of :func:`link_weight` over every range at or beyond ``range_m`` (m): the weight itself on
    the paper's link budget (it falls with range), the ocean's bound from TL's floor otherwise (a TL table need
    not grow with range)."""
    if ctx.link is not None:
        return ctx.link.weight_bound(range_m)
    return link_weight(ctx, range_m)


def fiedler(own_w: np.ndarray, nb_w: np.ndarray) -> np.ndarray:
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
        q3 = (a * b + (a + b) * c) * 3.0
        spread = (((a - b) * (a - b) + (a - c) * (a - c)) + (b - c) * (b - c)) * 0.5
        den = np.sqrt(spread) + ((a + b) + c)
        return np.divide(q3, den, out=np.zeros(q3.shape), where=den > 0.0)
    own_w = np.ascontiguousarray(own_w)
    lap = np.zeros((n_pts, k + 1, k + 1))
    lap[:, 0, 1:] = -own_w
    lap[:, 1:, 0] = -own_w
    lap[:, 0, 0] = own_w.sum(axis=1)
    lap[:, 1:, 1:] = -nb_w
    idx = np.arange(1, k + 1)
    lap[:, idx, idx] = nb_w.sum(axis=2) + own_w
    return np.maximum(np.linalg.eigvalsh(lap)[:, 1], 0.0)
