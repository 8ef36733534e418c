"""``auv-swarm compose --agents N [-o FILE]``: write the docker-compose file of an N-AUV swarm.

The checked-in ``docker-compose.yml`` is this generator's output for 3 AUVs (a test
keeps them equal). The file follows the Compose Specification with nothing
v2-only (no top-level ``version:`` or ``name:``), so docker-compose 1.29 and
``docker compose`` v2 both run it. One container per process; the service names
are the hostnames (clients connect to ``tcp/router:7447``, no multicast scouting).

Start order: ``setup`` (one-shot: run folder, scenario.toml) and ``credentials``
(one-shot: one password file per process) complete first; then the router;
then the channel, the AUVs, the recorder and the collector, which retry the
router until ``CONNECT_RETRY_S``; the world waits for all of them by their
liveliness tokens (no healthchecks: each is a ``docker exec`` per interval).
Every process ends with the mission, so ``docker-compose up`` returns; the
collector's exit status is the mission's exit code.
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
