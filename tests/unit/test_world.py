"""Ground truth: angles, bearings, sensor noise, vehicle kinematics, target paths, world model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import quad, solve_ivp

from auv_swarm.contract.config import (
    AgentsConfig,
    KillEvent,
    PlannerConfig,
    RunConfig,
    Scenario,
    SensorConfig,
    TargetConfig,
)
from auv_swarm.world.model import (
    TargetTrajectory,
    WorldModel,
    bearing,
    initial_agent_states,
    measure_bearing,
    vehicle_step,
    wrap_angle,
)


@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False))
def test_wrap_angle_range_and_equivalence(a: float) -> None:
    w = wrap_angle(a)
    assert -math.pi < w <= math.pi
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)


def test_wrap_angle_boundaries() -> None:
    assert wrap_angle(math.pi) == math.pi
    assert wrap_angle(-math.pi) == math.pi
    assert wrap_angle(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(0.0) == 0.0
    np.testing.assert_allclose(wrap_angle(np.array([0.5, 2 * math.pi + 0.5, -2 * math.pi + 0.5])), [0.5, 0.5, 0.5])


def test_bearing_known_geometry() -> None:
    assert bearing([0.0, 0.0], [1.0, 1.0]) == pytest.approx(math.pi / 4)
    assert bearing([0.0, 0.0], [-1.0, 0.0]) == math.pi
    assert bearing([0.0, 0.0], [-1.0, -0.0]) == math.pi
    assert bearing([0.0, 0.0], [0.0, -3.0]) == pytest.approx(-math.pi / 2)
    assert bearing([10.0, 10.0], [10.0, 10.0]) == 0.0
    sensors = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    np.testing.assert_allclose(bearing(sensors, [0.0, 0.0]), [0.0, math.pi, -math.pi / 2])


def test_measure_bearing_noise_bounded_and_zero_mean() -> None:
    rng = np.random.default_rng(3)
    sigma = math.radians(4.5)
    truth = bearing([0.0, 0.0], [-500.0, 1.0])  # close to +pi: exercises wrapping
    errs = np.array(
        [wrap_angle(measure_bearing([0.0, 0.0], [-500.0, 1.0], sigma, 0.0, rng) - truth) for _ in range(20000)]
    )
    assert np.all(np.abs(errs) <= sigma + 1e-12)
    assert abs(errs.mean()) < 3 * sigma / math.sqrt(3 * 20000)
    assert errs.std() == pytest.approx(sigma / math.sqrt(3), rel=0.03)


def test_measure_bearing_outlier_rate() -> None:
    rng = np.random.default_rng(4)
    sigma = math.radians(1.0)
    n = 20000
    errs = np.array([measure_bearing([0.0, 0.0], [100.0, 0.0], sigma, 0.2, rng) for _ in range(n)])
    frac = np.mean(np.abs(errs) > sigma)
    # An outlier lands within +/-sigma with probability sigma/pi; expected outside fraction 0.2 (1 - sigma/pi).
    expected = 0.2 * (1 - sigma / math.pi)
    assert frac == pytest.approx(expected, abs=4 * math.sqrt(expected * (1 - expected) / n))
    assert np.all((errs > -math.pi) & (errs <= math.pi))


@pytest.mark.parametrize("outlier_rate", [0.0, 0.5, 1.0])
def test_measure_bearing_always_consumes_three_variates(outlier_rate: float) -> None:
    rng = np.random.default_rng(11)
    ref = np.random.default_rng(11)
    measure_bearing([0.0, 0.0], [1.0, 2.0], 0.1, outlier_rate, rng)
    ref.random(3)
    assert rng.random() == ref.random()


def test_measure_bearing_rejects_bad_parameters() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="sigma_m_rad"):
        measure_bearing([0, 0], [1, 0], -0.1, 0.0, rng)
    with pytest.raises(ValueError, match="outlier_rate"):
        measure_bearing([0, 0], [1, 0], 0.1, 1.5, rng)


def _integrate(state: np.ndarray, u: float, r: float, dt: float) -> np.ndarray:
    def rhs(_t: float, s: np.ndarray) -> list[float]:
        return [u * math.cos(s[2]), u * math.sin(s[2]), r]

    sol = solve_ivp(rhs, (0.0, dt), state, method="DOP853", rtol=1e-12, atol=1e-12)
    return sol.y[:, -1]


@pytest.mark.parametrize(
    ("u", "r", "dt"), [(2.0, 0.05, 130.0), (1.5, -0.03, 60.0), (1.0, 1e-14, 50.0), (0.5, 0.0, 10.0)]
)
def test_vehicle_step_exact_arc_matches_fine_integration(u: float, r: float, dt: float) -> None:
    s0 = np.array([10.0, -20.0, 0.7])
    exact = vehicle_step(s0, u, r, dt, u_max=2.0, r_max=0.05)
    fine = _integrate(s0, u, r, dt)
    np.testing.assert_allclose(exact[:2], fine[:2], atol=1e-6)
    assert wrap_angle(exact[2] - fine[2]) == pytest.approx(0.0, abs=1e-9)


def test_vehicle_step_half_circle() -> None:
    # u = 1 m/s, r = 0.1 rad/s: radius 10 m; after pi/r s the vehicle is 20 m to the left, facing back.
    out = vehicle_step([0.0, 0.0, 0.0], 1.0, 0.1, math.pi / 0.1, u_max=2.0, r_max=0.2)
    np.testing.assert_allclose(out, [0.0, 20.0, math.pi], atol=1e-9)


def test_vehicle_step_clamps_commands() -> None:
    s0 = np.array([0.0, 0.0, 0.0])
    np.testing.assert_allclose(vehicle_step(s0, 5.0, 0.0, 10.0, 2.0, 0.05), [20.0, 0.0, 0.0])
    np.testing.assert_allclose(vehicle_step(s0, -1.0, 0.0, 10.0, 2.0, 0.05), [0.0, 0.0, 0.0])
    assert vehicle_step(s0, 0.0, 1.0, 10.0, 2.0, 0.05)[2] == pytest.approx(0.5)
    assert vehicle_step(s0, 0.0, -1.0, 10.0, 2.0, 0.05)[2] == pytest.approx(-0.5)
    with pytest.raises(ValueError, match="dt"):
        vehicle_step(s0, 1.0, 0.0, -1.0, 2.0, 0.05)
    with pytest.raises(ValueError, match="finite"):
        vehicle_step(s0, math.nan, 0.0, 1.0, 2.0, 0.05)


def test_vehicle_step_vectorised() -> None:
    states = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 1.0]])
    out = vehicle_step(states, np.array([1.0, 2.0]), np.array([0.01, -0.02]), 20.0, 2.0, 0.05)
    for k in range(2):
        np.testing.assert_allclose(out[k], vehicle_step(states[k], [1.0, 2.0][k], [0.01, -0.02][k], 20.0, 2.0, 0.05))


def test_target_static_and_constant_velocity_exact() -> None:
    static = TargetTrajectory(TargetConfig(model="static", position_m=(3.0, 4.0), speed_mps=1.0))
    p, v = static.state(1000.0)
    np.testing.assert_array_equal(p, [3.0, 4.0])
    np.testing.assert_array_equal(v, [0.0, 0.0])
    cv = TargetTrajectory(TargetConfig(position_m=(-450.0, 105.0), speed_mps=0.5, heading_rad=math.pi / 3))
    p, v = cv.state(1500.0)
    np.testing.assert_allclose(p, [-450.0 + 750.0 * 0.5, 105.0 + 750.0 * math.sqrt(3) / 2], atol=1e-9)
    np.testing.assert_allclose(v, [0.25, 0.5 * math.sqrt(3) / 2], atol=1e-12)
    pa, va = cv.state(np.array([0.0, 1500.0]))
    assert pa.shape == (2, 2) and va.shape == (2, 2)
    np.testing.assert_allclose(pa[1], p)


@pytest.mark.parametrize(
    ("v", "theta0", "a", "w"),
    [(0.2, math.pi / 2, 0.3, 0.03), (0.5, math.pi, 0.1, 0.01), (0.35, -math.pi / 2, 0.2, 0.02), (1.0, 0.4, 1.0, 0.5)],
)
def test_target_oscillating_matches_numerical_integration(v: float, theta0: float, a: float, w: float) -> None:
    cfg = TargetConfig(
        model="oscillating", position_m=(400.0, 0.0), speed_mps=v, heading_rad=theta0, amplitude=a, omega_radps=w
    )
    traj = TargetTrajectory(cfg)
    for t in (0.0, 1.0, 333.3, 1500.0):
        p, vel = traj.state(t)
        psi = theta0 + a * math.sin(w * t + math.pi)
        np.testing.assert_allclose(vel, [v * math.cos(psi), v * math.sin(psi)], atol=1e-12)
        x = (
            400.0
            + quad(lambda s: v * math.cos(theta0 + a * math.sin(w * s + math.pi)), 0.0, t, limit=500, epsabs=1e-10)[0]
        )
        y = quad(lambda s: v * math.sin(theta0 + a * math.sin(w * s + math.pi)), 0.0, t, limit=500, epsabs=1e-10)[0]
        np.testing.assert_allclose(p, [x, y], atol=1e-6)


def test_target_oscillating_zero_omega_is_straight() -> None:
    cfg = TargetConfig(model="oscillating", speed_mps=1.0, heading_rad=0.3, amplitude=0.5, omega_radps=0.0)
    p, _ = TargetTrajectory(cfg).state(100.0)
    np.testing.assert_allclose(p, [100.0 * math.cos(0.3), 100.0 * math.sin(0.3)], atol=1e-9)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_target_oscillating_literal_formula(axis: str) -> None:
    a, w, v = 30.0, 0.02, 0.35
    cfg = TargetConfig(
        model="oscillating_literal",
        position_m=(250.0, 350.0),
        speed_mps=v,
        amplitude=a,
        omega_radps=w,
        axis=axis,
        heading_rad=2.0,
    )
    traj = TargetTrajectory(cfg)
    t = 123.4
    p, vel = traj.state(t)
    osc, nominal = a * math.sin(w * t + math.pi), v * t
    expected = [250.0 + osc, 350.0 + nominal] if axis == "y" else [250.0 + nominal, 350.0 + osc]
    np.testing.assert_allclose(p, expected, atol=1e-12)
    h = 1e-4
    numeric = (traj.state(t + h)[0] - traj.state(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(vel, numeric, atol=1e-7)


def test_target_random_heading_is_seeded() -> None:
    cfg = TargetConfig(speed_mps=1.0, random_heading=True, heading_rad=0.0)
    h1 = TargetTrajectory(cfg, np.random.default_rng(5)).heading_rad
    h2 = TargetTrajectory(cfg, np.random.default_rng(5)).heading_rad
    h3 = TargetTrajectory(cfg, np.random.default_rng(6)).heading_rad
    assert h1 == h2 != h3
    assert -math.pi < h1 <= math.pi
    _, vel = TargetTrajectory(cfg, np.random.default_rng(5)).state(0.0)
    np.testing.assert_allclose(vel, [math.cos(h1), math.sin(h1)])
    with pytest.raises(ValueError, match="rng"):
        TargetTrajectory(cfg)


def _scenario(**kw: object) -> Scenario:
    return Scenario(**kw)


def test_initial_states_from_config() -> None:
    sc = _scenario(agents=AgentsConfig(count=2, positions_m=((500.0, 0.0), (0.0, -500.0)), headings_rad=(0.1, 4.0)))
    out = initial_agent_states(sc, np.random.default_rng(0))
    np.testing.assert_allclose(out, [[500.0, 0.0, 0.1], [0.0, -500.0, 4.0 - 2 * math.pi]])


@pytest.mark.parametrize("seed", range(5))
def test_initial_states_random_respect_d_safe_and_box(seed: int) -> None:
    sc = _scenario(
        agents=AgentsConfig(count=6, spawn_box_m=(-200.0, -100.0, 200.0, 100.0)), planner=PlannerConfig(d_safe_m=100.0)
    )
    out = initial_agent_states(sc, np.random.default_rng(seed))
    assert out.shape == (6, 3)
    assert np.all(out[:, 0] >= -200.0) and np.all(out[:, 0] <= 200.0)
    assert np.all(out[:, 1] >= -100.0) and np.all(out[:, 1] <= 100.0)
    d = np.hypot(*(out[:, None, :2] - out[None, :, :2]).transpose(2, 0, 1))
    assert np.all(d[np.triu_indices(6, 1)] >= 100.0)
    np.testing.assert_array_equal(out[:, 2], 0.0)
    np.testing.assert_array_equal(out, initial_agent_states(sc, np.random.default_rng(seed)))


def test_initial_states_grow_a_small_spawn_box_and_raise_when_it_cannot_grow_enough() -> None:
    sc = _scenario(
        agents=AgentsConfig(count=4, spawn_box_m=(0.0, 0.0, 10.0, 10.0)), planner=PlannerConfig(d_safe_m=100.0)
    )
    xy = initial_agent_states(sc, np.random.default_rng(0))[:, :2]
    gaps = [np.hypot(*(xy[i] - xy[j])) for i in range(4) for j in range(i)]
    assert min(gaps) >= 100.0
    assert np.all(np.abs(xy - 5.0) < 1000.0), "grown about the box's centre"
    sc = _scenario(
        agents=AgentsConfig(count=4, spawn_box_m=(0.0, 0.0, 10.0, 10.0)), planner=PlannerConfig(d_safe_m=1e5)
    )
    with pytest.raises(ValueError, match="d_safe_m"):
        initial_agent_states(sc, np.random.default_rng(0))


def test_the_worlds_check_places_the_team_as_the_world_does_without_building_it(monkeypatch) -> None:
    from auv_swarm.contract.config import builtin_scenarios, load_scenario
    from auv_swarm.orchestrator.mission.api import check_runnable
    from auv_swarm.world.service import WorldService, check_scenario

    tight = _scenario(agents=AgentsConfig(count=5, spawn_box_m=(0.0, 0.0, 1.0, 1.0)))
    with pytest.raises(ValueError) as by_check:
        check_scenario(tight)
    with pytest.raises(ValueError) as by_world:
        WorldService(tight)
    assert str(by_check.value) == str(by_world.value) and "too small to place" in str(by_check.value)
    placed = {}
    monkeypatch.setattr(
        "auv_swarm.world.service.initial_agent_states",
        lambda s, rng: placed.setdefault(s.name, initial_agent_states(s, rng)),
    )
    for name in builtin_scenarios():
        scenario = load_scenario(name)
        check_scenario(scenario)
        model = WorldService(scenario).model
        np.testing.assert_array_equal(placed[name], [model.states[i] for i in model.ids], err_msg=name)
    monkeypatch.setattr("auv_swarm.world.model.WorldModel.__init__", lambda *a: pytest.fail("a world was built"))
    check_runnable(load_scenario("manoeuvre-zigzag"), "processes")


def _world_scenario(**kw: object) -> Scenario:
    base = dict(
        run=RunConfig(tick_s=2.0),
        target=TargetConfig(position_m=(400.0, 0.0), speed_mps=0.5, heading_rad=math.pi),
        agents=AgentsConfig(count=3, positions_m=((500.0, 0.0), (0.0, -500.0), (-1000.0, 0.0))),
        sensor=SensorConfig(period_s=2.0, sigma_m_deg=4.5, outlier_rate=0.1),
    )
    base.update(kw)
    return Scenario(**base)


def test_world_kills_at_the_right_tick_and_dead_vehicles_stop() -> None:
    world = WorldModel(_world_scenario(kills=(KillEvent(agent=1, time_s=750.0),)), np.random.default_rng(1))
    for i in range(3):
        world.set_command(i, 1.0, 0.01)
    killed_at = None
    for _ in range(400):
        if world.advance():
            assert killed_at is None
            killed_at = world.tick
            frozen = world.states[1].copy()
    assert killed_at == 375
    assert world.time_s == 800.0
    assert world.alive == {0, 2}
    np.testing.assert_array_equal(world.states[1], frozen)
    assert set(world.sense()) == {0, 2}


def test_world_time_is_tick_times_tick_s() -> None:
    world = WorldModel(
        _world_scenario(run=RunConfig(tick_s=0.1), sensor=SensorConfig(period_s=0.3)), np.random.default_rng(1)
    )
    for _ in range(7):
        world.advance()
    assert world.time_s == 7 * 0.1
    assert not world.measurement_due()
    world.advance()
    world.advance()
    assert world.tick == 9 and world.measurement_due()


def test_world_sense_not_due_returns_none_without_drawing() -> None:
    sc = _world_scenario(run=RunConfig(tick_s=1.0))
    a = WorldModel(sc, np.random.default_rng(2))
    b = WorldModel(sc, np.random.default_rng(2))
    a.sense()
    b.sense()
    a.advance()
    b.advance()
    assert a.sense() == {0: None, 1: None, 2: None}
    a.advance()
    b.advance()
    due_a, due_b = a.sense(), b.sense()
    assert all(v is not None for v in due_a.values())
    assert due_a == due_b


def test_world_same_seed_same_sense_sequence() -> None:
    sc = _world_scenario(agents=AgentsConfig(count=4))
    runs = []
    for _ in range(2):
        world = WorldModel(sc, np.random.default_rng(42))
        seq = []
        for k in range(50):
            world.set_command(k % 4, 1.5, 0.02 * ((k % 3) - 1))
            seq.append(world.sense())
            world.advance()
        runs.append(seq)
    assert runs[0] == runs[1]
    other = WorldModel(sc, np.random.default_rng(43)).sense()
    assert other != runs[0][0]


def test_world_bearings_of_survivors_do_not_depend_on_failures() -> None:
    sc = _world_scenario()
    a = WorldModel(sc, np.random.default_rng(9))
    b = WorldModel(sc, np.random.default_rng(9))
    b.kill(2)
    for _ in range(20):
        sa, sb = a.sense(), b.sense()
        assert sb == {0: sa[0], 1: sa[1]}
        a.advance()
        b.advance()


def test_world_sense_respects_max_range_and_noise_bounds() -> None:
    sc = _world_scenario(sensor=SensorConfig(period_s=2.0, sigma_m_deg=2.0, max_range_m=800.0))
    world = WorldModel(sc, np.random.default_rng(3))
    target, _ = world.target()
    out = world.sense()
    assert out[2] is None  # 1400 m away
    for i in (0, 1):
        truth = bearing(world.states[i][:2], target)
        assert abs(wrap_angle(out[i] - truth)) <= math.radians(2.0) + 1e-12


def test_world_commands_clamped_and_validated() -> None:
    world = WorldModel(_world_scenario(), np.random.default_rng(0))
    assert world.commands == {0: (0.0, 0.0), 1: (0.0, 0.0), 2: (0.0, 0.0)}
    world.set_command(0, 9.0, -1.0)
    assert world.commands[0] == (2.0, -0.05)
    world.advance()
    np.testing.assert_allclose(world.states[1], [0.0, -500.0, 0.0])
    np.testing.assert_allclose(world.states[0], vehicle_step([500.0, 0.0, 0.0], 2.0, -0.05, 2.0, 2.0, 0.05))
    with pytest.raises(ValueError, match="agent"):
        world.set_command(7, 1.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        world.set_command(0, math.inf, 0.0)
    assert world.kill(0) is True
    assert world.kill(0) is False


def test_world_target_follows_trajectory() -> None:
    world = WorldModel(_world_scenario(), np.random.default_rng(0))
    for _ in range(10):
        world.advance()
    p, v = world.target()
    np.testing.assert_allclose(p, [400.0 - 0.5 * 20.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(v, [-0.5, 0.0], atol=1e-12)


def test_wrap_angle_scalar_path_is_bitwise_the_array_path() -> None:
    rng = np.random.default_rng(5)
    x = np.concatenate(
        [rng.uniform(-50.0, 50.0, 5000), [math.pi, -math.pi, 0.0, -0.0, 3 * math.pi, -2 * math.pi, 1e17]]
    )
    scalar = np.array([wrap_angle(float(v)) for v in x] + [wrap_angle(np.float64(v)) for v in x])
    assert np.array_equal(np.tile(wrap_angle(x), 2).view(np.int64), scalar.view(np.int64))
