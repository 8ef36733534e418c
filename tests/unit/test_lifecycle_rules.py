"""The decisions behind "a run never lies" and "every process ends with the mission", without processes."""

from __future__ import annotations

import pytest

from auv_swarm.bus.lifeline import Lifeline
from auv_swarm.contract import wire
from auv_swarm.contract.config import ConfigError, builtin_scenarios, load_scenario, scenario_from_dict
from auv_swarm.orchestrator.mission.supervise import STALL_S, Outcome, Supervisor
from auv_swarm.world.service import WorldService


def _event(kind: str, t_s: float = 10.0, auv: int = -1, text: str = "") -> wire.WorldEvent:
    return wire.WorldEvent(t_s=t_s, source="world", kind=kind, auv=auv, text=text)


def test_losing_a_critical_process_names_it_and_its_time() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_event(_event("start", 0.0), now=0.0)
    sup.on_tick(312.0, now=1.0)
    sup.on_exit("channel", -9)
    assert sup.outcome == Outcome(False, "channel_lost", "channel died at t = 312 s (signal 9); the run is incomplete")
    assert sup.outcome.exit_code == 1 and sup.done
    sup.on_exit("world", -15)
    assert sup.outcome.reason == "channel_lost", "the first failure is the one reported"


def test_a_process_killed_by_a_scheduled_fault_is_said_dead_at_the_faults_tick() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_event(_event("start", 0.0), now=0.0)
    sup.on_tick(100.0, now=1.0)
    sup.on_fault("recorder", 100.0)
    sup.on_fault("channel", 100.0)
    sup.on_tick(102.0, now=1.5)  # a tick heard before the exit is noticed does not move the time said
    sup.on_exit("recorder", -9)
    sup.on_exit("channel", -9)
    assert sup.lines[0] == "warning: the recorder died at t = 100 s (signal 9); the recording stops there"
    assert sup.outcome.line == "channel died at t = 100 s (signal 9); the run is incomplete"
    restarted = Supervisor(600.0, silent_limit_s=30.0)
    restarted.on_event(_event("start", 0.0), now=0.0)
    restarted.on_fault("channel", 50.0)
    restarted.expect_exit("channel", True)
    restarted.on_exit("channel", -9)
    restarted.expect_exit("channel", False)
    restarted.on_tick(80.0, now=2.0)
    restarted.on_exit("channel", -9)
    assert restarted.outcome.line.startswith("channel died at t = 80 s"), "a restart that is over is forgotten"


def test_a_critical_process_that_gives_up_during_a_router_restart_makes_the_run_router_lost() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_event(_event("start", 0.0), now=0.0)
    sup.on_tick(40.0, now=1.0)
    sup.expect_exit("router", True)
    sup.on_exit("router", -9)
    assert sup.outcome is None, "the restart's own kill is no failure"
    sup.on_exit("auv1", 1)
    sup.on_exit("channel", 1)
    assert sup.outcome is not None and sup.outcome.reason == "router_lost"
    assert sup.outcome.line.startswith("router lost at t = 40 s") and "channel exit code 1" in sup.outcome.line
    aborted = Supervisor(600.0, silent_limit_s=30.0)
    aborted.on_event(_event("start", 0.0), now=0.0)
    aborted.expect_exit("router", True)
    aborted.expect_exit("router", False)  # back, but the world gave up on the channel meanwhile
    aborted.on_event(_event("abort", 40.0, text="channel_lost: the channel did not come back"), now=3.0)
    assert aborted.outcome is not None and aborted.outcome.reason == "router_lost"
    back = Supervisor(600.0, silent_limit_s=30.0)
    back.on_event(_event("start", 0.0), now=0.0)
    back.expect_exit("router", True)
    back.expect_exit("router", False)
    back.on_tick(42.0, now=2.0)
    back.on_exit("channel", -9)
    assert back.outcome is not None and back.outcome.reason == "channel_lost", "the router was back and moving"


def test_before_the_start_any_exit_is_a_start_failure() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_exit("auv3", 2)
    assert sup.outcome is not None and sup.outcome.reason == "start_failed"
    assert sup.outcome.line == "AUV 3 exited before the mission started (exit code 2)"


def test_recorder_and_auv_deaths_are_warnings_and_planned_kills_are_quiet() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_event(_event("start", 0.0), now=0.0)
    sup.on_exit("recorder", -9)
    sup.on_event(_event("kill", 84.0, auv=1), now=1.0)
    sup.on_exit("auv1", -9)
    sup.on_event(_event("death", 90.0, auv=2, text="AUV 2 lost its liveliness token at tick 45"), now=2.0)
    assert sup.outcome is None
    assert sup.lines == [
        "warning: the recorder died at t = 0 s (signal 9); the recording stops there",
        "warning: AUV 2 died at t = 90 s (AUV 2 lost its liveliness token at tick 45); the swarm goes on",
    ]
    sup.on_event(_event("rejoin", 120.0, auv=2), now=2.5)
    sup.on_event(_event("rejoin", 130.0, auv=0), now=2.6)  # AUV 0 was never out: nothing to say
    assert sup.lines[2:] == ["AUV 2 rejoined at t = 120 s; the swarm has it back"]
    sup.on_event(_event("end", 600.0), now=3.0)
    sup.on_exit("world", 0)
    assert sup.done and sup.outcome is None and sup.t_s == 600.0


def test_a_stalled_mission_is_said_once_and_a_silent_world_is_dead() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_event(_event("start", 0.0), now=0.0)
    sup.on_tick(100.0, now=1.0)
    sup.on_wall(1.0 + STALL_S / 2)
    assert sup.lines == []
    sup.on_wall(1.0 + STALL_S + 0.1)
    sup.on_wall(1.0 + STALL_S + 0.2)
    assert sup.lines == [f"no new tick for {STALL_S:g} s at t = 100 s: waiting for the world"]
    sup.on_tick(102.0, now=6.0)
    assert sup.lines[-1] == "the mission moves again at t = 102 s"
    sup.on_wall(37.0)
    assert sup.outcome is not None and sup.outcome.reason == "world_died"


def test_the_world_abort_and_ctrl_c_give_their_reasons() -> None:
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_event(_event("start", 0.0), now=0.0)
    sup.on_event(_event("abort", 50.0, text="channel_lost: gone for more than 3 s at t = 50 s"), now=1.0)
    assert sup.outcome == Outcome(False, "channel_lost", "gone for more than 3 s at t = 50 s")
    sup = Supervisor(600.0, silent_limit_s=30.0)
    sup.on_tick(20.0, now=0.0)
    sup.interrupted()
    assert sup.outcome is not None and sup.outcome.exit_code == 130 and "interrupted at t = 20 s" in sup.outcome.line


def test_lifeline_ends_on_the_end_on_the_world_gone_past_the_grace_and_on_the_parent() -> None:
    line = Lifeline(grace_s=3.0)
    world = wire.liveliness_component("world")
    line.on_liveliness(world, False, now=0.0)
    assert line.check(100.0) is None, "a world never seen is not a lost world"
    line.on_liveliness(world, True, now=1.0)
    line.on_liveliness(world, False, now=2.0)
    assert line.check(4.9) is None
    line.on_liveliness(world, True, now=4.9)
    assert line.check(10.0) is None, "a world back within the grace is not lost"
    line.on_liveliness(world, False, now=11.0)
    assert "gone for more than 3 s" in (line.check(14.1) or "") and line.exit_code == 1

    ended = Lifeline(grace_s=3.0)
    ended.on_world_event(_event("end", 1500.0))
    assert ended.check(0.0) == "the world announced the end of the mission" and ended.exit_code == 0
    aborted = Lifeline(grace_s=3.0)
    aborted.on_world_event(_event("abort", 10.0, text="channel_lost: x"))
    assert aborted.check(0.0) == "the world aborted the mission" and aborted.exit_code == 1
    orphan = Lifeline(grace_s=3.0, parent_pid=12345)
    assert orphan.check(0.0, parent_alive=False) == "the launcher (pid 12345) is gone"
    with pytest.raises(ValueError, match="grace_s"):
        Lifeline(grace_s=0.0)


def test_run_grace_s_is_validated_like_every_key() -> None:
    with pytest.raises(ConfigError, match=r"run.grace_s must be in \(0, 600\]"):
        scenario_from_dict({"run": {"grace_s": 0.0}})
    assert scenario_from_dict({"run": {"grace_s": 1.5}}).run.grace_s == 1.5


def test_every_builtin_places_any_team_from_1_to_16() -> None:
    for name in builtin_scenarios():
        base = load_scenario(name)
        for n in range(1, 17):
            scenario = base.replace(kills=tuple(k for k in base.kills if k.agent < n)).with_overrides(agents=n)
            world = WorldService(scenario)
            xy = [s[:2] for s in world.model.states.values()]
            d_safe = scenario.planner.d_safe_m
            assert len(xy) == n
            assert all(((a - b) ** 2).sum() ** 0.5 >= d_safe for i, a in enumerate(xy) for b in xy[:i]), (name, n)


def test_a_mission_ends_at_its_duration() -> None:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=10.0)
    world = WorldService(scenario)
    while not world.finished:
        world.apply({})
    assert world.model.time_s == 10.0


def test_a_shell_that_saw_the_end_itself_lingers_past_the_worlds_exit() -> None:
    """The router and the recorder handle the end themselves (they linger for clients, drain the bus): the world
    leaving after the end must not turn their exit into a failure (seen under docker-compose, where clients
    leave more slowly than the 3 s grace)."""
    line = Lifeline(grace_s=3.0)
    world = wire.liveliness_component("world")
    line.on_liveliness(world, True, now=0.0)
    line.note_end()
    line.on_liveliness(world, False, now=1.0)
    assert line.check(100.0) is None and line.exit_code == 0


def _faulted(faults: tuple) -> dict:
    from auv_swarm.orchestrator.mission.api import run_mission
    from auv_swarm.results.metrics import comparable

    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=300.0, seed=2)
    scenario = scenario.replace(kills=(), faults=faults)
    return comparable(run_mission(scenario).metrics)


def test_auv_faults_in_process_are_deterministic_and_a_restart_rejoins_on_its_tick() -> None:
    from auv_swarm.contract.config import Fault

    faults = (
        Fault(at_s=101.0, target="auv:1", action="restart", down_s=40.0),
        Fault(at_s=200.0, target="auv:2", action="term"),
    )
    first, second = _faulted(faults), _faulted(faults)
    assert first == second
    assert first["agents"]["1"]["alive_intervals_s"] == [[0.0, 102.0], [142.0, 300.0]]
    assert first["agents"]["2"]["alive_intervals_s"] == [[0.0, 200.0]]
    assert first["agents"]["1"]["plans"] > _faulted(())["agents"]["1"]["plans"] - 3
    with pytest.raises(ConfigError, match=r"faults\[0\]: the world cannot be restarted"):
        scenario_from_dict({"faults": [{"at_s": 1.0, "target": "world", "action": "restart", "down_s": 1.0}]})


def test_in_process_mode_rejects_faults_of_processes_with_exit_2(tmp_path, capsys) -> None:
    from auv_swarm.orchestrator.cli import run

    path = tmp_path / "f.toml"
    path.write_text('[[faults]]\nat_s = 10.0\ntarget = "channel"\naction = "restart"\ndown_s = 1.0\n')
    out = tmp_path / "out"
    assert run.main(["--scenario", str(path), "--mode", "inprocess", "--quiet", "--out", str(out)]) == 2
    assert "faults[0]: faults of the channel, router, world or recorder exist only in processes mode" in (
        capsys.readouterr().err
    )
    assert not out.exists()
    assert run.main(["--restart", "sometimes", "--quiet", "--out", str(out)]) == 2
    assert run.parse_restart("on-failure:2.5") == 2.5 and run.parse_restart("no") is None
