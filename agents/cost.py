"""What a planner minimises: a :class:`Cost` of predicted states and actions, kept apart from the dynamics.

A rollout's return, which the planner maximises, is minus the sum of its stage costs over the horizon
minus its terminal cost. The costs here are the pendulum's, over states (θ, θ̇) in Gymnasium's
convention (θ = 0 upright): :class:`PendulumCost` (Gymnasium's reward) and :class:`EnergyCost` (the
swing-up with a weak motor). A latent model's cost (minus its predicted reward) lives with the model,
in :mod:`agents.planet.planner`.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import torch
from torch import Tensor

__all__ = ["Cost", "EnergyCost", "PendulumCost", "returns"]


class Cost(Protocol):
    """Stage and terminal costs of predicted trajectories (lower is better)."""

    def stage(self, states: Tensor, actions: Tensor) -> Tensor:
        """Cost (B, H) of each step: the states (B, H, S) reached under the actions (B, H, A)."""
        ...

    def terminal(self, final: Tensor) -> Tensor | None:
        """Cost (B,) of the last state (B, S), or None for a cost without a terminal term."""
        ...


def returns(cost: Cost, states: Tensor, actions: Tensor) -> Tensor:
    """Returns (B,) of trajectories: minus their summed stage costs and terminal cost.

    Args:
        states: (B, H, S) predicted states.
        actions: (B, H, A) the actions that led to them.
    """
    total = cost.stage(states, actions).sum(1)  # (B,)
    terminal = cost.terminal(states[:, -1])
    if terminal is not None:
        total.add_(terminal)
    return total.neg_()


class PendulumCost(NamedTuple):
    """Gymnasium's pendulum cost of a step, w_θ·wrap(θ − θ_goal)² + w_v·θ̇² + w_u·u², with
    wrap(x) = ((x + π) mod 2π) − π, over states (θ, θ̇) and actions (u,); no terminal term.
    :class:`agents.dynamics.PendulumDynamics` computes it inside its compiled rollout."""

    goal: float
    """θ_goal (Gymnasium's convention)."""
    angle_weight: float
    """w_θ."""
    velocity_weight: float
    """w_v."""
    action_weight: float
    """w_u."""

    def stage(self, states: Tensor, actions: Tensor) -> Tensor:
        angles, speeds, u = states[..., 0], states[..., 1], actions[..., 0]  # (B, H) each
        # in place, on tiny tensors, where each operator call costs more than its arithmetic
        cost = torch.remainder(angles - (self.goal - math.pi), 2 * math.pi).sub_(math.pi).square_()
        if self.angle_weight != 1.0:
            cost.mul_(self.angle_weight)
        return cost.addcmul_(speeds, speeds, value=self.velocity_weight).addcmul_(u, u, value=self.action_weight)

    def terminal(self, final: Tensor) -> None:
        return None


class EnergyCost(NamedTuple):
    """The swing-up cost for a weak motor, over states (θ, θ̇) and actions (u,); no terminal term:

        w_θ·(1 − cos θ) + w_E·((E − E*) / 2E*)² + w_u·u²,  E = θ̇² / 2 + k_g·cos θ,  E* = k_g,

    where k_g is the pendulum's gravity gain (θ̈ = k_g·sin θ + ...), so E* is the upright's energy at rest.
    The energy term rewards every step that pumps energy toward the upright's; the angle term takes
    over near the top.
    """

    gravity_gain: float
    """k_g, which sets the upright's energy."""
    angle_weight: float
    """w_θ."""
    energy_weight: float
    """w_E."""
    action_weight: float
    """w_u."""

    def stage(self, states: Tensor, actions: Tensor) -> Tensor:
        q, v, u = states[..., 0], states[..., 1], actions[..., 0]  # (B, H) each
        k_g = self.gravity_gain
        energy = 0.5 * v * v + k_g * torch.cos(q)  # (B, H)
        e = (energy - k_g) / (2 * k_g)
        return self.angle_weight * (1 - torch.cos(q)) + self.energy_weight * e * e + self.action_weight * u * u

    def terminal(self, final: Tensor) -> None:
        return None
