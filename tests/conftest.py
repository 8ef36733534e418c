"""Settings for every test run.

A shell without job control starts a background job with SIGINT ignored (``pytest ... &`` in a script), and a
child inherits an ignored signal through exec, so the CLI under test would never see the tests' Ctrl-C. A
handled signal is reset to its default on exec instead: handling SIGINT here gives every process the tests
start the Ctrl-C a terminal would send, however pytest itself was started.
"""

from __future__ import annotations

import signal

if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
