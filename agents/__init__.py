"""Controllers: the CEM optimiser, the planner over a :class:`~agents.dynamics.Dynamics`, the piga MPC agent and the oracle."""
