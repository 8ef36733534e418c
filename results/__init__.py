"""What a mission leaves behind, from the bus messages a recorder heard to the files of a results folder.

- :mod:`.collect`: :class:`~.collect.MessageLog`, the sink that files every message and builds the run record;
- :mod:`.record`: :class:`~.record.RunRecord`, the run as columns (truth, estimates, plans, events, channel counts);
- :mod:`.metrics`: ``compute_metrics``, every figure of ``metrics.json`` (docs/results.md);
- :mod:`.tracking`: NEES and the lost-track metrics; :mod:`.channel_books`: the channel's counters over a run;
- :mod:`.report`: ``write_results``, the folder's files (metrics.json, events.jsonl, the figures);
- :mod:`.summary`: the console summary.

Pure: numpy, json and matplotlib (imported when a figure is drawn); it imports nothing of the swarm but
``auv_swarm.contract``.
"""
