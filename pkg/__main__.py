"""``python -m auv_swarm VERB ...``: the same as the ``auv-swarm`` command."""

import sys

from auv_swarm.orchestrator.cli.main import main

sys.exit(main())
