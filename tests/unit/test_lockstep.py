"""The world's tick loop without a network: a scripted IO stands in for zenoh or the in-memory bus."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.world.lockstep import Lockstep
from auv_swarm.world.service import WorldService


class ScriptedIO:
    """Answers for the channel and the AUVs in ``answering``; records what was published and noted."""

    def __init__(self, lockstep: Lockstep, answering: set[int]) -> None:
        self.lockstep = lockstep
        self.answering = answering
        self.published: list[tuple[str, wire.Message]] = []
        self.notes: list[str] = []
        self.vanish: dict[int, str] = {}

    def publish(self, key: str, msg: wire.Message) -> None:
        self.published.append((key, msg))

    def wait(self, until: Callable[[], bool], timeout_s: float) -> bool:
        ls = self.lockstep
        tick = ls.service.tick
        ls.on_message(wire.ChannelDone(t_s=0.0, source="channel", tick=tick, rx_count={}))
        for tick_at, key in list(self.vanish.items()):
            if tick_at == tick:
                ls.on_liveliness(key, False)
        for a in sorted(self.answering & set(ls.service.alive)):
            ls.on_message(wire.Command(t_s=0.0, source=f"auv{a}", tick=tick, auv=a, u=1.0, r=0.0, tx_count=0))
        return until()

    def stopping(self) -> bool:
        return False

    def note(self, text: str) -> None:
        self.notes.append(text)


def _lockstep(duration_s: float = 10.0) -> Lockstep:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=duration_s)
    ls = Lockstep(WorldService(scenario), scenario.run.tick_timeout_s)
    return ls


def test_a_silent_auv_is_hung_once_and_waited_for_again_when_it_answers() -> None:
    ls = _lockstep()
    io = ScriptedIO(ls, answering={0, 1})
    for key in ls.expected_tokens():
        ls.on_liveliness(key, True)
    assert ls.start(io, 1.0) == []
    ls.step(io)
    assert ls.hung == {2} and io.notes == ["tick 0: no command from [2]; treated as hung"]
    ls.step(io)
    assert len(io.notes) == 1, "a hung AUV is not waited for again"
    io.answering.add(2)
    ls.step(io)
    assert ls.hung == set() and ls.service.alive == (0, 1, 2)
    events = [(m.kind, m.auv, m.t_s) for _k, m in io.published if isinstance(m, wire.WorldEvent)]
    assert events == [("start", -1, 0.0), ("hung", 2, 0.0), ("resume", 2, 4.0)]


def test_a_lost_token_is_a_death_event_and_a_missing_token_stops_the_start() -> None:
    ls = _lockstep()
    io = ScriptedIO(ls, answering={0, 1, 2})
    assert ls.start(io, 1.0) == ls.expected_tokens()
    assert io.published == []
    for key in ls.expected_tokens():
        ls.on_liveliness(key, True)
    assert ls.start(io, 1.0) == []
    io.vanish[1] = wire.liveliness(1)
    while not ls.finished:
        ls.step(io)
    deaths = [m for _k, m in io.published if isinstance(m, wire.WorldEvent) and m.kind == "death"]
    assert [(d.auv, d.t_s) for d in deaths] == [(1, 2.0)]
    assert ls.service.alive == (0, 2)


class HoldIO(ScriptedIO):
    """A :class:`ScriptedIO` whose launcher confirms the faults of the ticks in ``confirm`` when the world holds
    there, after ``during_hold(lockstep)`` (what the fault does meanwhile); ``published_at_hold`` is what the
    world had published when it asked."""

    def __init__(self, lockstep: Lockstep, confirm: set[int], during_hold: Callable[[Lockstep], None]):
        super().__init__(lockstep, answering={0, 1, 2})
        self.confirm = confirm
        self.during_hold = during_hold
        self.published_at_hold: list[tuple[str, wire.Message]] = []
        self.after_confirm: Callable[[Lockstep], None] | None = None

    def wait(self, until: Callable[[], bool], timeout_s: float) -> bool:
        ls = self.lockstep
        tick = ls.service.tick
        if ls._holding and tick not in ls.confirmed:
            self.published_at_hold = list(self.published)
            self.during_hold(ls)
            if tick in self.confirm:
                ls.on_message(wire.FaultsInjected(t_s=0.0, source="orchestrator", tick=tick, faults=("kill channel",)))
            return until()
        if ls._holding and self.after_confirm is not None:
            self.after_confirm(ls)
        return super().wait(until, timeout_s)


def _held(hold_at: tuple[float, ...]) -> Lockstep:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=10.0)
    ls = Lockstep(WorldService(scenario, hold_at=hold_at), scenario.run.tick_timeout_s)
    for key in ls.expected_tokens():
        ls.on_liveliness(key, True)
    return ls


def test_the_world_holds_the_clock_at_a_faults_tick_between_its_truth_and_its_navigation() -> None:
    ls = _held((3.0,))  # ticks of 2 s: the first at or after 3 s is tick 2 (t = 4 s)
    io = HoldIO(ls, confirm={2}, during_hold=lambda _ls: None)
    assert ls.start(io, 1.0) == []
    while not ls.finished:
        ls.step(io)
    assert io.notes == ["tick 2: the launcher injected its faults (kill channel)"]
    last_key, last = io.published_at_hold[-1]
    assert last_key == wire.truth() and last.tick == 2, "the launcher acts on the truth of the fault's tick"
    assert not any(isinstance(m, wire.Nav) and m.tick == 2 for _k, m in io.published_at_hold)
    assert any(isinstance(m, wire.Nav) and m.tick == 2 for _k, m in io.published), "then the tick goes on"
    assert ls.finished and ls.lost is None and ls.confirmed == {}


def test_an_unconfirmed_fault_is_noted_and_the_mission_goes_on() -> None:
    ls = _held((4.0,))
    io = HoldIO(ls, confirm=set(), during_hold=lambda _ls: None)
    ls.fault_wait_s = 0.5
    assert ls.start(io, 1.0) == []
    while not ls.finished:
        ls.step(io)
    assert io.notes == ["tick 2: no confirmation of the faults due within 0.5 s; going on"]
    assert ls.service.model.time_s == 10.0


def test_after_a_router_outage_in_a_hold_every_token_is_waited_for_and_a_lone_fault_is_not() -> None:
    """A router restart inside the hold takes every token with it: the AUVs whose tokens come back within the
    grace are not declared dead. A channel or an AUV killed in the hold is not waited for."""
    ls = _held((4.0,))
    io = HoldIO(ls, confirm={2}, during_hold=lambda ls: [ls.on_liveliness(k, False) for k in ls.expected_tokens()])
    io.after_confirm = lambda ls: [ls.on_liveliness(k, True) for k in ls.expected_tokens()]
    assert ls.start(io, 1.0) == []
    while not ls.finished:
        ls.step(io)
    assert not [m for _k, m in io.published if isinstance(m, wire.WorldEvent) and m.kind == "death"]
    assert ls.service.alive == (0, 1, 2)
    assert "tick 2: every process's token went with the router; waiting up to 10 s" in io.notes
    for lone in (wire.liveliness(1), wire.liveliness_component("channel")):
        ls = _held((4.0,))
        io = HoldIO(ls, confirm={2}, during_hold=lambda ls, key=lone: ls.on_liveliness(key, False))
        io.after_confirm = lambda _ls: pytest.fail("a lone process's fault is not waited for")
        assert ls.start(io, 1.0) == []
        while not ls.finished:
            ls.step(io)
        deaths = [(m.auv, m.t_s) for _k, m in io.published if isinstance(m, wire.WorldEvent) and m.kind == "death"]
        assert deaths == ([(1, 4.0)] if lone == wire.liveliness(1) else []), (
            "an AUV killed in the hold dies on its tick"
        )


def test_hold_times_are_due_once_on_the_first_tick_at_or_after_them() -> None:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(duration_s=10.0)
    service = WorldService(scenario, hold_at=(4.0, 3.0, 9.0))
    due = []
    while not service.finished:
        due.append(service.hold_due())
        service.apply({})
    assert due == [False, False, True, False, False, True]
    with pytest.raises(ValueError, match="hold_at"):
        WorldService(scenario, hold_at=(float("nan"),))


def test_hold_at_is_read_from_the_command_line_and_bad_values_are_one_line(capsys: pytest.CaptureFixture) -> None:
    from auv_swarm.world.node import main, parse_times

    assert parse_times("100.0, 61,") == (100.0, 61.0) and parse_times("") == ()
    for bad in ("x", "nan", "-1", "inf"):
        assert main(["--hold-at", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: --hold-at: "), err
