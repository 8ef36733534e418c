import sys

from auv_swarm.world.node import main

sys.exit(main())
