"""The PlaNet-style baseline: an RSSM world model learned from pixels and rewards, and CEM in its latent space."""

from agents.planet.config import IterativeConfig, LatentPlannerConfig, PlanetTrainConfig, RSSMConfig

__all__ = ["IterativeConfig", "LatentPlannerConfig", "PlanetTrainConfig", "RSSMConfig"]
