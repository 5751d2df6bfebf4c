"""The PlaNet-style baseline: an RSSM world model learned from pixels and rewards (:mod:`.rssm`), CEM in its latent space (:mod:`.planner`), its training loop (:mod:`.train`, and PlaNet's collect-then-train loop, :mod:`.iterative`) and reading its run (:mod:`.run`)."""

from agents.planet.config import IterativeConfig, LatentPlannerConfig, PlanetTrainConfig, RSSMConfig

__all__ = ["IterativeConfig", "LatentPlannerConfig", "PlanetTrainConfig", "RSSMConfig"]
