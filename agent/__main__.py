import sys

from auv_swarm.agent.node import main

sys.exit(main())
