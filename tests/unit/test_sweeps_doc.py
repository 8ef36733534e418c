"""docs/sweeps.md: its SLURM job-script example renders with the TLS flags (no SLURM needed), its cluster recipe
carries Dask's TLS flags and names an address, its store table is the store's."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from auv_swarm.orchestrator.sweep.store import FIXED_NAMES

ROOT = Path(__file__).resolve().parents[2]
PAGE = (ROOT / "docs" / "sweeps.md").read_text(encoding="utf-8")


def test_the_jobqueue_example_renders_a_job_script(tmp_path, monkeypatch) -> None:
    pytest.importorskip("dask_jobqueue")
    from auv_swarm.bus import credentials

    monkeypatch.setenv("HOME", str(tmp_path))
    assert credentials.main(["--dask", str(tmp_path / "auv-swarm-tls")]) == 0
    block = PAGE.split("<!-- jobqueue-example -->")[1].split("<!-- /jobqueue-example -->")[0]
    code = block.split("```python")[1].split("```")[0]
    code = code.split("cluster.scale(")[0]  # no jobs are submitted: CI has no SLURM
    assert 'interface="ib0"' in code
    code = code.replace('interface="ib0"', 'interface="lo"')  # no InfiniBand here
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
    worker = next(line for line in script.splitlines() if "distributed.cli.dask_worker" in line)
    assert " tls://127.0.0.1:" in worker and "--protocol tls://" in worker and "--interface lo" in worker
    for flag, name in (("--tls-ca-file", "ca.pem"), ("--tls-cert", "worker.pem"), ("--tls-key", "worker.key")):
        assert f"{flag} {tmp_path / 'auv-swarm-tls' / name}" in worker, worker
    assert "--dashboard-address 127.0.0.1:0" in worker


def test_the_cluster_recipe_uses_tls_and_names_where_to_listen() -> None:
    block = PAGE.split("<!-- cluster-recipe -->")[1].split("<!-- /cluster-recipe -->")[0]
    commands = block.replace("\\\n", " ").split("```")[1].strip().splitlines()
    scheduler, worker, sweep = (
        next(c for c in commands if c.startswith(p)) for p in ("dask scheduler", "dask worker", "auv-swarm")
    )
    for command, role in ((scheduler, "scheduler"), (worker, "worker")):
        words = command.split()
        assert (
            words[words.index("--tls-cert") + 1] == f"$T/{role}.pem"
            and words[words.index("--tls-key") + 1] == f"$T/{role}.key"
        )
        assert words[words.index("--tls-ca-file") + 1] == "$T/ca.pem"
        assert (
            words[words.index("--host") + 1] == "127.0.0.1"
            and words[words.index("--dashboard-address") + 1] == "127.0.0.1:0"
        )
    assert "--protocol tls" in scheduler and " tls://127.0.0.1:8786 " in worker
    assert "--scheduler tls://127.0.0.1:8786 --tls-dir $T" in sweep


def test_the_page_names_every_store_column() -> None:
    table = PAGE.split("<!-- generated:store-columns -->")[1].split("<!-- /generated -->")[0]
    assert re.findall(r"^\| `([a-z0-9_]+)` \|", table, flags=re.M) == list(FIXED_NAMES)
