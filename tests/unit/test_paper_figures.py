"""The paper comparisons the README quotes, re-run in full (slow: Monte-Carlo, `pytest -m slow`)."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import pytest

from auv_swarm.bench.table3 import PAPER, SCENARIOS, one_run, summarise

pytestmark = pytest.mark.slow

SEEDS = range(1, 11)


@pytest.mark.timeout(3600)
def test_section_3_3_mean_and_std_below_the_paper_dmpc_row() -> None:
    """`auv-swarm bench table3`: 5 scenarios x 10 seeds x 1500 s, in process (README, Measured figures)."""
    jobs = [(name, "dmpc", seed) for name in SCENARIOS for seed in SEEDS]
    with ProcessPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(one_run, *zip(*jobs, strict=True)))
    for name in SCENARIOS:
        paper_mean, paper_std = PAPER[(name, "dmpc")][:2]
        row = summarise(name, "dmpc", [r for (n, _, _), r in zip(jobs, runs, strict=True) if n == name])
        assert row["error_mean_m"] < paper_mean, row
        assert row["error_std_m"] < paper_std, row


def test_section_3_2_survivors_stay_within_15_m_after_the_loss() -> None:
    """`auv-swarm run` (seed 1): after AUV 1 dies at 750 s every survivor sample is within 15 m (Fig. 7b)."""
    metrics = one_run("paper-3.2-challenging", "dmpc", 1)
    after = metrics["after_first_kill"]
    assert after["t_s"] == 750.0 and after["samples"] > 0
    assert after["fraction_below_threshold"] == 1.0
    assert after["tracking_error_mean_m"] < 10.0
