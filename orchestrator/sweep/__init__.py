"""Sweeps: a grid of missions (:mod:`.grid`) run on Dask (:mod:`.engine`, :mod:`.worker`) into a resumable
SQLite store (:mod:`.store`), then summarised (:mod:`.summary`); :func:`.execute.execute` is the verb's work."""
