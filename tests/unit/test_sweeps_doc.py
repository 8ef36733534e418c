"""docs/sweeps.md: its SLURM job-script example renders (no SLURM needed), its store table is the store's."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from auv_swarm.orchestrator.sweep.store import FIXED_NAMES

ROOT = Path(__file__).resolve().parents[2]
PAGE = (ROOT / "docs" / "sweeps.md").read_text(encoding="utf-8")


def test_the_jobqueue_example_renders_a_job_script() -> None:
    pytest.importorskip("dask_jobqueue")
    block = PAGE.split("<!-- jobqueue-example -->")[1].split("<!-- /jobqueue-example -->")[0]
    code = block.split("```python")[1].split("```")[0]
    code = code.split("cluster.scale(")[0]  # no jobs are submitted: CI has no SLURM
    out = io.StringIO()
    scope: dict = {}
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, "docs/sweeps.md", "exec"), scope)
    finally:
        if "cluster" in scope:
            scope["cluster"].close()
    script = out.getvalue()
    assert script.startswith("#!/usr/bin/env bash") and "#SBATCH" in script
    assert "#SBATCH --partition=short" in script and "#SBATCH -t 04:00:00" in script
    assert "source ~/auv-swarm/.venv/bin/activate" in script and "distributed.cli.dask_worker" in script


def test_the_page_names_every_store_column() -> None:
    table = PAGE.split("<!-- generated:store-columns -->")[1].split("<!-- /generated -->")[0]
    assert re.findall(r"^\| `([a-z0-9_]+)` \|", table, flags=re.M) == list(FIXED_NAMES)
