"""The world's tick loop without a network: a scripted IO stands in for zenoh or the in-memory bus."""

from __future__ import annotations

from collections.abc import Callable

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
