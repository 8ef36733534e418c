import sys

from auv_swarm.recorder.node import main

sys.exit(main())
