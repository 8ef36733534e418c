"""Ground truth: target motion, vehicle kinematics and the bearing sensor, eqs. (1)-(4).

Frames and units: inertial 2-D frame, positions in metres, headings and bearings in
radians measured from +x counter-clockwise and wrapped to (-pi, pi], speeds in m/s,
turn rates in rad/s, time in seconds of simulated time. Pure: time and a numpy
``Generator`` are passed in; no clock, no global RNG, no I/O.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import jv

from auv_swarm.contract.config import Scenario, TargetConfig
from auv_swarm.contract.geometry import wrap_angle
from auv_swarm.world import manoeuvre
from auv_swarm.world.navigation import DeadReckoning

_TWO_PI = 2.0 * math.pi
_SPAWN_RESTARTS = 40
_SPAWN_BATCH = 256
_SPAWN_RESTARTS_GROWN = 10
_SPAWN_GROWTH = 1.25
_SPAWN_GROWTHS = 20
_TIME_TOL_S = 1e-9


def bearing(sensor_xy: ArrayLike, target_xy: ArrayLike) -> float | np.ndarray:
    """True bearing of eq. (2): atan2(p_y - p_s,y, p_x - p_s,x), in (-pi, pi]; positions (..., 2) in m.

    Coincident positions give 0.0 (never NaN).
    """
    s = np.asarray(sensor_xy, dtype=float)
    t = np.asarray(target_xy, dtype=float)
    return wrap_angle(np.arctan2(t[..., 1] - s[..., 1], t[..., 0] - s[..., 0]))


def measure_bearing(
    sensor_xy: ArrayLike,
    target_xy: ArrayLike,
    sigma_m_rad: float,
    outlier_rate: float,
    rng: np.random.Generator,
) -> float:
    """One noisy bearing of eq. (4): h = beta + nu, nu ~ U[-sigma_m, +sigma_m], wrapped to (-pi, pi].

    With probability ``outlier_rate`` the bearing is replaced by a uniform draw in
    (-pi, pi]. Every call consumes exactly three variates (noise, outlier coin,
    outlier value) in that order, so random streams stay aligned whatever happens.
    """
    if not (math.isfinite(sigma_m_rad) and sigma_m_rad >= 0.0):
        raise ValueError(f"sigma_m_rad must be in [0, inf) rad, got {sigma_m_rad!r}")
    if not (0.0 <= outlier_rate <= 1.0):
        raise ValueError(f"outlier_rate must be in [0, 1], got {outlier_rate!r}")
    noise = rng.uniform(-sigma_m_rad, sigma_m_rad)
    coin = rng.random()
    outlier = math.pi - _TWO_PI * rng.random()
    if coin < outlier_rate:
        return float(outlier)
    return float(wrap_angle(bearing(sensor_xy, target_xy) + noise))


def vehicle_step(
    state: ArrayLike,
    u: ArrayLike,
    r: ArrayLike,
    dt: float,
    u_max: float,
    r_max: float,
) -> np.ndarray:
    """Integrate the unicycle kinematics of eq. (1) exactly over ``dt`` s with constant (u, r).

    ``state`` is (x, y, theta) in m, m, rad (shape (3,) or (..., 3)). The surge speed is
    clamped to [0, u_max] m/s (AUVs do not reverse) and the turn rate to [-r_max, r_max]
    rad/s. The arc is integrated in chord form, p' = p + u dt sinc(r dt / 2)
    [cos(theta + r dt/2), sin(theta + r dt/2)], which is exact for every r and reduces to
    a straight line as r -> 0 without cancellation. The new heading is wrapped to (-pi, pi].
    """
    if not (math.isfinite(dt) and dt >= 0.0):
        raise ValueError(f"dt must be in [0, inf) s, got {dt!r}")
    if not (math.isfinite(u_max) and u_max >= 0.0):
        raise ValueError(f"u_max must be in [0, inf) m/s, got {u_max!r}")
    if not (math.isfinite(r_max) and r_max >= 0.0):
        raise ValueError(f"r_max must be in [0, inf) rad/s, got {r_max!r}")
    s = np.asarray(state, dtype=float)
    if s.shape[-1:] != (3,):
        raise ValueError(f"state must have shape (..., 3) = (x, y, theta), got {s.shape}")
    uc = np.asarray(u, dtype=float).clip(0.0, u_max)
    rc = np.asarray(r, dtype=float).clip(-r_max, r_max)
    if not (np.isfinite(uc).all() and np.isfinite(rc).all()):
        raise ValueError("u and r must be finite")
    half_turn = 0.5 * rc * dt
    chord = uc * dt * np.sinc(half_turn / math.pi)
    mid = s[..., 2] + half_turn
    out = np.empty(np.broadcast(s[..., 0], chord).shape + (3,), dtype=float)
    out[..., 0] = s[..., 0] + chord * np.cos(mid)
    out[..., 1] = s[..., 1] + chord * np.sin(mid)
    out[..., 2] = wrap_angle(s[..., 2] + 2.0 * half_turn)
    return out


def _pairs(first: ArrayLike, second: ArrayLike) -> np.ndarray:
    """``first`` and ``second`` (same shape) side by side on a new last axis of length 2."""
    out = np.empty(np.shape(first) + (2,))
    out[..., 0] = first
    out[..., 1] = second
    return out


def _bessel_order(amplitude: float) -> int:
    """Truncation order of the Jacobi-Anger series for |J_n(a)| below 1e-30 beyond it."""
    return int(math.ceil(amplitude + 12.0 * amplitude ** (1.0 / 3.0) + 40.0))


class TargetTrajectory:
    """Ground-truth motion of the acoustic source (eq. (3) and Table 2), exact in closed form.

    Models (``cfg.model``), with p0 = ``cfg.position_m``, v_n = ``cfg.speed_mps``,
    theta_0 = heading, a = ``cfg.amplitude``, omega = ``cfg.omega_radps``:

    - ``static``: p(t) = p0.
    - ``constant_velocity`` (eq. 3): p(t) = p0 + v_n t [cos theta_0, sin theta_0].
    - ``oscillating`` (Table 2 read as a heading oscillation): heading
      psi(t) = theta_0 + a sin(omega t + pi), speed v_n, p(t) = p0 + integral of
      v_n [cos psi, sin psi]. Integrated exactly by the Jacobi-Anger expansion
      exp(-i a sin(omega s)) = sum_k J_k(a) exp(-i k omega s).
    - ``oscillating_literal`` (the paper's formula, not rotated by any heading):
      p(t) = p0 + [a sin(omega t + pi), v_n t] for axis "y", p0 + [v_n t, a sin(omega t + pi)]
      for axis "x"; velocity is its time derivative.

    - ``waypoints``, ``stop_and_go``, ``constant_turn``, ``random_turn``: manoeuvring sources made of
      arcs and legs of constant speed and turn rate (``world.manoeuvre``), built up to ``duration_s``
      (after that the last speed and turn rate hold); ``random_turn`` draws from ``rng``.

    With ``cfg.random_heading`` theta_0 is drawn once, uniformly in (-pi, pi], from ``rng`` (before
    any random_turn draw).
    """

    def __init__(self, cfg: TargetConfig, rng: np.random.Generator | None = None, duration_s: float = 1e4) -> None:
        self.cfg = cfg
        if cfg.random_heading or cfg.model == "random_turn":
            if rng is None:
                raise ValueError(f"rng must be a numpy Generator for target.model {cfg.model!r} or random_heading")
        if cfg.random_heading:
            self.heading_rad = math.pi - _TWO_PI * float(rng.random())
        else:
            self.heading_rad = float(cfg.heading_rad)
        self.p0 = np.array(cfg.position_m, dtype=float)
        self._segments: manoeuvre.Segments | None = None
        if cfg.model == "waypoints":
            self._segments = manoeuvre.waypoints(cfg, self.p0, self.heading_rad, duration_s)
        elif cfg.model == "stop_and_go":
            self._segments = manoeuvre.stop_and_go(cfg, self.p0, self.heading_rad, duration_s)
        elif cfg.model == "constant_turn":
            self._segments = manoeuvre.constant_turn(cfg, self.p0, self.heading_rad)
        elif cfg.model == "random_turn":
            self._segments = manoeuvre.random_turn(cfg, self.p0, self.heading_rad, duration_s, rng)
        if self._segments is not None:
            self._segments.freeze()
        if cfg.model == "oscillating":
            order = _bessel_order(cfg.amplitude)
            self._k = np.arange(-order, order + 1, dtype=float)
            self._jk = jv(self._k, cfg.amplitude)
            self._kw = self._k * cfg.omega_radps
            self._v_rot = cfg.speed_mps * np.exp(1j * self.heading_rad)

    def state(self, t: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and velocity (m/s) at sim time ``t`` (s); shapes t.shape + (2,)."""
        tt = np.asarray(t, dtype=float)
        if not np.isfinite(tt).all():
            raise ValueError(f"t must be finite (s), got {t!r}")
        cfg = self.cfg
        v, a, w, th = cfg.speed_mps, cfg.amplitude, cfg.omega_radps, self.heading_rad
        shape = tt.shape + (2,)
        if self._segments is not None:
            return self._segments.state(tt)
        if cfg.model == "static":
            return np.broadcast_to(self.p0, shape).copy(), np.zeros(shape)
        if cfg.model == "constant_velocity":
            vel = np.broadcast_to(v * np.array([math.cos(th), math.sin(th)]), shape).copy()
            return self.p0 + tt[..., None] * vel, vel
        if cfg.model == "oscillating":
            # integral_0^t exp(-i k w s) ds = t exp(-i k w t / 2) sinc(k w t / (2 pi)), exact also for k w = 0
            x = tt[..., None] * self._kw
            integral = tt[..., None] * np.exp(-0.5j * x) * np.sinc(x / _TWO_PI)
            z = self._v_rot * (integral @ self._jk)
            psi = th + a * np.sin(w * tt + math.pi)
            return self.p0 + _pairs(z.real, z.imag), v * _pairs(np.cos(psi), np.sin(psi))
        osc = a * np.sin(w * tt + math.pi)
        dosc = a * w * np.cos(w * tt + math.pi)
        nominal = v * tt
        if cfg.axis == "y":
            pos = _pairs(osc, nominal)
            vel = _pairs(dosc, np.full_like(tt, v))
        else:
            pos = _pairs(nominal, osc)
            vel = _pairs(np.full_like(tt, v), dosc)
        return self.p0 + pos, vel


def initial_agent_states(scenario: Scenario, rng: np.random.Generator) -> np.ndarray:
    """Initial AUV states (n, 3) = (x, y, theta) in m, m, rad.

    Uses ``agents.positions_m`` / ``agents.headings_rad`` when given. Otherwise draws
    positions uniformly in ``agents.spawn_box_m`` with every pairwise distance
    >= ``planner.d_safe_m`` (sequential rejection sampling, bounded number of tries).
    When the team does not fit, the box grows about its centre by ``_SPAWN_GROWTH``
    per try (so the spawn area grows with ``agents.count``; a team that fits the
    configured box is placed exactly as before); ValueError if no placement is found
    after ``_SPAWN_GROWTHS`` growths. Headings default to 0.
    """
    ag = scenario.agents
    n = ag.count
    states = np.zeros((n, 3))
    if ag.headings_rad:
        states[:, 2] = wrap_angle(np.asarray(ag.headings_rad, dtype=float))
    if ag.positions_m:
        states[:, :2] = np.asarray(ag.positions_m, dtype=float)
        return states
    lo = np.array(ag.spawn_box_m[:2], dtype=float)
    hi = np.array(ag.spawn_box_m[2:], dtype=float)
    centre = 0.5 * (lo + hi)
    d_safe = scenario.planner.d_safe_m
    for growth in range(_SPAWN_GROWTHS + 1):
        scale = _SPAWN_GROWTH**growth
        box_lo, box_hi = centre + scale * (lo - centre), centre + scale * (hi - centre)
        width, height = box_hi - box_lo
        if n * math.pi * (0.5 * d_safe) ** 2 > (width + d_safe) * (height + d_safe):
            continue  # disks of radius d_safe/2 about each AUV cannot fit: no placement exists
        restarts = _SPAWN_RESTARTS if growth == 0 else _SPAWN_RESTARTS_GROWN
        placed = _place(n, box_lo, box_hi, d_safe, rng, restarts)
        if placed is not None:
            states[:, :2] = placed
            return states
    raise ValueError(
        f"agents.spawn_box_m {list(ag.spawn_box_m)} is too small to place agents.count = {n} AUVs "
        f"at least planner.d_safe_m = {d_safe:g} m apart, even grown {scale:.0f} times; lower d_safe_m"
    )


def _place(
    n: int, lo: np.ndarray, hi: np.ndarray, d_safe: float, rng: np.random.Generator, restarts: int
) -> np.ndarray | None:
    """``n`` positions (n, 2) drawn uniformly in the box [lo, hi], pairwise >= ``d_safe`` m apart, by sequential
    rejection sampling with at most ``restarts`` restarts; None when none was found."""
    for _ in range(restarts):
        placed: list[np.ndarray] = []
        for _i in range(n):
            cand = rng.uniform(lo, hi, size=(_SPAWN_BATCH, 2))
            if placed:
                prev = np.array(placed)
                dist = np.hypot(*(cand[:, None, :] - prev[None, :, :]).transpose(2, 0, 1))
                ok = np.flatnonzero(np.all(dist >= d_safe, axis=1))
            else:
                ok = np.array([0])
            if ok.size == 0:
                break
            placed.append(cand[ok[0]])
        if len(placed) == n:
            return np.array(placed)
    return None


def world_streams(rng: np.random.Generator) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """The world's independent streams split from ``rng`` (``Generator.spawn``): the spawn placement, the target
    (random heading and turns) and the bearing sensor."""
    spawn_rng, target_rng, sensor_rng = rng.spawn(3)
    return spawn_rng, target_rng, sensor_rng


class WorldModel:
    """The world's pure core: target truth, AUV kinematics, bearing sensor, scheduled failures.

    Both the world process and the in-process runner drive it with ``set_command`` /
    ``sense`` / ``advance``. Time advances in ticks of ``run.tick_s``; ``time_s`` is
    ``tick * tick_s`` exactly. ``rng`` is split (``Generator.spawn``) into independent
    streams for the spawn placement, the target's random heading and the sensor, so
    changing one never shifts the others.
    """

    def __init__(
        self, scenario: Scenario, rng: np.random.Generator, nav_rng: np.random.Generator | None = None
    ) -> None:
        """``nav_rng``: the navigation's own stream (``world.navigation``), needed unless navigation is perfect."""
        self.scenario = scenario
        spawn_rng, target_rng, self._sensor_rng = world_streams(rng)
        self.trajectory = TargetTrajectory(scenario.target, target_rng, scenario.run.duration_s)
        init = initial_agent_states(scenario, spawn_rng)
        self.ids: tuple[int, ...] = tuple(range(scenario.agents.count))
        self.states: dict[int, np.ndarray] = {i: init[i].copy() for i in self.ids}
        self.alive: set[int] = set(self.ids)
        self.commands: dict[int, tuple[float, float]] = {i: (0.0, 0.0) for i in self.ids}
        self.tick: int = 0
        self._sensor_every = max(1, round(scenario.sensor.period_s / scenario.run.tick_s))
        self._sigma_rad = math.radians(scenario.sensor.sigma_m_deg)
        self._pending_kills = sorted(scenario.kills, key=lambda k: (k.time_s, k.agent))
        self._target_at: tuple[int, tuple[np.ndarray, np.ndarray]] | None = None
        self.navigation: DeadReckoning | None = None
        """Each AUV's dead reckoning; None under perfect navigation (the believed pose is the true one)."""
        if not scenario.navigation.perfect:
            if nav_rng is None:
                raise ValueError("nav_rng must be a numpy Generator when navigation is not perfect")
            self.navigation = DeadReckoning(scenario.navigation, self.ids, nav_rng)

    @property
    def time_s(self) -> float:
        """Sim time now (s): tick * run.tick_s."""
        return self.tick * self.scenario.run.tick_s

    def target(self) -> tuple[np.ndarray, np.ndarray]:
        """Target position (m) and velocity (m/s) now, each shape (2,) (evaluated once per tick)."""
        if self._target_at is None or self._target_at[0] != self.tick:
            self._target_at = (self.tick, self.trajectory.state(self.time_s))
        pos, vel = self._target_at[1]
        return pos.copy(), vel.copy()

    def measurement_due(self) -> bool:
        """True when sim time is a multiple of sensor.period_s."""
        return self.tick % self._sensor_every == 0

    def sense(self) -> dict[int, float | None]:
        """Bearings (rad, eq. (4)) of the target from every alive AUV at the current time.

        When a measurement is due, a bearing is drawn for every agent id in sorted order,
        alive or not, so the sensor stream does not depend on failures; a bearing beyond
        sensor.max_range_m is drawn and discarded (None). When no measurement is due all
        values are None and nothing is drawn. Only alive agents are in the result. With a compass bias
        (``navigation.heading_bias_deg``) each bearing is turned by it, as the AUV measures it.
        """
        if not self.measurement_due():
            return {i: None for i in sorted(self.alive)}
        sensor = self.scenario.sensor
        target_xy, _ = self.target()
        out: dict[int, float | None] = {}
        for i in self.ids:
            xy = self.states[i][:2]
            b = measure_bearing(xy, target_xy, self._sigma_rad, sensor.outlier_rate, self._sensor_rng)
            if self.navigation is not None:
                b = self.navigation.bearing(b)
            if i in self.alive:
                in_range = math.hypot(*(target_xy - xy)) <= sensor.max_range_m
                out[i] = b if in_range else None
        return out

    def believed(self, agent: int) -> np.ndarray:
        """The pose (x m, y m, theta rad) ``agent`` believes it has: its true state under perfect navigation."""
        if self.navigation is None:
            return self.states[agent]
        return self.navigation.believed(agent, self.states[agent])

    def _check_agent(self, agent: int) -> None:
        if agent not in self.states:
            raise ValueError(f"agent must be in [0, {len(self.ids) - 1}], got {agent!r}")

    def set_command(self, agent: int, u: float, r: float) -> None:
        """Hold the command (u m/s, r rad/s) for ``agent``; stored clamped to [0, u_max] x [-r_max, r_max]."""
        self._check_agent(agent)
        if not (math.isfinite(u) and math.isfinite(r)):
            raise ValueError(f"u and r must be finite, got u={u!r}, r={r!r}")
        ag = self.scenario.agents
        self.commands[agent] = (
            min(max(float(u), 0.0), ag.u_max_mps),
            min(max(float(r), -ag.r_max_radps), ag.r_max_radps),
        )

    def kill(self, agent: int) -> bool:
        """Stop ``agent`` for good (it keeps its last state); True if it was alive."""
        self._check_agent(agent)
        was_alive = agent in self.alive
        self.alive.discard(agent)
        return was_alive

    def revive(self, agent: int) -> bool:
        """Bring ``agent`` back (a restarted AUV) where it stopped, at rest; True if it was dead."""
        self._check_agent(agent)
        was_dead = agent not in self.alive
        self.alive.add(agent)
        self.commands[agent] = (0.0, 0.0)
        return was_dead

    def advance(self) -> list[int]:
        """Move every alive AUV over one tick with its held command (and its dead reckoning), make a position fix
        when one is due, then apply due scheduled kills.

        A kill scheduled at time t takes effect at the first tick boundary >= t (one-tick
        resolution). Returns the ids killed by this call, sorted.
        """
        ag = self.scenario.agents
        dt = self.scenario.run.tick_s
        moving = sorted(self.alive)
        if moving:
            states = np.array([self.states[i] for i in moving])
            u, r = np.array([self.commands[i] for i in moving]).T
            moved = vehicle_step(states, u, r, dt, ag.u_max_mps, ag.r_max_radps)
            for i, new in zip(moving, moved, strict=True):
                self.states[i] = new
            if self.navigation is not None:
                self.navigation.move(moving, moved[:, :2] - states[:, :2])
        self.tick += 1
        now = self.time_s
        while self.navigation is not None and self.navigation.fix_due(now):
            self.navigation.fix()
        killed: list[int] = []
        while self._pending_kills and self._pending_kills[0].time_s <= now + _TIME_TOL_S:
            event = self._pending_kills.pop(0)
            if self.kill(event.agent):
                killed.append(event.agent)
        return sorted(killed)
