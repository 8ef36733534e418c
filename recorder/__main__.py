import sys

from recorder.node import main

sys.exit(main())
