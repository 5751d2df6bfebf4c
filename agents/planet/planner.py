"""PlaNet's agent: filter the latent state from frames, then CEM over action sequences in latent space.

At each step the agent takes the newest frame, updates its belief (h_t from the last state and the
action it executed, then s_t from the posterior given the frame), and plans with the shared
:class:`agents.planner.Planner` over the model's latent dynamics (:class:`LatentDynamics`: states
[h, s] (B, D + S), sampled from the prior) and minus its predicted reward (:class:`RewardCost`): each
candidate sequence (B, H, A) is scored by the sum of the rewards the model predicts over H imagined
steps. As in PlaNet, every step re-plans from scratch (no warm start) and executes the first action
of CEM's final mean. With the model's action repeat R, a step is R env steps: the agent reads every
R-th frame, plans there, and holds the action for R env steps.

The latent dynamics scores :class:`RewardCost` in one pass with
:class:`agents.planet.imagine.Imagination`, which computes :meth:`WorldModel.imagine_return`'s numbers
(same random draws, float rounding apart) without its per-step allocations; ``fast=False`` rolls out
step by step with the model's own modules and scores the states with its reward head instead.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import Tensor

from agents.cost import Cost
from agents.dynamics import Scorer
from agents.planet.config import LatentPlannerConfig
from agents.planet.imagine import Imagination
from agents.planet.rssm import Belief, WorldModel, held, sample
from agents.planner import Planner
from envs.constants import MAX_ACTION

__all__ = ["LatentDynamics", "PlanetAgent", "RewardCost"]


def features(belief: Belief) -> Tensor:
    """A belief's states [h, s] (B, D + S), the latent dynamics' state."""
    return torch.cat([belief.h, belief.s], -1)


class RewardCost:
    """Minus the model's predicted reward of each latent state [h, s]; no terminal term.

    Args:
        model: the world model whose reward head scores the states.
    """

    def __init__(self, model: WorldModel):
        self.model = model

    def stage(self, states: Tensor, actions: Tensor) -> Tensor:
        """Cost (B, H) of latent states (B, H, D + S)."""
        return self.model.reward_head(states)[..., 0].neg()

    def terminal(self, final: Tensor) -> None:
        return None


class LatentDynamics:
    """The world model's prior as a :class:`agents.dynamics.Dynamics` over latent states [h, s] (B, D + S):
    each step, h from the RSSM's transition under the action held for R env steps, then s sampled from
    the prior with the planner's generator. Also a :class:`agents.dynamics.FusedDynamics`: for the same
    model's :class:`RewardCost` it scores with :class:`Imagination` (``fast``).

    Args:
        model: the world model.
        fast: offer the fused :class:`Imagination` scorer.
    """

    def __init__(self, model: WorldModel, fast: bool = True):
        self.model = model
        self.imagination = Imagination(model) if fast else None

    def split(self, state: Tensor) -> Belief:
        """The belief (h (B, D), s (B, S)) of latent states (B, D + S)."""
        return Belief(state[:, :self.model.config.deter_size], state[:, self.model.config.deter_size:])

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Latent states (B, H, D + S) of the H model steps after ``state`` ((1, D + S) or (B, D + S)) under
        actions (B, H, A), each held for R env steps; s sampled from the prior."""
        b, horizon = actions.shape[:2]
        rssm = self.model.rssm
        held_actions = held(actions, self.model.config.action_repeat)  # (B, H, R·A)
        belief = self.split(state.expand(b, -1))
        states = []
        for step in range(horizon):
            h, prior = rssm.transition(belief, held_actions[:, step])
            belief = Belief(h, sample(prior, generator))
            states.append(features(belief))
        return torch.stack(states, 1)  # (B, H, D + S)

    def fused(self, state: Tensor, cost: Cost, generator: torch.Generator | None = None) -> Scorer | None:
        """:class:`Imagination`'s sums of predicted rewards from ``state`` (1, D + S), for this model's
        :class:`RewardCost` (``fast``)."""
        imagination = self.imagination
        if imagination is None or not isinstance(cost, RewardCost) or cost.model is not self.model:
            return None
        belief = self.split(state)
        return lambda actions: imagination(belief, actions, generator)

    def reset(self) -> None:
        """Nothing to forget (the agent keeps the belief)."""

    def executed(self, action: np.ndarray) -> None:
        """No history."""


class PlanetAgent:
    """Control from pixels with a trained :class:`WorldModel` and latent CEM.

    It keeps its own belief across steps, so it needs only the newest frame: episodes give it a
    stack of one frame (``input_frames`` = 1). Randomness (posterior and prior samples, CEM's
    candidates) comes from one generator seeded with ``config.seed`` at each :meth:`reset`, so an
    episode is deterministic for a seed.

    Args:
        model: a trained world model.
        config: planner settings (PlaNet's by default).
        fast: score candidates with :class:`Imagination` (True) or by rolling out, then scoring.
        device: where the model filters and plans ("cpu", or "cuda" for PlaNet's batched CEM on a GPU; the
            model is moved there). A CUDA generator draws other numbers than the CPU's for the same seed.
    """

    input_frames = 1
    """Frames the agent needs per decision (its belief carries the history)."""

    def __init__(self, model: WorldModel, config: LatentPlannerConfig = LatentPlannerConfig(), fast: bool = True,
                 device: str | torch.device = "cpu"):
        if model.config.action_dim != 1:
            raise ValueError(f"PlanetAgent controls the pendulum (one action), got a model with action_dim={model.config.action_dim}")
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()
        self.config = config
        self.repeat = model.config.action_repeat
        self.planner = Planner(LatentDynamics(model, fast), RewardCost(model), [-MAX_ACTION], [MAX_ACTION], config.cem,
                               warm_start="off", seed=config.seed, device=self.device)
        self.generator = self.planner.generator
        """The planner's generator, which the posterior samples also draw from."""
        self.reset()

    def reset(self) -> None:
        """Starts an episode: the zero state, no previous action, the generator reseeded."""
        self.planner.reset()
        self.belief = self.model.rssm.initial(1)
        self.previous = torch.zeros(1, self.model.config.input_action_size, device=self.device)  # (1, R·A) the actions since the last read frame
        self.action = np.zeros(1, np.float32)  # (1,) the action held
        self.left = 0  # env steps the held action has left
        self.planned = False  # whether the last act planned (episodes time only those steps)

    @torch.inference_mode()
    def observe(self, frame: np.ndarray) -> Belief:
        """Updates the belief with the newest frame, uint8 (H, W) (after the previous action); returns it."""
        h, _ = self.model.rssm.transition(self.belief, self.previous)
        embed = self.model.embed(torch.from_numpy(np.ascontiguousarray(frame)).to(self.device)[None, None])[:, 0]  # (1, E)
        self.belief = Belief(h, sample(self.model.rssm.posterior(h, embed), self.generator))
        return self.belief

    def plan(self, belief: Belief) -> np.ndarray:
        """The first action (1,) of CEM's final mean from ``belief`` ((1, ·) states)."""
        return self.planner.plan(features(belief))[0]

    def _step(self, frames: np.ndarray, choose: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """The action (1,) for this env step: at the start of a model step, read the newest frame of
        ``frames`` (uint8 (L, H, W)), plan, and hold ``choose(planned)`` for R env steps."""
        self.planned = self.left == 0
        if self.planned:
            self.action = choose(self.plan(self.observe(frames[-1])))
            self.previous = held(torch.from_numpy(self.action).to(self.device)[None], self.repeat)  # (1, R·A): what the next read follows
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
