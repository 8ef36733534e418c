"""The section 3.3 baselines beside our DMPC: dec-MPC, distributed PSO and centralised MPC.

All three minimise the DMPC's own cost (eq. 38 with the constraints of eq. 50) through
:mod:`agent.baselines.cost`; they differ in what an AUV knows of the others and how it
searches. The method of a run is ``planner.method`` (registry: :mod:`auv_swarm.agent.methods`); see
docs/baselines.md.
"""
