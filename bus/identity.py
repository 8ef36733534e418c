"""Who sent a message: the key it arrived on, never a field in its body.

One home for the trust check of every consumer (world, channel, agents, recorder,
results writer, in-process runner). The router's access control lets a user put
only on its own keys (``bus.acl.acl_roles``), so the key names the sender:
``<prefix>/auv/3/cmd`` can only come from AUV 3. A body that claims another
source (``source``, ``auv``), a message of another type than the key carries, or
a key outside the contract is dropped, counted by reason and logged once per
sender and reason.

Replays: on the keys an AUV publishes (its commands, modem frames and telemetry),
a message whose ``tick`` is older than the newest one accepted on that key, or
repeats one already accepted at that tick (the same tick for one-per-tick
messages, the same ``seq`` for modem frames), is dropped as ``replay``. The tick
is sim time owned by the world, so a restarted AUV, whose first message answers
the world's current tick, is never taken for a replayer; a restarted world starts
its consumers afresh (:meth:`Gate.forget`).

Duplicate logins: the real AUV never sends two different messages on one key for one tick (one command,
one telemetry per tick, one frame per ``seq``). When a second, different one arrives for the tick the key
last carried, a second client is logged in with that AUV's password: it is dropped as ``duplicate_login``
(not ``replay``) and handed to the gate's ``on_duplicate`` (the world reports it as a ``duplicate_login``
event). Whichever of the two arrived first was taken. An impostor that copies the real stream exactly
sends nothing different and cannot be told apart (its copies are dropped as replays).
"""

from __future__ import annotations

import functools
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass

from auv_swarm.contract import wire

REASONS = (
    "decode_error",
    "unknown_key",
    "wrong_type",
    "forged_source",
    "forged_auv",
    "replay",
    "duplicate_login",
    "future",
    "over_rate",
)
"""Why :class:`Gate` drops a message (the counter names)."""

OBSERVER_AHEAD_TICKS = 256
"""How far an observer (orchestrator, recorder) lets telemetry run ahead of the newest truth it heard."""

MAX_PER_TICK = 16
"""Distinct messages one key may carry per tick (modem frames by ``seq``); more are dropped as ``over_rate``."""


@dataclass(frozen=True)
class Origin:
    """What a key may carry: the message type, the only ``source`` allowed, and the AUV id of the key (or None)."""

    message: type[wire.Message]
    source: str
    auv: int | None

    @property
    def from_auv(self) -> bool:
        """True on the keys an AUV publishes (the untrusted principals; replays are checked there)."""
        return self.source.startswith("auv/")


_AUV_TAILS: dict[str, tuple[type[wire.Message], str | None]] = {
    "cmd": (wire.Command, None),
    "modem/tx": (wire.ModemTx, None),
    "telemetry": (wire.Telemetry, None),
    "modem/rx": (wire.ModemRx, "channel"),
    "nav": (wire.Nav, "world"),
    "sensor": (wire.Sensor, "world"),
    "plan": (wire.CentralPlan, "central"),
}
_FIXED: dict[str, tuple[type[wire.Message], str]] = {
    "world/clock": (wire.Clock, "world"),
    "world/truth": (wire.Truth, "world"),
    "world/events": (wire.WorldEvent, "world"),
    "channel/tick": (wire.ChannelTick, "world"),
    "channel/done": (wire.ChannelDone, "channel"),
    "channel/stats": (wire.ChannelStats, "channel"),
    "channel/events": (wire.PacketEvent, "channel"),
    "orchestrator/faults": (wire.FaultsInjected, "orchestrator"),
}


@functools.lru_cache(maxsize=4096)
def origin(key: str, prefix: str = wire.PREFIX) -> Origin | None:
    """The :class:`Origin` of a concrete key of the wire contract, or None for a key outside it (memoised: a swarm
    uses a few dozen keys, and every message is checked)."""
    head = f"{prefix}/"
    if not isinstance(key, str) or not key.startswith(head):
        return None
    rest = key[len(head) :]
    fixed = _FIXED.get(rest)
    if fixed is not None:
        return Origin(fixed[0], fixed[1], None)
    auv = wire.parse_auv_id(key)
    if auv is None or not rest.startswith(f"auv/{auv}/"):
        return None
    tail = _AUV_TAILS.get(rest[len(f"auv/{auv}/") :])
    if tail is None:
        return None
    message, source = tail
    return Origin(message, source or f"auv/{auv}", auv)


def check_source(key: str, msg: wire.Message, prefix: str = wire.PREFIX) -> str | None:
    """Why ``msg`` may not have arrived on ``key`` (a :data:`REASONS` entry), or None when it may.

    The key decides: its message type, its only allowed ``source``, and for
    ``<prefix>/auv/<id>/...`` keys the ``auv`` field (the addressee of a Nav,
    Sensor or ModemRx, the sender of a Command, ModemTx or Telemetry).
    """
    where = origin(key, prefix)
    if where is None:
        return "unknown_key"
    if type(msg) is not where.message:
        return "wrong_type"
    if msg.source != where.source:
        return "forged_source"
    if where.auv is not None and getattr(msg, "auv", None) != where.auv:
        return "forged_auv"
    return None


def _fingerprint(msg: wire.Message) -> object:
    """What tells two messages of one key and one tick apart (modem frames: ``seq``; others: nothing)."""
    return msg.seq if isinstance(msg, wire.ModemTx) else None


def _same(a: wire.Message, b: wire.Message) -> bool:
    """True when ``a`` and ``b`` are the same message (as encoded: a NaN field equals itself)."""
    return a == b or wire.encode(a) == wire.encode(b)


class Gate:
    """The admission check of one consumer: decode, identity from the key, replays; drops counted by reason.

    ``name`` prefixes the log lines; ``log`` receives each line (default: stderr). Each
    (sender, reason) pair is logged once, every drop is counted in :attr:`counts`. ``on_duplicate(key, msg)``
    is called (outside the lock) for every message dropped as ``duplicate_login``.
    Thread-safe: bus callbacks of several threads may share one gate.
    """

    def __init__(
        self,
        name: str,
        prefix: str = wire.PREFIX,
        log: Callable[[str], None] | None = None,
        on_duplicate: Callable[[str, wire.Message], None] | None = None,
    ) -> None:
        self.name = name
        self.prefix = prefix
        self.counts = dict.fromkeys(REASONS, 0)
        self._log = log or (lambda line: print(line, file=sys.stderr, flush=True))
        self._on_duplicate = on_duplicate
        self._logged: set[tuple[str, str]] = set()
        self._newest: dict[str, tuple[int, dict[object, wire.Message]]] = {}
        self._lock = threading.Lock()

    def receive(
        self, key: str, data: bytes, expected: type[wire.Message] | None = None, max_tick: int | None = None
    ) -> wire.Message | None:
        """Decode ``data`` that arrived on ``key`` and :meth:`admit` it; None when it is dropped."""
        try:
            msg = wire.decode(data, expected)
        except wire.DecodeError as exc:
            self._drop(key, "decode_error", str(exc))
            return None
        return msg if self.admit(key, msg, max_tick) else None

    def admit(self, key: str, msg: wire.Message, max_tick: int | None = None, track: bool = True) -> bool:
        """True when ``msg`` may be used as a message from ``key``'s publisher; else it is counted and dropped.

        ``max_tick``: the latest tick an AUV may stamp right now, when the consumer knows it (the
        world: its current tick). A later one is dropped as ``future`` before it can become the
        newest tick of its key, so it cannot make the AUV's next genuine messages look like replays.
        ``track=False``: the identity and ``future`` checks only; the consumer keeps its own books of what each
        key carried (the channel: frames by ``seq``, so that no frame's arrival order decides which are kept).
        """
        reason = check_source(key, msg, self.prefix)
        if reason is not None:
            self._drop(key, reason, f"{type(msg).__name__} from {msg.source!r}")
            return False
        tick = getattr(msg, "tick", None)
        if tick is None or not origin(key, self.prefix).from_auv:
            return True
        if max_tick is not None and tick > max_tick:
            self._drop(key, "future", f"{type(msg).__name__} of tick {tick}, latest allowed {max_tick}")
            return False
        if not track:
            return True
        with self._lock:
            newest = self._newest.get(key)
            mark = _fingerprint(msg)
            if newest is None or tick > newest[0]:
                self._newest[key] = (tick, {mark: msg})
                return True
            if tick == newest[0] and mark in newest[1] and not _same(newest[1][mark], msg):
                reason = "duplicate_login"
            elif tick < newest[0] or mark in newest[1]:
                reason = "replay"
            elif len(newest[1]) >= MAX_PER_TICK:
                reason = "over_rate"
            else:
                newest[1][mark] = msg
                return True
        self._drop(key, reason, f"{type(msg).__name__} of tick {tick}")
        if reason == "duplicate_login" and self._on_duplicate is not None:
            self._on_duplicate(key, msg)
        return False

    def forget(self) -> None:
        """Forget the newest ticks seen (the world restarted its mission: ticks start again at 0)."""
        with self._lock:
            self._newest.clear()

    def dropped(self) -> int:
        """How many messages were dropped, all reasons together."""
        with self._lock:
            return sum(self.counts.values())

    def _drop(self, key: str, reason: str, detail: str) -> None:
        where = origin(key, self.prefix)
        sender = where.source if where is not None else "a key outside the contract"
        with self._lock:
            self.counts[reason] += 1
            first = (sender, reason) not in self._logged
            self._logged.add((sender, reason))
        if first:
            self._log(
                f"{self.name}: dropped a message on {key} ({reason}: {detail}); "
                f"further {reason} drops from {sender} are only counted"
            )
