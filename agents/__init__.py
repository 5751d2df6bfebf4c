"""Controllers and baselines: CEM planning, the piga MPC agent, the oracle, PlaNet and DDPG."""
