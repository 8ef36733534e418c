"""Every zenoh key expression of the swarm, as functions of the AUV id under a prefix (default ``auvswarm``).

The key a message arrives on is its identity (see :mod:`bus.identity`); the
interface table here is what ``--interface`` prints and what ``docs/wire.md`` shows.
"""

from __future__ import annotations

import operator
import re
from typing import NamedTuple

PREFIX = "auvswarm"
MAX_AUV_ID = 255


_SEGMENT = re.compile(r"[A-Za-z0-9_.-]+")
MAX_SESSION_ID_CHARS = 64
"""The longest session id (a zenoh id is 32 hex digits)."""
_SESSION_ID = re.compile(rf"[A-Za-z0-9]{{1,{MAX_SESSION_ID_CHARS}}}")


def is_session_id(text: object) -> bool:
    """Whether ``text`` is a bus session's id as tokens and attachments carry it: 1 to :data:`MAX_SESSION_ID_CHARS`
    letters or digits (the one rule for both, so the world compares ids of one form)."""
    return isinstance(text, str) and _SESSION_ID.fullmatch(text) is not None


_VALID_PREFIXES: set[str] = set()


def _check_prefix(prefix: str) -> str:
    if isinstance(prefix, str) and prefix in _VALID_PREFIXES:
        return prefix
    if not isinstance(prefix, str) or not all(_SEGMENT.fullmatch(s) for s in prefix.split("/")):
        raise ValueError(f"prefix must be '/'-separated segments of letters, digits, '_', '.', '-', got {prefix!r}")
    _VALID_PREFIXES.add(prefix)
    return prefix


def _auv_id(auv: int) -> int:
    """``auv`` as a Python int (numpy integers accepted), or ValueError."""
    try:
        value = operator.index(auv)
    except TypeError:
        value = -1
    if isinstance(auv, bool) or not 0 <= value <= MAX_AUV_ID:
        raise ValueError(f"auv must be an integer in [0, {MAX_AUV_ID}], got {auv!r}")
    return value


def _auv_key(auv: int, tail: str, prefix: str) -> str:
    return f"{_check_prefix(prefix)}/auv/{_auv_id(auv)}/{tail}"


def modem_tx(auv: int, prefix: str = PREFIX) -> str:
    """Key where AUV ``auv`` publishes its acoustic transmissions (:class:`ModemTx`)."""
    return _auv_key(auv, "modem/tx", prefix)


def modem_rx(auv: int, prefix: str = PREFIX) -> str:
    """Key where the channel delivers packets to AUV ``auv`` (:class:`ModemRx`)."""
    return _auv_key(auv, "modem/rx", prefix)


def sensor(auv: int, prefix: str = PREFIX) -> str:
    """Key of AUV ``auv``'s bearing sensor (:class:`Sensor`)."""
    return _auv_key(auv, "sensor", prefix)


def nav(auv: int, prefix: str = PREFIX) -> str:
    """Key of AUV ``auv``'s navigation solution (:class:`Nav`)."""
    return _auv_key(auv, "nav", prefix)


def command(auv: int, prefix: str = PREFIX) -> str:
    """Key of AUV ``auv``'s actuator command and tick reply (:class:`Command`)."""
    return _auv_key(auv, "cmd", prefix)


def telemetry(auv: int, prefix: str = PREFIX) -> str:
    """Key of AUV ``auv``'s estimator and planner telemetry (:class:`Telemetry`)."""
    return _auv_key(auv, "telemetry", prefix)


def central_plan(auv: int, prefix: str = PREFIX) -> str:
    """Key where the central planner sends AUV ``auv`` its plan (:class:`CentralPlan`; centralised MPC only)."""
    return _auv_key(auv, "plan", prefix)


def all_central_plans(prefix: str = PREFIX) -> str:
    """Wildcard over every AUV's :func:`central_plan` key."""
    return f"{_check_prefix(prefix)}/auv/*/plan"


def liveliness(auv: int, prefix: str = PREFIX) -> str:
    """Liveliness token key of AUV ``auv`` (``<prefix>/alive/auv/<id>``)."""
    return f"{_check_prefix(prefix)}/alive/auv/{_auv_id(auv)}"


def liveliness_session(auv: int, session: str, prefix: str = PREFIX) -> str:
    """Liveliness token key of AUV ``auv``'s process as one bus session (``<prefix>/alive/auv/<id>/<session>``,
    the session's zenoh id in hex): two processes logged in as one AUV hold two tokens, never one merged one."""
    if not is_session_id(session):
        raise ValueError(f"session must be 1 to {MAX_SESSION_ID_CHARS} letters or digits, got {session!r}")
    return f"{liveliness(auv, prefix)}/{session}"


def parse_liveliness(key: str, prefix: str = PREFIX) -> tuple[int, str | None] | None:
    """``(auv, session)`` of an AUV's token key (:func:`liveliness`: session None; :func:`liveliness_session`),
    else None."""
    head = f"{_check_prefix(prefix)}/alive/auv/"
    if not isinstance(key, str) or not key.startswith(head):
        return None
    parts = key[len(head) :].split("/")
    auv = parse_auv_id(f"auv/{parts[0]}")
    if auv is None or str(auv) != parts[0] or len(parts) > 2 or (len(parts) == 2 and not is_session_id(parts[1])):
        return None
    return auv, parts[1] if len(parts) == 2 else None


def liveliness_component(name: str, prefix: str = PREFIX) -> str:
    """Liveliness token key of a named component, e.g. ``"world"`` or ``"channel"``."""
    if not isinstance(name, str) or not all(_SEGMENT.fullmatch(s) for s in name.split("/")):
        raise ValueError(f"name must be '/'-separated segments of letters, digits, '_', '.', '-', got {name!r}")
    return f"{_check_prefix(prefix)}/alive/{name}"


def clock(prefix: str = PREFIX) -> str:
    """Key of the world clock (:class:`Clock`)."""
    return f"{_check_prefix(prefix)}/world/clock"


def truth(prefix: str = PREFIX) -> str:
    """Key of the ground truth (:class:`Truth`)."""
    return f"{_check_prefix(prefix)}/world/truth"


def world_events(prefix: str = PREFIX) -> str:
    """Key of mission events (:class:`WorldEvent`)."""
    return f"{_check_prefix(prefix)}/world/events"


def channel_tick(prefix: str = PREFIX) -> str:
    """Key where the world asks the channel to process a tick (:class:`ChannelTick`)."""
    return f"{_check_prefix(prefix)}/channel/tick"


def channel_done(prefix: str = PREFIX) -> str:
    """Key where the channel reports a processed tick (:class:`ChannelDone`)."""
    return f"{_check_prefix(prefix)}/channel/done"


def channel_stats(prefix: str = PREFIX) -> str:
    """Key of the channel's counters (:class:`ChannelStats`)."""
    return f"{_check_prefix(prefix)}/channel/stats"


def channel_events(prefix: str = PREFIX) -> str:
    """Key of the per-packet log (:class:`PacketEvent`)."""
    return f"{_check_prefix(prefix)}/channel/events"


def faults_injected(prefix: str = PREFIX) -> str:
    """Key where the launcher confirms the faults it injected at a tick (:class:`FaultsInjected`); the world holds
    the clock at that tick until it hears it."""
    return f"{_check_prefix(prefix)}/orchestrator/faults"


def all_modem_tx(prefix: str = PREFIX) -> str:
    """Wildcard over every AUV's :func:`modem_tx` key."""
    return f"{_check_prefix(prefix)}/auv/*/modem/tx"


def all_modem_rx(prefix: str = PREFIX) -> str:
    """Wildcard over every AUV's :func:`modem_rx` key."""
    return f"{_check_prefix(prefix)}/auv/*/modem/rx"


def all_commands(prefix: str = PREFIX) -> str:
    """Wildcard over every AUV's :func:`command` key."""
    return f"{_check_prefix(prefix)}/auv/*/cmd"


def all_telemetry(prefix: str = PREFIX) -> str:
    """Wildcard over every AUV's :func:`telemetry` key."""
    return f"{_check_prefix(prefix)}/auv/*/telemetry"


def all_sensors(prefix: str = PREFIX) -> str:
    """Wildcard over every AUV's :func:`sensor` key."""
    return f"{_check_prefix(prefix)}/auv/*/sensor"


def all_liveliness(prefix: str = PREFIX) -> str:
    """Wildcard over every liveliness token, AUVs and components."""
    return f"{_check_prefix(prefix)}/alive/**"


def parse_auv_id(key: str) -> int | None:
    """The AUV id in a key such as ``auvswarm/auv/3/cmd`` or ``auvswarm/alive/auv/3``, else None.

    The id is the segment after the first ``auv`` segment that is followed by a
    canonical decimal integer in [0, 255].
    """
    parts = str(key).split("/")
    for seg, nxt in zip(parts, parts[1:], strict=False):
        if seg == "auv" and re.fullmatch(r"0|[1-9][0-9]{0,2}", nxt) and int(nxt) <= MAX_AUV_ID:
            return int(nxt)
    return None


class KeyRow(NamedTuple):
    """One row of the interface table: key pattern, publisher, subscribers, message type."""

    key: str
    publisher: str
    subscribers: str
    message: str


def key_table(prefix: str = PREFIX) -> list[KeyRow]:
    """The interface table for ``prefix``; ``{id}`` stands for an AUV id."""
    p = _check_prefix(prefix)
    return [
        KeyRow(f"{p}/world/clock", "world", "observers (any tool), central", "Clock"),
        KeyRow(f"{p}/auv/{{id}}/nav", "world", "agent {id}, central", "Nav"),
        KeyRow(f"{p}/auv/{{id}}/sensor", "world", "agent {id}, central, orchestrator, recorder", "Sensor"),
        KeyRow(f"{p}/auv/{{id}}/cmd", "agent {id}", "world", "Command"),
        KeyRow(f"{p}/auv/{{id}}/modem/tx", "agent {id}", "channel", "ModemTx"),
        KeyRow(f"{p}/auv/{{id}}/modem/rx", "channel", "agent {id}", "ModemRx"),
        KeyRow(f"{p}/auv/{{id}}/telemetry", "agent {id}", "orchestrator, recorder", "Telemetry"),
        KeyRow(f"{p}/channel/tick", "world", "channel", "ChannelTick"),
        KeyRow(f"{p}/channel/done", "channel", "world", "ChannelDone"),
        KeyRow(f"{p}/channel/stats", "channel", "orchestrator, recorder", "ChannelStats"),
        KeyRow(f"{p}/channel/events", "channel", "orchestrator, recorder", "PacketEvent"),
        KeyRow(f"{p}/world/truth", "world", "orchestrator, recorder", "Truth"),
        KeyRow(f"{p}/world/events", "world", "orchestrator, recorder, channel, agent {id}", "WorldEvent"),
        KeyRow(f"{p}/auv/{{id}}/plan", "central", "agent {id}", "CentralPlan"),
        KeyRow(f"{p}/orchestrator/faults", "orchestrator", "world", "FaultsInjected"),
        KeyRow(f"{p}/alive/auv/{{id}}/{{session}}", "agent {id}", "world, channel", "liveliness token"),
        KeyRow(
            f"{p}/alive/{{component}}",
            "world, channel, recorder, central",
            "world; every process (the world's)",
            "liveliness token",
        ),
    ]


KEY_TABLE: list[KeyRow] = key_table()


def interface_rows(component: str, rows: list[KeyRow] | None = None) -> list[KeyRow]:
    """Rows that ``component`` ("world", "channel" or "agent") publishes or subscribes to (for ``--interface``)."""
    rows = KEY_TABLE if rows is None else rows
    return [r for r in rows if component in r.publisher or component in r.subscribers]


def format_key_table(rows: list[KeyRow] | None = None, markdown: bool = False) -> str:
    """The interface table as aligned text, or as a Markdown table."""
    rows = KEY_TABLE if rows is None else rows
    header = KeyRow("key", "publisher", "subscribers", "message")
    if markdown:
        lines = [f"| {' | '.join(header)} |", "|---|---|---|---|"]
        lines += [f"| `{r.key}` | {r.publisher} | {r.subscribers} | {r.message} |" for r in rows]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(4)]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in [header, *rows])
