"""The ``auv-swarm`` command line: the dispatcher (:mod:`.main`) and each verb's argument parsing."""
