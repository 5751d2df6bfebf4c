"""A learned objective for the piga agent: a reward head over piga's own encoded state, in place of Gymnasium's cost.

The piga agent plans by default against Gymnasium's exact cost (:class:`agents.cost.PendulumCost`), which it is
given. This module learns that objective instead, as the PlaNet-style baseline does (:mod:`agents.planet.rssm`):
a small MLP regresses the file's ``/rewards`` with PlaNet's reward loss, ½·(r̂ − r)². Its input is the state that
the agent itself plans from, read from the frames by the trained model (the encoder's angle plus the model's
offset φ, and the velocity estimator's velocity: never ``/states``), and the action:

| input | meaning |
|---|---|
| cos θ_t, sin θ_t | the encoded angle (Gymnasium's convention, θ = model angle + φ), as a point on the circle |
| θ̇_t | the velocity estimator's velocity over the L frames ending at frame t |
| u_t | the action after frame t |

The pairing is PlaNet's ``reward_alignment="frame"`` plus the action: ``rewards[n, t]`` is the env's reward for
the action after frame t, read against the state of frame t (the first state is that of frame L − 1, the first
with L frames behind it). The angle enters as (cos θ, sin θ) because the planner's rollouts wind past ±π while the
encoder reads angles within it: a head on θ itself would score a wound angle as far from upright.

:class:`LearnedCost` is a :class:`~agents.cost.Cost` (minus the head's reward, per step, no terminal term), so it
plugs into the one planner (:class:`agents.planner.Planner`) as Gymnasium's cost does; with it the planner is
goal-free (the head learned one task, upright's).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.torch_layers import create_mlp
from torch import Tensor, nn

from piga.io.choices import check_ranges, check_types
from piga.world.model import PhysicsModel, frames_to_float

__all__ = ["LearnedCost", "RewardHead", "RewardHeadConfig", "encoded_transitions", "load_reward_head",
           "save_reward_head", "train_reward_head"]


@dataclass(frozen=True)
class RewardHeadConfig:
    """The reward head and its training (PlaNet's reward loss, Adam)."""

    hidden: int = 64
    """Width of each hidden layer."""
    layers: int = 2
    """Hidden layers (ReLU)."""
    steps: int = 3000
    """Adam steps on minibatches of the train split's transitions."""
    batch_size: int = 256
    """Transitions per step."""
    lr: float = 1e-3
    """Adam's learning rate."""
    seed: int = 0
    """Seed of the head's initialisation and of the minibatches."""

    def __post_init__(self) -> None:
        check_types(self)  # hidden="64" was compared with 1
        check_ranges(self, {"lr": (0, math.inf), "seed": (0, 2**63 - 1)}, above=("lr",))
        if min(self.hidden, self.layers, self.steps, self.batch_size) < 1 or not self.lr > 0:
            raise ValueError(f"RewardHeadConfig needs hidden, layers, steps and batch_size >= 1 and lr > 0, got {self}")


class RewardHead(nn.Module):
    """MLP: (θ, θ̇) states (..., 2) and actions (..., 1) -> predicted rewards (...)."""

    def __init__(self, config: RewardHeadConfig = RewardHeadConfig()):
        super().__init__()
        self.config = config
        # SB3's MLP builder: Linear and ReLU per hidden layer, then a Linear to the reward
        self.net = nn.Sequential(*create_mlp(4, 1, [config.hidden] * config.layers, nn.ReLU))

    def forward(self, states: Tensor, actions: Tensor) -> Tensor:
        theta, speed = states[..., 0], states[..., 1]  # (...) each
        x = torch.stack([torch.cos(theta), torch.sin(theta), speed, actions[..., 0]], -1).float()  # (..., 4)
        return self.net(x)[..., 0]


class LearnedCost:
    """A :class:`~agents.cost.Cost`: minus a :class:`RewardHead`'s reward of each planned step; no terminal term.

    Like :class:`~agents.cost.PendulumCost` it scores the state each action leads to, with that action."""

    def __init__(self, head: RewardHead):
        self.head = head.eval()

    def stage(self, states: Tensor, actions: Tensor) -> Tensor:
        return self.head(states, actions).neg()  # (B, H)

    def terminal(self, final: Tensor) -> None:
        return None


@torch.inference_mode()
def encoded_transitions(model: PhysicsModel, frames: np.ndarray, actions: np.ndarray) -> tuple[Tensor, Tensor]:
    """piga's own states and the actions after them, from frames alone: what the agent reads at control time.

    Args:
        model: a trained pendulum model.
        frames: uint8 (n, T, H, W) sequences.
        actions: (n, T, A), actions[:, t] after frames[:, t].

    Returns:
        States (n, T - L + 1, 2): (θ + φ, θ̇) of frames L-1..T-1, each from the L frames ending there; and the
        actions (n, T - L + 1, A) after those frames.
    """
    model = model.eval()
    length = model.config.input_frames
    offset = model.physical_parameters().get("offset", 0.0)
    states = []
    for seq, acts in zip(frames, actions):
        x = frames_to_float(torch.from_numpy(np.ascontiguousarray(seq))[None], model.config.channels)  # (1, T, C, H, W)
        coords = model.encode(x)[0]  # (T, N, D)
        windows = coords.unfold(0, length, 1).movedim(-1, 1)  # (T - L + 1, L, N, D)
        last = None
        if model.config.velocity_hold:  # the action over each window's last frame (zeros before the first frame)
            before = np.concatenate([np.zeros_like(acts[:1]), acts[:-1]])  # (T, A)
            last = torch.from_numpy(before[length - 1:]).float()  # (T - L + 1, A)
        p, v = model.initial_state(windows, last)  # (T - L + 1, N, D) each
        states.append(torch.stack([p[:, 0, 0] + offset, v[:, 0, 0]], -1))  # (T - L + 1, 2)
    return torch.stack(states), torch.from_numpy(np.ascontiguousarray(actions[:, length - 1:])).float()


def train_reward_head(model: PhysicsModel, data: str | os.PathLike[str],
                      config: RewardHeadConfig = RewardHeadConfig()) -> tuple[RewardHead, dict[str, Any]]:
    """Trains a :class:`RewardHead` on ``data``'s train split: frames -> ``model``'s states, regressing ``/rewards``.

    Reads the file's frames, actions and rewards only (never ``/states``). Returns the head and its metrics: the
    final train loss, the validation split's mean absolute reward error (None without one), against a constant
    guess of the train split's mean reward, and the training seconds.
    """
    from piga.data.schema import load_rewards, read_sequences, split_indices

    started = time.time()
    length = model.config.input_frames

    def split(name: str) -> tuple[Tensor, Tensor, Tensor]:  # states (M, 2), actions (M, A), rewards (M,)
        frames, actions = read_sequences(data, name)
        rewards = torch.from_numpy(load_rewards(data, name)[:, length - 1:]).float()  # (n, T - L + 1)
        states, acts = encoded_transitions(model, frames, actions)
        return states.flatten(0, 1), acts.flatten(0, 1), rewards.flatten()

    states, actions, rewards = split("train")
    generator = torch.Generator().manual_seed(config.seed)
    with torch.random.fork_rng():  # the head's initialisation from the seed, without touching the global RNG
        torch.manual_seed(config.seed)
        head = RewardHead(config)
    optimizer = torch.optim.Adam(head.parameters(), lr=config.lr)
    loss = torch.tensor(math.nan)
    for _ in range(config.steps):
        rows = torch.randint(len(rewards), (min(config.batch_size, len(rewards)),), generator=generator)
        loss = 0.5 * (head(states[rows], actions[rows]) - rewards[rows]).square().mean()  # PlaNet's reward loss
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    head.eval()
    metrics: dict[str, Any] = {"train_loss": float(loss.detach()), "train_transitions": len(rewards), "valid_abs_error": None,
                               "valid_abs_error_mean_guess": None}
    if len(split_indices(data, "valid")):
        v_states, v_actions, v_rewards = split("valid")
        with torch.no_grad():
            metrics["valid_abs_error"] = float((head(v_states, v_actions) - v_rewards).abs().mean())
        metrics["valid_abs_error_mean_guess"] = float((v_rewards - rewards.mean()).abs().mean())
    metrics["seconds"] = time.time() - started
    return head, metrics


def save_reward_head(path: str | os.PathLike[str], head: RewardHead, metrics: dict[str, Any] | None = None) -> None:
    """Writes the head, its config and ``metrics`` to ``path`` (atomically)."""
    from piga.io.atomic import atomic_output, torch_save

    with atomic_output(Path(path), overwrite=True) as tmp:
        torch_save({"config": asdict(head.config), "state": head.state_dict(), "metrics": metrics or {}}, tmp)


def load_reward_head(path: str | os.PathLike[str]) -> RewardHead:
    """The head :func:`save_reward_head` wrote, in eval mode."""
    saved = torch.load(path, map_location="cpu", weights_only=True)
    head = RewardHead(RewardHeadConfig(**saved["config"]))
    head.load_state_dict(saved["state"])
    return head.eval()
