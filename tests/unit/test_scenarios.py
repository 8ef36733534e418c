"""The shipped scenarios match the paper's Tables 1-2; user TOML errors name the key or file."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from auv_swarm.bus.shell import example_text
from auv_swarm.contract.config import (
    BUILTIN_DIR,
    ConfigError,
    Scenario,
    builtin_scenarios,
    dump_toml,
    load_scenario,
    scenario_from_dict,
)

NAMES = [
    "paper-3.1-scenario1",
    "paper-3.1-scenario2",
    "paper-3.1-scenario3",
    "paper-3.2-challenging",
    "paper-3.3-sim1",
    "paper-3.3-sim2",
    "paper-3.3-sim3",
    "paper-3.3-sim4",
    "paper-3.3-sim5",
]

# Table 1 columns: (T_m, T_s, sigma_m, PDR, d_S, d_M, d*, u_max, r_max, headings, H, T_o)
TABLE1 = {
    "Sim 1": (1.0, 6.0, 3.5, 0.95, 25.0, 500.0, 30.0, 1.0, 0.05, 7, 4, 60.0),
    "Sim 2": (2.0, 14.0, 4.5, 0.65, 100.0, 1000.0, 500.0, 2.0, 0.05, 9, 5, 130.0),
    "Sim 3": (2.0, 14.0, 6.5, 0.65, 100.0, 2000.0, 500.0, 2.0, 0.05, 9, 5, 130.0),
}
COLUMN = {n: "Sim 1" for n in NAMES[:3]} | {NAMES[3]: "Sim 2"} | {n: "Sim 3" for n in NAMES[4:]}

# Table 2: NL (dB), initial position (m), v_n (m/s), theta_0 (rad), a, omega (rad/s)
TABLE2 = {
    1: (30.0, (0.0, -350.0), 0.2, math.pi / 2, 0.3, 0.03),
    2: (30.0, (400.0, 0.0), 0.5, math.pi, 0.1, 0.01),
    3: (60.0, (400.0, 0.0), 0.15, math.pi, 0.2, 0.01),
    4: (50.0, (-600.0, 25.0), 0.35, -math.pi / 2, 0.2, 0.02),
    5: (40.0, (250.0, 350.0), 0.35, math.pi, 0.3, 0.03),
}


def test_all_builtins_listed_and_load() -> None:
    assert [n for n in builtin_scenarios() if n.startswith("paper-")] == sorted(NAMES)
    for name in NAMES:
        s = load_scenario(name)
        assert s.name == name
        assert s.description
        assert s.agents.count == 3 and s.run.seed == 1


@pytest.mark.parametrize("name", NAMES)
def test_table1_column(name: str) -> None:
    s = load_scenario(name)
    t_m, t_s, sigma, pdr, d_s, d_m, d_star, u_max, r_max, headings, horizon, t_o = TABLE1[COLUMN[name]]
    assert s.sensor.period_s == t_m and s.run.tick_s == t_m
    assert s.channel.slot_s == t_s
    assert s.sensor.sigma_m_deg == sigma
    assert s.channel.pdr == pdr
    assert (s.planner.d_safe_m, s.planner.d_max_m, s.planner.d_star_m) == (d_s, d_m, d_star)
    assert (s.agents.u_max_mps, s.agents.r_max_radps) == (u_max, r_max)
    assert (s.planner.n_headings, s.planner.horizon, s.planner.step_s) == (headings, horizon, t_o)
    # section 3: the modem
    ch = s.channel
    assert (ch.source_level_db, ch.frequency_khz, ch.directivity_index_db, ch.bit_rate_bps) == (186.0, 10.0, 0.0, 120.0)
    assert ch.mode == "tdma"


@pytest.mark.parametrize("name", NAMES)
def test_files_open_with_comments_citing_the_paper(name: str) -> None:
    text = (BUILTIN_DIR / f"{name}.toml").read_text(encoding="utf-8")
    head = text.split("\nname = ", 1)[0]
    assert all(line.startswith("#") or not line for line in head.splitlines())
    assert "Table 1" in head and "Choices where the paper is silent" in head
    section = name.split("-")[1]
    assert f"section {section}" in head


@pytest.mark.parametrize("name", NAMES)
def test_slot_budget_holds_a_frame(name: str) -> None:
    ch = load_scenario(name).channel
    budget_bits = math.floor(ch.bit_rate_bps * (ch.slot_s - ch.guard_s - ch.max_range_m / ch.sound_speed_mps) + 1e-9)
    assert budget_bits >= 500  # header plus several bearings fit (docs/scenarios.md)


def test_section_3_1() -> None:
    s1, s2, s3 = (load_scenario(n) for n in NAMES[:3])
    for s in (s1, s2, s3):
        assert s.agents.positions_m == ((-17.0, -23.0), (-10.0, 5.0), (20.0, -3.0))
        assert s.target.position_m == (-30.0, -100.0)
        assert s.channel.noise_level_db == 20.0
        assert s.kills == ()
    assert s1.target.model == "static"
    assert (s1.planner.alpha, s1.planner.gamma) == (0.8, 0.3)
    assert s2.target.model == "constant_velocity" and s2.target.heading_rad == pytest.approx(math.pi / 4)
    assert s2.target.speed_mps == 0.2
    assert (s2.planner.alpha, s2.planner.gamma) == (0.5, 0.3)
    assert (s3.planner.alpha, s3.planner.gamma) == (0.5, 0.8)
    assert s3.target == s2.target and s3.agents == s2.agents and s3.channel == s2.channel


def test_section_3_2() -> None:
    s = load_scenario("paper-3.2-challenging")
    assert s.target.position_m == (-450.0, 105.0)
    assert s.target.model == "oscillating" and s.target.random_heading
    assert (s.target.speed_mps, s.target.amplitude, s.target.omega_radps) == (0.3, 0.2, 0.01)
    assert s.agents.positions_m == () and s.agents.spawn_box_m == (-100.0, -100.0, 100.0, 100.0)
    assert s.channel.noise_level_db == 40.0
    assert (s.planner.alpha, s.planner.gamma) == (0.5, 0.25)
    assert len(s.kills) == 1 and (s.kills[0].agent, s.kills[0].time_s) == (1, 750.0)  # the paper's "AUV 2"
    assert s.run.duration_s == 1500.0


@pytest.mark.parametrize("k", sorted(TABLE2))
def test_section_3_3_table2(k: int) -> None:
    s = load_scenario(f"paper-3.3-sim{k}")
    nl, pos, v_n, theta0, a, omega = TABLE2[k]
    assert s.channel.noise_level_db == nl
    assert s.target.position_m == pos
    assert s.target.speed_mps == v_n
    assert s.target.heading_rad == pytest.approx(theta0, abs=1e-15)
    assert (s.target.amplitude, s.target.omega_radps) == (a, omega)
    assert s.target.model == "oscillating" and not s.target.random_heading
    assert s.agents.positions_m == ((500.0, 0.0), (0.0, -500.0), (-1000.0, 0.0))
    assert (s.planner.alpha, s.planner.gamma) == (0.5, 0.25)
    assert s.run.duration_s == 1500.0 and s.kills == ()


def test_config_defaults_kept_for_detection_threshold_and_rho_m() -> None:
    default = Scenario().channel
    for name in NAMES:
        ch = load_scenario(name).channel
        assert ch.detection_threshold_db == default.detection_threshold_db
        assert ch.snr_max_db == default.snr_max_db


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "user.toml"
    path.write_text(body, encoding="utf-8")
    return path


def test_user_toml_loads(tmp_path: Path) -> None:
    s = load_scenario(_write(tmp_path, 'name = "mine"\n[planner]\nalpha = 0.7\n[run]\nseed = 9\n'))
    assert (s.name, s.planner.alpha, s.run.seed) == ("mine", 0.7, 9)
    assert s.planner.gamma == Scenario().planner.gamma


@pytest.mark.parametrize(
    ("body", "needles"),
    [
        ("[planner]\nalpha = 0.5\nbeta = 1.0\n", ["unknown key", "planner.beta"]),
        ("[sensr]\nperiod_s = 2.0\n", ["unknown key", "sensr"]),
        ("[planner]\nalpha = 1.5\n", ["planner.alpha", "[0, 1]", "1.5"]),
        ("[channel]\npdr = -0.1\n", ["channel.pdr", "[0, 1]"]),
        ("[planner]\nhorizon = 4.5\n", ["planner.horizon", "integer"]),
        ('[agents]\nu_max_mps = "fast"\n', ["agents.u_max_mps", "number"]),
        ("[target]\nrandom_heading = 1\n", ["target.random_heading", "true or false"]),
        ('[target]\nmodel = "zigzag"\n', ["target.model", "oscillating"]),
        ("[[kills]]\nagent = 5\ntime_s = 10.0\n", ["kills[0].agent", "[0, 2]"]),
        ("[run]\nseed = 1\n[run\n", ["invalid TOML"]),
        ("[channel]\nslot_s = 2.0\nguard_s = 0.2\n", ["channel: a slot cannot carry", "slot_s must be >= "]),
        ("[channel]\nbit_rate_bps = 5.0\n", ["channel: a slot cannot carry", "budget_bits must be >= "]),
    ],
)
def test_user_toml_errors_name_the_key(tmp_path: Path, body: str, needles: list[str]) -> None:
    path = _write(tmp_path, body)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    message = str(info.value)
    assert str(path) in message
    for needle in needles:
        assert needle in message


def test_missing_file_names_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="nope.toml"):
        load_scenario(missing)
    with pytest.raises(ConfigError, match="paper-3.2-challengin'.*built-ins: .*paper-3.1-scenario1"):
        load_scenario("paper-3.2-challengin")


def test_with_overrides() -> None:
    base = load_scenario("paper-3.2-challenging")
    s = base.with_overrides(seed=7, duration_s=300.0)
    assert (s.run.seed, s.run.duration_s) == (7, 300.0)
    assert s.planner == base.planner and s.kills == base.kills and base.run.seed == 1

    five = load_scenario("paper-3.3-sim2").with_overrides(agents=5)
    assert five.agents.count == 5 and five.agents.positions_m == ()  # 3 fixed positions no longer fit: random spawn
    two = base.with_overrides(agents=1)
    assert two.agents.count == 1 and two.kills == ()  # the kill of AUV id 1 no longer applies

    with pytest.raises(ConfigError, match="run.seed"):
        base.with_overrides(seed=-1)
    with pytest.raises(ConfigError, match="run.duration_s"):
        base.with_overrides(duration_s=0.0)
    with pytest.raises(ConfigError, match="agents.count"):
        base.with_overrides(agents=0)


@pytest.mark.parametrize("name", NAMES)
def test_written_scenario_loads_back_equal(name: str, tmp_path: Path) -> None:
    scenario = load_scenario(name).with_overrides(seed=2**63 - 1, duration_s=321.5)
    path = tmp_path / "scenario.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    assert load_scenario(path) == scenario


def test_written_scenario_keeps_awkward_values(tmp_path: Path) -> None:
    data = load_scenario("paper-3.2-challenging").to_dict()
    data["description"] = 'quotes " and \\ backslash,\nnew line, tab\t, non-ASCII: sigma_m = 4.5\u00b0'
    data["agents"]["positions_m"] = [[-17.0, -23.0], [-10.0, 5.0], [20.0, -3.0]]
    data["sensor"]["max_range_m"] = 1.2345678901234567e300
    data["target"]["speed_mps"] = 0.1 + 0.2
    data["kills"] = [{"agent": 1, "time_s": 750.0}, {"agent": 2, "time_s": 1000.25}]
    scenario = scenario_from_dict(data)
    path = tmp_path / "scenario.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    assert load_scenario(path) == scenario


def test_example_config_is_toml_with_the_defaults() -> None:
    defaults = Scenario().to_dict()
    example = tomllib.loads(example_text())
    for section, values in example.items():
        expected = defaults[section] if isinstance(values, dict) else {section: defaults[section]}
        got = values if isinstance(values, dict) else {section: values}
        assert {k: expected[k] for k in got} == got
    assert set(example) == {k for k in defaults if k not in ("kills", "faults")}
    sample = tomllib.loads(example_text(("agents", "sensor", "estimator", "planner")))
    assert set(sample) == {"agents", "sensor", "estimator", "planner"}


# Scenario.with_keys: dotted keys, validated as a TOML file is ------------------------------------------------------


def test_with_keys_sets_dotted_keys_as_a_toml_file_would() -> None:
    import dataclasses

    base = load_scenario("paper-3.3-sim2")
    keyed = base.with_keys({"planner.method": "dec-mpc", "channel.pdr": 0.5, "run.seed": 7})
    by_hand = base.replace(
        planner=dataclasses.replace(base.planner, method="dec-mpc"),
        channel=dataclasses.replace(base.channel, pdr=0.5),
        run=dataclasses.replace(base.run, seed=7),
    )
    assert keyed == by_hand
    assert base.with_keys({}) == base
    assert base.with_keys({"channel.pdr": 1}).channel.pdr == 1.0  # an integer is a number, as in TOML


def test_with_keys_agents_count_behaves_as_the_agents_option() -> None:
    base = load_scenario("paper-3.2-challenging")
    assert base.with_keys({"agents.count": 5}) == base.with_overrides(agents=5)
    fixed = base.with_keys({"agents.count": 2, "agents.positions_m": [[0.0, 0.0], [50.0, 0.0]]})
    assert fixed.agents.count == 2 and fixed.agents.positions_m == ((0.0, 0.0), (50.0, 0.0))


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ({"channel.pdr": 1.5}, "channel.pdr must be in [0, 1], got 1.5"),
        ({"channel.pdrx": 0.5}, "unknown key 'channel.pdrx'"),
        ({"chanel.pdr": 0.5}, "unknown key 'chanel.pdr': 'chanel' is not a table"),
        ({"planner.method": "best"}, "planner.method must be one of"),
        ({"agents.count": 0}, "agents.count must be in [1, 16]"),
        ({"agents.count": "3"}, "agents.count must be an integer"),
        ({"run.seed.x": 1}, "'run.seed' is not a table"),
    ],
)
def test_with_keys_names_the_bad_key_and_its_range(keys, message) -> None:
    with pytest.raises(ConfigError) as err:
        load_scenario("paper-3.2-challenging").with_keys(keys)
    assert message in str(err.value)


# kills and faults: their sample, and a warning for one after the mission's end ---------------------------------------


def test_the_kills_and_faults_sample_is_a_valid_scenario() -> None:
    from auv_swarm.contract.config import EXAMPLE_TOML, Fault, KillEvent

    scenario = scenario_from_dict(tomllib.loads(EXAMPLE_TOML))
    assert scenario.kills == (KillEvent(agent=1, time_s=750.0),)
    assert [(f.target, f.action) for f in scenario.faults] == [("auv:2", "restart"), ("channel", "stop")]
    assert isinstance(scenario.faults[0], Fault)
    assert "# [[faults]]" in example_text() and "#   faults[].down_s: " in example_text()


def test_a_kill_or_fault_after_the_missions_end_is_named_once_each() -> None:
    from auv_swarm.contract.config import Fault, KillEvent, after_end

    base = scenario_from_dict({"run": {"duration_s": 1200.0}, "agents": {"count": 3}})
    s = base.replace(
        kills=(KillEvent(agent=1, time_s=5000.0), KillEvent(agent=2, time_s=1200.0)),
        faults=(
            Fault(at_s=1000.0, target="channel", action="kill"),
            Fault(at_s=1300.0, target="router", action="term"),
        ),
    )
    assert after_end(s) == [
        "kills[0] (AUV 1 at 5000 s) is after the mission's end at 1200 s: it never happens",
        "faults[1] (term router at 1300 s) is after the mission's end at 1200 s: it never happens",
    ], "a kill at the end itself happens (on the last tick)"
    assert after_end(s, duration_s=6000.0) == []
    assert after_end(s, duration_s=900.0, agents=2) == [
        "kills[0] (AUV 1 at 5000 s) is after the mission's end at 900 s: it never happens",
        "faults[0] (kill channel at 1000 s) is after the mission's end at 900 s: it never happens",
        "faults[1] (term router at 1300 s) is after the mission's end at 900 s: it never happens",
    ], "kills[1], of an AUV the team no longer has, is dropped and said so elsewhere"


def test_run_warns_of_a_kill_after_the_missions_end_and_runs(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from auv_swarm.contract.config import KillEvent, dump_toml
    from auv_swarm.orchestrator.cli.run import load_checked, parse_args

    scenario = load_scenario("paper-3.1-scenario1").replace(kills=(KillEvent(agent=1, time_s=5000.0),))
    path = tmp_path / "late.toml"
    path.write_text(dump_toml(scenario), encoding="utf-8")
    checked = load_checked(parse_args(["--scenario", str(path), "--mode", "inprocess"]))
    assert checked.kills == scenario.kills, "a warning, not an error"
    assert capsys.readouterr().err.splitlines() == [
        "warning: kills[0] (AUV 1 at 5000 s) is after the mission's end at 1200 s: it never happens"
    ]
    load_checked(parse_args(["--scenario", "paper-3.2-challenging", "--duration", "300", "--agents", "1"]))
    assert capsys.readouterr().err.splitlines() == [
        "warning: kills[0] names AUV 1, but --agents 1 runs AUVs 0..0: that kill is dropped"
    ], "the kill at 750 s of an AUV the team no longer has is said once, as dropped"
    load_checked(parse_args(["--scenario", "paper-3.2-challenging", "--duration", "300"]))
    assert capsys.readouterr().err.splitlines() == [
        "warning: kills[0] (AUV 1 at 750 s) is after the mission's end at 300 s: it never happens"
    ]
