import sys

from world.node import main

sys.exit(main())
