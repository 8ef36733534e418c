"""The same mission gives about the same recording size however often the recorder sent its rows (paced or not)."""

from __future__ import annotations

from pathlib import Path

from auv_swarm.contract.config import load_scenario
from auv_swarm.recorder.core import RerunRecorder
from auv_swarm.recorder.options import RecorderOptions
from tests.unit.test_recorder import read_rrd, synthetic_mission


def _record(path: Path, flush_every: int, compact: bool) -> Path:
    scenario = load_scenario("paper-3.2-challenging").with_overrides(agents=3)
    options = RecorderOptions(flush_every=flush_every, flush_after_s=1e9, compact_at_close=compact)
    with RerunRecorder(scenario, path, options) as recorder:
        for msg in synthetic_mission(n_ticks=60):
            recorder.on_message(msg)
    return path


def test_paced_and_unpaced_recordings_hold_the_same_data_in_about_the_same_size(tmp_path: Path) -> None:
    # A paced run (--speed 5: a tick every 0.4 s of wall time) sends its rows about every 2 ticks, when the oldest
    # has waited 0.5 s; an unpaced run sends them every 250 ticks (here: once, at the end).
    raw_paced = _record(tmp_path / "raw-paced.rrd", 2, compact=False)
    raw_unpaced = _record(tmp_path / "raw-unpaced.rrd", 250, compact=False)
    paced = _record(tmp_path / "paced.rrd", 2, compact=True)
    unpaced = _record(tmp_path / "unpaced.rrd", 250, compact=True)
    size = {p.stem: p.stat().st_size for p in (raw_paced, raw_unpaced, paced, unpaced)}
    assert size["raw-paced"] > 3 * size["raw-unpaced"], f"the many small chunks of a paced run are the cost: {size}"
    assert abs(size["paced"] - size["unpaced"]) <= 0.15 * size["unpaced"], size
    assert size["paced"] < size["raw-paced"] / 3, size
    assert read_rrd(paced) == read_rrd(raw_paced) == read_rrd(unpaced)
