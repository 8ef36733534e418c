"""Which bus session speaks for each AUV: the world's binding, and the evidence of a stolen login (issue 44).

Every AUV process holds a liveliness token of its own session (``alive/auv/<id>/<session>``) and every message
it publishes carries that session's id (``bus.zbus``). :class:`Sessions` binds each AUV to the first session it
sees (a token or a message), and again to the first one after the bound session's token has gone (a restart is
a rejoin, not an impostor). Any other session that speaks for the AUV (a command, a frame, telemetry or a token)
while the bound one is up is evidence of a second login with that AUV's password: the AUV is *compromised*
(:attr:`Sessions.compromised`) and the world quarantines it. While the world counts the AUV dead (killed, its
restart pending), a new session's token is its restart, not evidence: it is bound once the old token goes.

On a bus without sessions (the in-process swarm) every token and message has session None, so nothing here
changes an honest run: the AUV binds to None and no second session can appear.

Pure: no clock, no I/O; the world's lockstep feeds it.
"""

from __future__ import annotations

from collections.abc import Iterable


class Sessions:
    """The binding of AUV id -> bus session and the AUVs found compromised (see the module docstring)."""

    def __init__(self, ids: Iterable[int]) -> None:
        self.bound: dict[int, str | None] = {}
        """AUV -> the session bound to it (None: a bus without sessions); absent until one is seen."""
        self.up: dict[int, dict[str | None, None]] = {a: {} for a in ids}
        """AUV -> the sessions holding its token now, in the order they appeared."""
        self.compromised: dict[int, str] = {}
        """AUV -> what gave the second login away (its first evidence)."""
        self.detected: list[int] = []
        """Compromised AUVs not reported yet (the lockstep reports and quarantines them at its next tick)."""

    def known(self, auv: int) -> bool:
        """True for an AUV of the mission."""
        return auv in self.up

    def holds(self, auv: int) -> bool:
        """True while the bound session's token is up (the AUV's process lives)."""
        return auv in self.bound and self.bound[auv] in self.up[auv]

    def on_token(self, auv: int, session: str | None, alive: bool, dead: bool) -> None:
        """AUV ``auv``'s token of ``session`` appeared (``alive``) or went; ``dead``: the world counts the AUV
        dead right now (killed, its restart pending), so a new session is its restart."""
        up = self.up[auv]
        if not alive:
            up.pop(session, None)
            if session == self.bound.get(auv) and dead and up:
                self.bound[auv] = next(iter(up))  # the restarted process that came up before the old one went
            return
        bound_up = self.holds(auv)
        up[session] = None
        if not bound_up:
            self.bound[auv] = session
        elif session != self.bound[auv] and not dead:
            self._evidence(auv, f"a second session holds AUV {auv}'s liveliness token")

    def on_message(self, auv: int, session: str | None, what: str, dead: bool) -> bool:
        """A ``what`` (command, frame, telemetry) on AUV ``auv``'s key from ``session``: True when it may be used
        (the bound session's, of an AUV not compromised); a message of another session is evidence, unless the
        world counts the AUV dead (nothing it says is used then)."""
        if auv in self.compromised:
            return False
        if auv not in self.bound:
            self.bound[auv] = session
            return True
        if session == self.bound[auv]:
            return True
        if not dead:
            self._evidence(auv, f"a {what} on AUV {auv}'s key from a second session")
        return False

    def report(self, auv: int, text: str) -> None:
        """Other evidence of a second login (two different commands of one tick: ``bus.identity``)."""
        self._evidence(auv, text)

    def channel_sessions(self) -> dict[int, str]:
        """What the channel is told (``ChannelTick.sessions``): each bound AUV's session, where the bus has them."""
        return {a: s for a, s in sorted(self.bound.items()) if s is not None and a not in self.compromised}

    def _evidence(self, auv: int, text: str) -> None:
        if auv not in self.compromised:
            self.compromised[auv] = text
            self.detected.append(auv)
