"""world.sessions: the binding of each AUV to one bus session, and what gives a second login away (issue 44)."""

from __future__ import annotations

from auv_swarm.world.sessions import Sessions


def test_the_first_session_seen_is_bound_and_another_token_is_evidence() -> None:
    s = Sessions([0, 1])
    s.on_token(1, "real", True, dead=False)
    assert s.bound[1] == "real" and s.holds(1) and not s.compromised
    s.on_token(1, "evil", True, dead=False)
    assert s.detected == [1] and "liveliness token" in s.compromised[1]
    assert s.channel_sessions() == {}, "a compromised AUV's frames are taken from no session"


def test_a_message_of_another_session_is_evidence_and_refused() -> None:
    s = Sessions([1])
    s.on_token(1, "real", True, dead=False)
    assert s.on_message(1, "real", "command", dead=False)
    assert not s.on_message(1, "evil", "frame", dead=False)
    assert not s.on_message(1, None, "telemetry", dead=False), "no session id is another session"
    assert list(s.compromised) == [1] and "frame" in s.compromised[1]
    assert not s.on_message(1, "real", "command", dead=False), "nothing of a compromised AUV is used"


def test_a_restart_rebinds_whichever_token_comes_first() -> None:
    s = Sessions([1])
    s.on_token(1, "old", True, dead=False)
    s.on_token(1, "old", False, dead=False)
    assert not s.holds(1), "the process is gone"
    s.on_token(1, "new", True, dead=True)
    assert s.bound[1] == "new" and s.holds(1) and not s.compromised
    # the fresh process's token can come before the killed one's goes: bound once the old one has gone
    s.on_token(1, "newer", True, dead=True)
    assert s.bound[1] == "new" and not s.compromised
    s.on_token(1, "new", False, dead=True)
    assert s.bound[1] == "newer" and s.holds(1) and not s.compromised


def test_the_death_is_the_bound_session_s_whatever_other_token_stays() -> None:
    s = Sessions([1])
    s.on_token(1, "real", True, dead=False)
    s.on_token(1, "evil", True, dead=False)
    s.on_token(1, "real", False, dead=False)
    assert not s.holds(1), "the impostor's token does not keep AUV 1 alive"


def test_a_router_restart_brings_the_same_sessions_back_without_an_alarm() -> None:
    s = Sessions([0, 1])
    for a in (0, 1):
        s.on_token(a, f"s{a}", True, dead=False)
    for a in (0, 1):
        s.on_token(a, f"s{a}", False, dead=False)
    for a in (1, 0):
        s.on_token(a, f"s{a}", True, dead=False)
    assert s.bound == {0: "s0", 1: "s1"} and not s.compromised and s.channel_sessions() == {0: "s0", 1: "s1"}


def test_a_bus_without_sessions_never_sees_a_second_one() -> None:
    s = Sessions([0, 1])
    for a in (0, 1):
        s.on_token(a, None, True, dead=False)
        assert s.on_message(a, None, "command", dead=False)
    s.on_token(1, None, False, dead=True)
    s.on_token(1, None, True, dead=True)
    assert s.holds(1) and not s.compromised and s.channel_sessions() == {}


def test_another_session_is_no_evidence_while_the_auv_is_dead() -> None:
    s = Sessions([1])
    s.on_token(1, "real", True, dead=False)
    assert not s.on_message(1, "other", "command", dead=True)
    assert not s.compromised
