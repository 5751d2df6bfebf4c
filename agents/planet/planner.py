"""PlaNet's agent: filter the latent state from frames, then CEM over action sequences in latent space.

At each step the agent takes the newest frame, updates its belief (h_t from the last state and the
action it executed, then s_t from the posterior given the frame), and plans with
:func:`agents.cem.cem`: each candidate sequence (B, H, A) is scored by the sum of the rewards the
model predicts over H imagined steps (states sampled from the prior). As in PlaNet, every step
re-plans from scratch (no warm start) and executes the first action of CEM's final mean. With the
model's action repeat R, a step is R env steps: the agent reads every R-th frame, plans there, and
holds the action for R env steps.

The scores come from :class:`agents.planet.imagine.Imagination`, which computes
:meth:`WorldModel.imagine_return`'s numbers (same random draws, float rounding apart) without its
per-step allocations; ``fast=False`` scores with the reference method instead.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from agents.cem import cem
from agents.planet.config import LatentPlannerConfig
from agents.planet.imagine import Imagination
from agents.planet.rssm import Belief, WorldModel, held, sample
from envs.constants import MAX_ACTION

__all__ = ["PlanetAgent"]


class PlanetAgent:
    """Control from pixels with a trained :class:`WorldModel` and latent CEM.

    It keeps its own belief across steps, so it needs only the newest frame: episodes give it a
    stack of one frame (``input_frames`` = 1). Randomness (posterior and prior samples, CEM's
    candidates) comes from one generator seeded with ``config.seed`` at each :meth:`reset`, so an
    episode is deterministic for a seed.

    Args:
        model: a trained world model.
        config: planner settings (PlaNet's by default).
        fast: score candidates with :class:`Imagination` (True) or :meth:`WorldModel.imagine_return`.
    """

    input_frames = 1
    """Frames the agent needs per decision (its belief carries the history)."""

    def __init__(self, model: WorldModel, config: LatentPlannerConfig = LatentPlannerConfig(), fast: bool = True):
        if model.config.action_dim != 1:
            raise ValueError(f"PlanetAgent controls the pendulum (one action), got a model with action_dim={model.config.action_dim}")
        self.model = model.eval()
        self.config = config
        self.low = torch.tensor([-MAX_ACTION])
        self.high = torch.tensor([MAX_ACTION])
        self.repeat = model.config.action_repeat
        self.generator = torch.Generator().manual_seed(config.seed)
        self.score = Imagination(model) if fast else model.imagine_return
        self.reset()

    def reset(self) -> None:
        """Starts an episode: the zero state, no previous action, the generator reseeded."""
        self.generator.manual_seed(self.config.seed)
        self.belief = self.model.rssm.initial(1)
        self.previous = torch.zeros(1, self.model.config.input_action_size)  # (1, R·A) the actions since the last read frame
        self.action = np.zeros(1, np.float32)  # (1,) the action held
        self.left = 0  # env steps the held action has left
        self.planned = False  # whether the last act planned (episodes time only those steps)

    @torch.inference_mode()
    def observe(self, frame: np.ndarray) -> Belief:
        """Updates the belief with the newest frame, uint8 (H, W) (after the previous action); returns it."""
        h, _ = self.model.rssm.transition(self.belief, self.previous)
        embed = self.model.embed(torch.from_numpy(np.ascontiguousarray(frame))[None, None])[:, 0]  # (1, E)
        self.belief = Belief(h, sample(self.model.rssm.posterior(h, embed), self.generator))
        return self.belief

    @torch.inference_mode()
    def plan(self, belief: Belief) -> np.ndarray:
        """The first action (1,) of CEM's final mean from ``belief`` ((1, ·) states)."""
        result = cem(lambda actions: self.score(belief, actions, self.generator),
                     self.low, self.high, self.config.cem, generator=self.generator)
        return result.mean[0].clamp(self.low, self.high).numpy().astype(np.float32)

    def _step(self, frames: np.ndarray, choose: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """The action (1,) for this env step: at the start of a model step, read the newest frame of
        ``frames`` (uint8 (L, H, W)), plan, and hold ``choose(planned)`` for R env steps."""
        self.planned = self.left == 0
        if self.planned:
            self.action = choose(self.plan(self.observe(frames[-1])))
            self.previous = held(torch.from_numpy(self.action)[None], self.repeat)  # (1, R·A): what the next read follows
            self.left = self.repeat
        self.left -= 1
        return self.action.copy()

    def explore(self, frames: np.ndarray, rng: np.random.Generator, noise: float) -> np.ndarray:
        """As :meth:`act`, plus PlaNet's exploration: the planned action (1,) plus N(0, (noise·bound)²),
        clipped to the bounds, held for R env steps; the belief then follows the action executed."""
        return self._step(frames, lambda planned: np.clip(planned + noise * MAX_ACTION * rng.standard_normal(1),
                                                          -MAX_ACTION, MAX_ACTION).astype(np.float32))

    def act(self, frames: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
        """Action (1,) from the newest frame of ``frames`` (uint8 (L, H, W)); ``state`` is never used."""
        return self._step(frames, lambda planned: planned)
