import sys

from agent.node import main

sys.exit(main())
