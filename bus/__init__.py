"""The runtime bus: the bus interface and its in-memory form (:mod:`.bus`), the zenoh client (:mod:`.zbus`),
credentials, identity (who may say what), the lifeline to a parent process and the process shells' arguments.
The shared language these carry (keys, messages, scenarios) is :mod:`auv_swarm.contract`."""
