"""The recorder's cost: an in-process mission without and with a :class:`~auv_swarm.recorder.core.RerunRecorder` sink."""

from __future__ import annotations

import math
import time
from pathlib import Path

from auv_swarm.contract.config import Scenario
from auv_swarm.recorder.core import RerunRecorder


def overhead(scenario: Scenario, out_dir: Path, repeats: int = 1) -> dict[str, float]:
    """Wall time of an in-process run without and with a :class:`RerunRecorder` sink (best of ``repeats``).

    Returns ``without_s``, ``with_s``, ``ratio`` (with / without), ``recorder_busy_s``
    (wall time spent inside the recorder) and ``rrd_bytes``. The recording goes to
    ``out_dir/recording.rrd``.
    """
    from auv_swarm.orchestrator.mission.api import run_mission

    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    without, with_rec, busy = math.inf, math.inf, math.inf
    path = Path(out_dir) / "recording.rrd"
    for _ in range(repeats):
        start = time.perf_counter()
        run_mission(scenario)
        without = min(without, time.perf_counter() - start)
        start = time.perf_counter()
        with RerunRecorder(scenario, path) as recorder:
            run_mission(scenario, sinks=[recorder])
        with_rec = min(with_rec, time.perf_counter() - start)
        busy = min(busy, recorder.busy_s)
    return {
        "without_s": without,
        "with_s": with_rec,
        "ratio": with_rec / without,
        "recorder_busy_s": busy,
        "rrd_bytes": float(path.stat().st_size),
    }
