"""The stable-baselines3 baselines: DDPG and SAC (:mod:`agents.sb3.config`, one config whose ``algo`` picks the
algorithm and its zoo values), from pixels, from an autoencoder's latent (:mod:`agents.sb3.autoencoder`) or from
the true state; :mod:`agents.sb3.train` trains a run, :mod:`agents.sb3.run` reads it back as an agent."""

from agents.sb3.config import SB3Config

__all__ = ["SB3Config"]
