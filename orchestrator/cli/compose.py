"""``auv-swarm compose --agents N [-o FILE]``: write the docker-compose file of an N-AUV swarm.

The file, its services and their start order: :mod:`auv_swarm.orchestrator.mission.compose` (docs/containers.md).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from auv_swarm.bus import zbus
from auv_swarm.contract.usage import fail, plain_description
from auv_swarm.orchestrator.mission.compose import compose_text, secret_folders


def main(argv: list[str] | None = None) -> int:
    """CLI of ``auv-swarm compose``."""
    parser = argparse.ArgumentParser(prog="auv-swarm compose", description=plain_description(__doc__))
    parser.add_argument("--agents", type=int, default=3, help=f"number of AUVs, 1..{zbus.MAX_AGENTS}")
    parser.add_argument("-o", "--output", type=Path, default=None, help="file to write (default docker-compose.N.yml)")
    args = parser.parse_args(argv)
    if not 1 <= args.agents <= zbus.MAX_AGENTS:
        return fail(f"--agents must be in [1, {zbus.MAX_AGENTS}], got {args.agents}")
    out = args.output or Path(f"docker-compose.{args.agents}.yml")
    folders = Path(os.environ.get("CREDENTIALS_DIR") or out.resolve().parent / ".credentials")
    try:
        out.write_text(compose_text(args.agents), encoding="utf-8")
        for name in secret_folders(args.agents):
            (folders / name).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return fail(f"cannot write {exc.filename}: {exc.strerror}")
    print(f"wrote {out} for {args.agents} AUVs (credential folders in {folders}): docker-compose -f {out} up")
    return 0


if __name__ == "__main__":
    sys.exit(main())
