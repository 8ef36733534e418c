"""The central planner of the centralised MPC baseline (section 3.3): core (pure) and node (process shell)."""
