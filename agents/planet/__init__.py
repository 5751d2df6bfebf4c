"""The PlaNet-style baseline: an RSSM world model learned from pixels and rewards, and CEM in its latent space."""

from agents.planet.config import LatentPlannerConfig, PlanetTrainConfig, RSSMConfig

__all__ = ["LatentPlannerConfig", "PlanetTrainConfig", "RSSMConfig"]
