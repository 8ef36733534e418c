"""The sections of a scenario (``[target]``, ``[agents]``, ``[sensor]``, ``[channel]``, ``[ocean]``,
``[estimator]``, ``[planner]``, ``[navigation]``, ``[run]``): every key declared once with its meaning, unit and
allowed range.

:class:`~auv_swarm.contract.config.Scenario` puts them together, loads and checks them; import them from
:mod:`auv_swarm.contract.config`. Symbols refer to Table 1 and Table 2 of the paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from auv_swarm.contract import methods
from auv_swarm.contract.modem import MODEMS
from auv_swarm.contract.params import MAX_AGENTS, MAX_HORIZON, param
from auv_swarm.contract.seabed import SEABEDS


@dataclass(frozen=True)
class TargetConfig:
    """The acoustic source's ground-truth motion (paper sections 3.1-3.3, Table 2)."""

    model: str = param(
        "constant_velocity",
        "motion model: constant_velocity (eq. 3); oscillating (Table 2 read as a heading "
        "oscillation, heading(t) = heading + amplitude*sin(omega*t + pi), speed constant); "
        "oscillating_literal (p(t) = p0 + [amplitude*sin(omega*t+pi), speed*t] along axis); manoeuvring "
        "(world/manoeuvre.py): waypoints (follow waypoints_m at leg_speeds_mps, turns of turn_radius_m), "
        "stop_and_go (go_s at speed, stop_s stopped, turn stop_turn_rad), constant_turn (turn_rate_radps), "
        "random_turn (seeded: a new turn rate in +/- speed/turn_radius_m, or straight, every "
        "manoeuvre_interval_s on average)",
        choices=(
            "constant_velocity",
            "oscillating",
            "oscillating_literal",
            "static",
            "waypoints",
            "stop_and_go",
            "constant_turn",
            "random_turn",
        ),
    )
    position_m: tuple[float, float] = param((0.0, 0.0), "initial position [x, y] (m, inertial frame)")
    speed_mps: float = param(0.0, "nominal speed v_n (m/s)", lo=0.0, hi=50.0)
    heading_rad: float = param(0.0, "initial heading theta_0 (rad, from +x, counter-clockwise)", lo=-10.0, hi=10.0)
    random_heading: bool = param(False, "draw the initial heading uniformly from the scenario seed (section 3.2)")
    amplitude: float = param(
        0.0, "oscillation amplitude a (rad for oscillating, m for oscillating_literal)", lo=0.0, hi=1e4
    )
    omega_radps: float = param(0.0, "oscillation angular rate omega (rad/s)", lo=0.0, hi=10.0)
    axis: str = param("y", "oscillating_literal only: axis of the nominal motion v_n*t", choices=("x", "y"))
    waypoints_m: tuple[tuple[float, float], ...] = param(
        (), "waypoints only: [[x, y], ...] visited in order from position_m (m)", factory=tuple
    )
    leg_speeds_mps: tuple[float, ...] = param(
        (), "waypoints only: speed on the leg to each waypoint (m/s); empty = speed_mps on every leg", factory=tuple
    )
    loop: bool = param(False, "waypoints only: after the last waypoint start again from the first")
    turn_radius_m: float = param(30.0, "waypoints and random_turn: smallest turn radius (m)", lo=1.0, hi=1e5)
    turn_rate_radps: float = param(
        0.0, "constant_turn only: signed turn rate (rad/s, + = counter-clockwise)", lo=-1.0, hi=1.0
    )
    go_s: float = param(120.0, "stop_and_go only: time moving at speed_mps (s)", lo=0.0, lo_open=True, hi=1e6)
    stop_s: float = param(60.0, "stop_and_go only: time stopped (s)", lo=0.0, hi=1e6)
    stop_turn_rad: float = param(0.0, "stop_and_go only: heading change while stopped (rad)", lo=-10.0, hi=10.0)
    manoeuvre_interval_s: float = param(
        120.0, "random_turn only: mean time between turn-rate draws (s, exponential)", lo=1.0, hi=1e6
    )


@dataclass(frozen=True)
class AgentsConfig:
    """The AUV team (Table 1) and its initial state."""

    count: int = param(3, "number of AUVs n", lo=1, hi=MAX_AGENTS)
    positions_m: tuple[tuple[float, float], ...] = param(
        (), "initial positions [[x, y], ...] (m); empty = random in the spawn box", factory=tuple
    )
    headings_rad: tuple[float, ...] = param((), "initial headings (rad); empty = all 0", factory=tuple)
    spawn_box_m: tuple[float, float, float, float] = param(
        (-100.0, -100.0, 100.0, 100.0), "random spawn box [xmin, ymin, xmax, ymax] (m) when positions_m is empty"
    )
    u_max_mps: float = param(
        2.0, "maximum surge speed u_max (m/s); the modem payload carries up to 10.23", lo=0.0, hi=10.0, lo_open=True
    )
    r_max_radps: float = param(0.05, "maximum turn rate r_max (rad/s)", lo=0.0, hi=5.0, lo_open=True)


@dataclass(frozen=True)
class SensorConfig:
    """The direction-of-arrival sensor, eqs. (2), (4)."""

    period_s: float = param(2.0, "measurement sampling period T_m (s)", lo=0.0, hi=600.0, lo_open=True)
    sigma_m_deg: float = param(4.5, "uniform bearing noise half-width sigma_m (deg)", lo=0.0, hi=90.0, lo_open=True)
    outlier_rate: float = param(
        0.0, "probability that a bearing is an outlier drawn uniformly in (-pi, pi]", lo=0.0, hi=1.0
    )
    max_range_m: float = param(1e9, "no bearing beyond this range from the source (m)", lo=0.0, lo_open=True)


@dataclass(frozen=True)
class ChannelConfig:
    """Acoustic modem, TDMA schedule and link model (eqs. 22-26, Table 1)."""

    slot_s: float = param(14.0, "TDMA slot length T_s (s)", lo=0.0, hi=3600.0, lo_open=True)
    guard_s: float = param(1.0, "guard time at the end of each slot (s)", lo=0.0, hi=3600.0)
    slot_order: tuple[int, ...] = param((), "AUV ids in slot order; empty = 0..n-1", factory=tuple)
    bit_rate_bps: float = param(120.0, "modem bit rate (bit/s)", lo=0.0, hi=1e7, lo_open=True)
    max_range_m: float = param(
        4000.0, "maximum range used for the slot budget's propagation delay (m)", lo=0.0, lo_open=True
    )
    sound_speed_mps: float = param(1500.0, "speed of sound (m/s)", lo=1000.0, hi=2000.0)
    pdr: float = param(0.95, "packet delivery ratio of the Bernoulli loss model", lo=0.0, hi=1.0)
    source_level_db: float = param(186.0, "source level SL (dB re 1 uPa @ 1 m)", lo=0.0, hi=300.0)
    noise_level_db: float = param(40.0, "ambient noise level NL (dB)", lo=-100.0, hi=300.0)
    directivity_index_db: float = param(0.0, "directivity index DI (dB)", lo=-100.0, hi=100.0)
    frequency_khz: float = param(10.0, "acoustic centre frequency f (kHz)", lo=0.0, hi=1000.0, lo_open=True)
    detection_threshold_db: float = param(
        10.0, "detection threshold DT (dB): no link below it (eq. 25)", lo=-100.0, hi=300.0
    )
    snr_max_db: float = param(0.0, "normaliser rho_M of eq. (26) (dB); 0 = SL - NL + DI (TL = 0)", lo=0.0, hi=400.0)
    snr_transition_db: float = param(
        0.0, "width of the soft SNR success ramp above DT (dB); 0 = hard threshold", lo=0.0, hi=100.0
    )
    mode: str = param("tdma", "medium access: tdma, or aloha for comparison", choices=("tdma", "aloha"))
    out_of_slot: str = param(
        "defer", "a transmission outside the sender's slot is deferred or rejected", choices=("defer", "reject")
    )


OCEAN_MODELS = ("paper", "physical")
SOUND_SPEED_PRESETS = ("isovelocity", "summer", "munk", "profile")
SEABED_PRESETS = tuple(SEABEDS)
MODEM_PRESETS = tuple(MODEMS)


@dataclass(frozen=True)
class OceanConfig:
    """The acoustic environment (docs/ocean.md): the paper's link budget, or one physical ocean that drives the
    bearing sensor, the modem and the connectivity graph. Every key but ``model`` applies to "physical" only."""

    model: str = param(
        "paper",
        "paper (eqs. 22-24 with channel.noise_level_db, uniform bearing noise, sensor.max_range_m) or physical "
        "(transmission loss, ambient noise, modem packet-error curves and a detector from the keys below)",
        choices=OCEAN_MODELS,
    )
    propagation: str = param(
        "practical",
        "transmission loss: practical (15 log10 r + Thorp absorption), bellhop (computed with pelagic, the "
        "[bellhop] extra, cached), table (ocean.tl_table)",
        choices=("practical", "bellhop", "table"),
    )
    tl_table: str = param(
        "", "propagation = table: builtin:NAME or a path to a TL table (.npz, docs/ocean.md), relative to the scenario"
    )
    tl_table_sha256: str = param("", "SHA-256 of the TL table file; filled in the resolved scenario, checked if set")
    depth_m: float = param(100.0, "water depth (m)", lo=1.0, hi=12000.0)
    sound_speed: str = param(
        "isovelocity",
        "sound-speed profile: isovelocity (1500 m/s), summer (a shallow summer thermocline), munk (Munk 1974), "
        "profile (ocean.sound_speed_profile)",
        choices=SOUND_SPEED_PRESETS,
    )
    sound_speed_profile: tuple[tuple[float, float], ...] = param(
        (), "sound_speed = profile: [[depth m, speed m/s], ...] from 0 m down to at least depth_m", factory=tuple
    )
    seabed: str = param(
        "sand", "seabed half-space (Jensen et al. 2011, Table 1.3): mud, sand, gravel, rock", choices=SEABED_PRESETS
    )
    wind_mps: float = param(5.0, "wind speed at the surface for the wind-noise spectrum (m/s)", lo=0.0, hi=40.0)
    shipping: float = param(
        0.5, "shipping activity of the shipping-noise spectrum, 0 (none) to 1 (heavy)", lo=0.0, hi=1.0
    )
    auv_depth_m: float = param(20.0, "depth of every AUV, its modem and its bearing sensor (m)", lo=0.0, hi=12000.0)
    source_depth_m: float = param(20.0, "depth of the tracked acoustic source (m)", lo=0.0, hi=12000.0)
    source_level_db: float = param(
        120.0, "the tracked source's level in its band (dB re 1 uPa at 1 m)", lo=0.0, hi=250.0
    )
    source_band_khz: tuple[float, float] = param(
        (10.6, 11.6), "[low, high] band of the source and of the passive bearing sensor (kHz)"
    )
    integration_s: float = param(
        1.0, "integration time of the bearing sensor's detector per measurement (s)", lo=0.0, lo_open=True, hi=600.0
    )
    false_alarm_probability: float = param(
        1e-4, "false-alarm probability per bearing cell and measurement (Albersheim: 1e-7 to 1e-3)", lo=1e-7, hi=1e-3
    )
    bearing_cells: int = param(36, "bearing cells the sensor searches per measurement (false alarms)", lo=1, hi=3600)
    modem: str = param(
        "micromodem-rate1",
        "modem packet-error curve (docs/ocean.md): micromodem-rate1, -rate3, -rate5 (WHOI Micro-Modem PSK rates "
        "as ros_acomms simulates them)",
        choices=MODEM_PRESETS,
    )
    modem_band_khz: float = param(
        5.0, "modem bandwidth centred on channel.frequency_khz (kHz)", lo=0.0, lo_open=True, hi=100.0
    )
    burst_p_good_bad: float = param(
        0.0, "Gilbert-Elliott bursty loss: per-frame probability of a link going bad (0 = off)", lo=0.0, hi=1.0
    )
    burst_p_bad_good: float = param(
        0.5, "Gilbert-Elliott: per-frame probability of a bad link recovering", lo=0.0, lo_open=True, hi=1.0
    )
    burst_loss: float = param(1.0, "Gilbert-Elliott: probability that a frame is lost in the bad state", lo=0.0, hi=1.0)
    table_range_m: float = param(
        5000.0, "propagation = bellhop: farthest range of the computed TL table (m)", lo=100.0, hi=100000.0
    )


ESTIMATOR_METHODS = tuple(methods.BUILTIN["estimator"])
"""The built-in estimators' names (``contract.methods.BUILTIN`` says where each factory is)."""


@dataclass(frozen=True)
class EstimatorConfig:
    """Share-and-estimate pseudo-linear WLS, eqs. (11)-(15), (21)."""

    method: str = param(
        "adaptive-window",
        "estimator of every AUV, by name: adaptive-window = the 600 s constant-velocity "
        "window (wls-cv) and a manoeuvring-track model (a piecewise-linear track with an acceleration-noise prior) "
        "side by side, mixed by the likelihood of their innovations with a prior for the constant-velocity window; "
        "wls-cv = the moving-window pseudo-linear WLS of a constant-velocity source with Gauss-Newton refinement alone; or a plug-in's name (docs/python.md)",
        choices=methods.MethodNames("estimator"),
    )
    window_s: float = param(
        600.0,
        "moving window of measurements (s); several TDMA frames so shared bearings are in it",
        lo=0.0,
        lo_open=True,
        hi=1e5,
    )
    min_measurements: int = param(6, "fewest measurements before an estimate is attempted", lo=4, hi=10000)
    min_sources: int = param(
        1, "distinct AUVs whose bearings must be in the window before an estimate is reported", lo=1, hi=MAX_AGENTS
    )
    gate_sigma: float = param(
        3.0, "outlier gate on bearing residuals, in multiples of sigma_m", lo=0.0, lo_open=True, hi=100.0
    )
    gauss_newton_iters: int = param(
        3, "Gauss-Newton refinements on the true bearing residuals (bias reduction)", lo=0, hi=50
    )
    consensus_gain: float = param(0.0, "consensus gain Omega of eq. (21) (scalar times identity)", lo=0.0, hi=1.0)
    max_position_std_m: float = param(
        100.0,
        "an estimate whose position std sqrt(P_xx + P_yy) exceeds this is reported as not ok (m)",
        lo=0.0,
        lo_open=True,
    )
    max_condition: float = param(
        1e10, "regressor condition number above which the problem is unobservable", lo=1.0, lo_open=True
    )
    adaptive_windows_s: tuple[float, ...] = param(
        (),
        "adaptive-window only: shorter constant-velocity windows run beside window_s (s); longer ones are ignored",
        factory=lambda: (),
    )
    likelihood_memory_s: float = param(
        90.0,
        "adaptive-window only: time constant of the fading memory of each window's innovation likelihood (s)",
        lo=0.0,
        lo_open=True,
    )
    adaptive_prior: float = param(
        25.0,
        "adaptive-window only: penalty added to the innovation score of each step down in window length "
        "(twice the log prior odds for the longer window; dimensionless)",
        lo=0.0,
    )
    spline_knot_s: float = param(
        30.0,
        "adaptive-window only: knot spacing (s) of the manoeuvring-track model run beside the windows (0: off)",
        lo=0.0,
    )
    spline_span_s: float = param(
        300.0, "adaptive-window only: bearings fitted by the manoeuvring-track model (s)", lo=0.0, lo_open=True
    )
    spline_q: float = param(
        3e-3,
        "adaptive-window only: acceleration noise intensity q of the manoeuvring-track model (m^2/s^3)",
        lo=0.0,
        lo_open=True,
    )
    spline_prior: float = param(
        25.0, "adaptive-window only: penalty added to the manoeuvring-track model's innovation score", lo=0.0
    )
    spline_wake: float = param(
        15.0,
        "adaptive-window only: the manoeuvring-track model wakes (is fitted) once the long window's faded "
        "chi-square excess sum(nu^2/var - 1) exceeds this and 3 sigma of it (the constant-velocity model broke; "
        "0: always fitted)",
        lo=0.0,
    )
    max_speed_mps: float = param(
        5.0,
        "an estimate whose target speed |v| exceeds this is reported as not ok (m/s): a prior bound on the "
        "source's speed that rejects solutions in a wrong basin of the bearing cost",
        lo=0.0,
        lo_open=True,
    )


PLANNER_METHODS = tuple(methods.BUILTIN["planner"])
"""The built-in planning methods' names, those of the paper's Table 3 (``contract.methods.BUILTIN`` says where each
factory is; ``centralised`` has none: its AUVs follow the central planner, ``central/``)."""


@dataclass(frozen=True)
class PlannerConfig:
    """DMPC planner, eqs. (27)-(50), Table 1, and the method of section 3.3 (docs/baselines.md)."""

    method: str = param(
        "dmpc",
        "planning method (section 3.3, docs/baselines.md): dmpc (ours, exact sequential DMPC, eq. 43), dec-mpc "
        "(no plans shared, neighbours' plans predicted), dpso (particle swarm, sequential), centralised (one "
        "planner, full information); or a plug-in's name (docs/python.md)",
        choices=methods.MethodNames("planner"),
    )
    horizon: int = param(5, "planning horizon H (steps)", lo=1, hi=MAX_HORIZON)
    step_s: float = param(130.0, "optimisation time step T_o (s)", lo=0.0, lo_open=True, hi=1e5)
    n_headings: int = param(9, "heading choices n_theta of eq. (48) (Table 1 U_0)", lo=1, hi=64)
    dtheta_max_rad: float = param(math.pi / 2, "heading change range +/- dtheta_max (rad)", lo=0.0, hi=math.pi)
    alpha: float = param(0.5, "geometry vs distance trade-off alpha of eq. (38)", lo=0.0, hi=1.0)
    gamma: float = param(
        0.25,
        "connectivity weight gamma of eqs. (37)-(38), the paper's: the cost sums gamma / lambda_2 over the |N_i| neighbours",
        lo=0.0,
        hi=1.0,
    )
    connectivity: str = param(
        "db",
        "reading of the connectivity cost of eq. (37): db (gamma / lambda_2 of the SNR Laplacian in dB, eqs. 22-26), "
        "formation (gamma sum_j |d_ij,h - d_ij,0| / d*: the pair distances' deviation from the plan start), "
        "topology (the same against the pair distances at the first plan that knew the neighbour, docs/planner.md)",
        choices=("db", "formation", "topology"),
    )
    anchor_tau_s: float = param(
        0.0,
        "connectivity = topology: time constant of the reference pair distance (s); 0 keeps the first plan's for "
        "good, tau > 0 lets it follow the measured distance as a moving average, a + min(1, dt / tau) (d - a) "
        "(docs/planner.md)",
        lo=0.0,
        hi=1e6,
    )
    speed_set: str = param(
        "ladder",
        "surge speeds of the control set: ladder ({0, u_e, d*/(4 T_o), d*/(2 T_o), d*/T_o, u_max}, the d* legs "
        "below u_max: one step a quarter, half or whole d* long, docs/planner.md), paper ({0, u_e, u_max}, eq. 46), "
        "dstar ({0, u_e, u_d, u_max} with u_d = min(u_max, d*/T_o))",
        choices=("ladder", "paper", "dstar"),
    )
    range_constraint: str = param(
        "worst",
        "where the soft range constraint d* <= d <= d_M of eq. (50) is evaluated: worst (at the sigma point that "
        "violates it most), mean (UT-weighted mean over the sigma points, eq. 30)",
        choices=("worst", "mean"),
    )
    leg_constraint: str = param(
        "first-arc",
        "where eq. (50)'s safety distance d_S and range floor d* are checked: first-arc (at the ends of the steps "
        "and along the first step's leg, the one executed before the next plan, with a margin for the turn the "
        "vehicle flies, u dtheta^2 / (2 r_max), and d_S also on the leg as flown; docs/planner.md), first (the same "
        "without the flown leg), straight (without the margin either), arc (the first leg as flown only: a turn at "
        "r_max, then straight), ends (at the ends of the steps only)",
        choices=("first-arc", "first", "straight", "arc", "ends"),
    )
    terminal_weight: float = param(
        1.0, "weight of the terminal cost (|p_H - p_s,H| - d*)/d* of eq. (38)", lo=0.0, hi=1e3
    )
    d_star_m: float = param(500.0, "desired range to the target d* (m)", lo=0.0, lo_open=True, hi=1e6)
    d_max_m: float = param(1000.0, "maximum range to the target d_M (m)", lo=0.0, lo_open=True, hi=1e6)
    d_safe_m: float = param(100.0, "inter-vehicle safety distance d_S (m)", lo=0.0, hi=1e6)
    w0: float = param(
        1.0 / 3.0,
        "unscented transform weight of the central sigma point omega_0 (eq. 32)",
        lo=-10.0,
        hi=1.0,
        hi_open=True,
    )
    soft_penalty: float = param(10.0, "penalty per unit of normalised violation of soft constraints", lo=0.0, hi=1e6)
    central_orders: int = param(
        1,
        "centralised: coordinate-descent starts, the first k rotations of the slot order (the best joint plan is kept)",
        lo=1,
        hi=16,
    )
    dpso_particles: int = param(40, "DPSO swarm size (particles per plan)", lo=2, hi=10000)
    dpso_iterations: int = param(50, "DPSO iterations per plan", lo=1, hi=10000)
    dpso_inertia: float = param(0.7298, "DPSO inertia weight w (Clerc-Kennedy constriction value)", lo=0.0, hi=1.0)
    dpso_c1: float = param(
        1.49618, "DPSO cognitive acceleration coefficient c1 (pull to the particle's best)", lo=0.0, hi=4.0
    )
    dpso_c2: float = param(
        1.49618, "DPSO social acceleration coefficient c2 (pull to the swarm's best)", lo=0.0, hi=4.0
    )


@dataclass(frozen=True)
class NavigationConfig:
    """Each AUV's own navigation: dead reckoning between position fixes (world/navigation.py, docs/navigation.md).

    Every key 0 (the default) is perfect navigation: every AUV knows its true pose, and nothing is drawn.
    """

    drift_fraction: float = param(
        0.0,
        "dead-reckoning drift: the 1-sigma radial position error as a fraction of the distance travelled on a "
        "straight leg since the last fix (dimensionless; 0.01 = 1 %); a body-frame scale and misalignment error "
        "drawn per AUV at the start and at every fix",
        lo=0.0,
        hi=1.0,
    )
    heading_bias_deg: float = param(
        0.0,
        "compass bias (deg, counter-clockwise): the AUV believes its heading is the true one plus this, dead-reckons "
        "along it and turns its measured bearings by it (eq. 4)",
        lo=-90.0,
        hi=90.0,
    )
    fix_period_s: float = param(0.0, "a position fix every this many seconds of sim time (0 = none)", lo=0.0, hi=1e7)
    fix_sigma_m: float = param(
        0.0, "1-sigma radial error of a position fix (m); needs fix_period_s > 0", lo=0.0, hi=1e5
    )

    @property
    def perfect(self) -> bool:
        """True when every AUV knows its true pose at every tick (no drift, no heading bias, exact fixes)."""
        return self.drift_fraction == 0.0 and self.heading_bias_deg == 0.0 and self.fix_sigma_m == 0.0


@dataclass(frozen=True)
class RunConfig:
    """Mission-level settings."""

    duration_s: float = param(1500.0, "mission length (s of sim time)", lo=0.0, lo_open=True, hi=1e7)
    seed: int = param(1, "master seed of every random draw", lo=0, hi=2**63 - 1)
    tick_s: float = param(2.0, "world tick (s); must divide the sensor period", lo=0.0, lo_open=True, hi=600.0)
    tick_timeout_s: float = param(
        5.0, "wall-clock wait for a live component to finish a tick (s)", lo=0.0, lo_open=True, hi=600.0
    )
    convergence_error_m: float = param(15.0, "tracking-error level that defines convergence (m)", lo=0.0, lo_open=True)
    grace_s: float = param(
        10.0,
        "wall-clock grace period (s): how long a process waits for the world's liveliness to come back before "
        "it ends, and how long the world waits for the channel",
        lo=0.0,
        lo_open=True,
        hi=600.0,
    )
