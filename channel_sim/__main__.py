"""``python -m channel_sim``: the acoustic channel emulator process (same as ``auv-swarm channel``)."""

import sys

from auv_swarm.channel_sim.node import main

sys.exit(main())
