"""The paper comparisons the README quotes, re-run in full (slow: Monte-Carlo, `pytest -m slow`)."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import pytest

from bench.table3 import PAPER_DMPC, one_run, summarise

pytestmark = pytest.mark.slow

SEEDS = range(1, 11)


@pytest.mark.timeout(3600)
def test_section_3_3_mean_and_std_below_the_paper_dmpc_row() -> None:
    """`auv-swarm bench table3`: 5 scenarios x 10 seeds x 1500 s, in process (README, Measured figures)."""
    jobs = [(name, seed) for name in sorted(PAPER_DMPC) for seed in SEEDS]
    with ProcessPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(one_run, *zip(*jobs, strict=True)))
    for name, (paper_mean, paper_std) in sorted(PAPER_DMPC.items()):
        row = summarise(name, [r for (n, _), r in zip(jobs, runs, strict=True) if n == name])
        assert row["tracking_error_mean_m"] < paper_mean, row
        assert row["tracking_error_std_m"] < paper_std, row


def test_section_3_2_survivors_stay_within_15_m_after_the_loss() -> None:
    """`auv-swarm run` (seed 1): after AUV 1 dies at 750 s every survivor sample is within 15 m (Fig. 7b)."""
    metrics = one_run("paper-3.2-challenging", 1)
    after = metrics["after_first_kill"]
    assert after["t_s"] == 750.0 and after["samples"] > 0
    assert after["fraction_below_threshold"] == 1.0
    assert after["tracking_error_mean_m"] < 10.0
