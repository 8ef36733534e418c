"""Running the swarm: one mission (:mod:`.mission`), grids of missions on Dask (:mod:`.sweep`) and the
``auv-swarm`` command line (:mod:`.cli`)."""
