"""The channel's books over a run: every channel process's (epoch's) last counters added up, and the frames
whose fate died with a channel process that was killed counted as lost, reason ``channel_restart``.

Pure: counters in, counters out (no bus, no clock). A channel process publishes its counters
(``ChannelStats``, see ``channel_sim.node``) before the ``ChannelDone`` of every tick that moved a frame,
so the last counters heard from a process that was killed describe it as of the last tick the world saw
it finish. What it held then is lost with it:

- the links (frame, recipient) it had on the air, its ``in_flight``: they are in its ``sent``;
- the frames the AUVs sent that it held, not yet on the air, and those sent while no channel was up:
  the next process is told of them on its first tick and never gets them (its ``tx_lost_restart``).
  Each is added to ``sent`` (the senders sent it) and its ``n - 1`` links are lost.

The identity the books keep, per link as the channel counts (``docs/channel.md``; the per-frame reasons
``oversize``, ``tx_backlog_full`` and ``outside_slot`` count frames that never went on the air, outside ``sent``)::

    sent * (n - 1) == delivered + sum(dropped_<link reason>) + in_flight_at_end

where ``in_flight_at_end`` is the last process's ``in_flight``: links still on their way when the mission
ended (neither delivered nor lost).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

RESTART_REASON = "channel_restart"
"""The reason of a link lost with a channel process that was killed."""
FRAME_REASONS = ("oversize", "tx_backlog_full", "outside_slot")
"""Drop reasons that count frames (decided before the frame goes on the air); the others count links
(the channel model's ``channel_sim.model.FRAME_REASONS``, restated here: results imports only the contract)."""
GAUGES = ("in_flight",)
"""Counters that say how things stand (not how many happened): the last process's value is the run's."""
NOT_COUNTS = ("epoch",)
"""Keys of the counters that are no count at all (the process's start time)."""


def run_totals(epochs: Sequence[Mapping[str, int]], n_agents: int) -> dict[str, int]:
    """The run's channel counters from the last counters of every channel process, in the order they started.

    Counts are summed; ``in_flight`` is the last process's (``in_flight_at_end`` too); every process but the
    last was killed, so its ``in_flight`` and the next ones' ``tx_lost_restart`` (times ``n_agents - 1``
    links) make ``dropped_channel_restart``, and ``tx_lost_restart`` joins ``sent``. ``epochs`` counts the
    processes. Raises ValueError if ``n_agents`` < 1.
    """
    if n_agents < 1:
        raise ValueError(f"n_agents must be >= 1, got {n_agents!r}")
    totals: dict[str, int] = {}
    for counters in epochs:
        for key, value in counters.items():
            if key not in NOT_COUNTS and key not in GAUGES:
                totals[key] = totals.get(key, 0) + int(value)
    in_flight = [int(c.get("in_flight", 0)) for c in epochs]
    lost_frames = totals.get("tx_lost_restart", 0)
    totals["sent"] = totals.get("sent", 0) + lost_frames
    totals[f"dropped_{RESTART_REASON}"] = sum(in_flight[:-1]) + (n_agents - 1) * lost_frames
    totals["in_flight"] = totals["in_flight_at_end"] = in_flight[-1] if in_flight else 0
    totals["epochs"] = len(epochs)
    return totals


def link_balance(
    dropped: Mapping[str, int], sent: int, delivered: int, in_flight_at_end: int, n_agents: int
) -> tuple[int, int]:
    """Both sides of the books' identity (module docstring): ``(sent_links, accounted_links)``, equal when
    every link is delivered, lost under one reason or still on its way. ``dropped``: reason -> count."""
    lost = sum(v for reason, v in dropped.items() if reason not in FRAME_REASONS)
    return sent * (n_agents - 1), delivered + lost + in_flight_at_end


def frame_balance(totals: Mapping[str, int]) -> tuple[int, int]:
    """The senders' count against the channel's, per frame: ``(tx_expected, accounted)``, where ``tx_expected``
    is what the AUVs said they sent for the ticks a channel process ran, and ``accounted`` the frames sent (on
    the air or lost with a process), dropped before the air, from a dead sender, or missing on a later tick."""
    accounted = sum(totals.get(k, 0) for k in ("sent", "tx_dead_sender", "tx_missing"))
    accounted += sum(totals.get(f"dropped_{r}", 0) for r in FRAME_REASONS)
    return totals.get("tx_expected", 0), accounted
