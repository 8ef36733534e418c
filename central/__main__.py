"""``python -m auv_swarm.central``: the central planner process (same as ``auv-swarm central``)."""

import sys

from auv_swarm.central.node import main

sys.exit(main())
