"""``auv-swarm compare RUN_DIR RUN_DIR... [--out DIR] [--json]``: runs side by side.

Prints every metric of metrics.json (per-AUV figures aside) for each run with its difference to the first, then
every scenario key that differs (the seed included), with a one-line warning first when the runs come from
different base scenarios; writes ``compare.png`` (their team-mean tracking error against sim time) into ``--out``
(default: the current folder). ``--json`` prints the same as one JSON object. A folder that is not a run with its
raw data (record.parquet): one line, exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.results.compare import compare
from auv_swarm.results.export import ExportError


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm compare``."""
    parser = argparse.ArgumentParser(prog="auv-swarm compare", description=plain_description(__doc__))
    parser.add_argument("runs", type=Path, nargs="+", metavar="RUN_DIR", help="two or more results folders")
    parser.add_argument("--out", type=Path, default=None, help="folder for compare.png (default: the current one)")
    parser.add_argument("--json", action="store_true", help="print the comparison as JSON on stdout")
    args = parser.parse_args(argv)
    try:
        result = compare(args.runs, args.out)
    except (ExportError, OSError) as exc:
        return fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    if args.json:
        if result.warning:
            print(result.warning, file=sys.stderr)
        print(json.dumps(result.to_dict(), indent=2, allow_nan=False))
    else:
        print(result.text())
        print(f"\nwrote {result.figure}")
    return 0
