"""DrQ-v2 (Yarats et al., 2021: "Mastering Visual Continuous Control: Improved Data-Augmented
Reinforcement Learning") as a stable-baselines3 off-policy algorithm.

DrQ-v2 is DDPG from pixels made to work. What it adds, each here:

| part | DrQ-v2 | here |
|---|---|---|
| encoder | 4 convs of 32 channels (3x3, the first of stride 2), trained by the critic's loss only | :class:`Encoder`; the actor reads its output with the gradient stopped |
| augmentation | random shifts of ±4 pixels (replicate padding, bilinear) on every sampled observation | :func:`random_shift` through ``F.affine_grid``/``F.grid_sample`` |
| actor, critic | a trunk each (linear to 50, LayerNorm, tanh), then MLPs of 1024 x 2; two Q heads, clipped double Q | :class:`Actor`, :class:`Critic` |
| exploration | Gaussian noise whose std falls linearly (1.0 to 0.1), clipped to ±0.3 in the updates | ``SB3Config.noise_std`` -> ``noise_final_std`` over ``noise_decay_steps`` |
| returns | 3-step | SB3's ``NStepReplayBuffer`` (``SB3Config.n_step``) |
| updates | every 2 env steps, batch 256, Adam 1e-4, target critic tau 0.01 | ``SB3Config`` drqv2 preset |
| arithmetic | float32 (on its GPUs, torch's default TF32 convolutions) | the encoder's convolutions in bfloat16 on a CPU with bfloat16 hardware (``SB3Config.encoder_precision``), else float32 |

Everything around it is SB3's: the env loop, the warm-up of uniform random actions (``learning_starts``),
the replay buffer, ``predict``, saving and loading, TensorBoard logging. SB3 ships no DrQ-v2 (its DDPG
and SAC train the actor's CNN by the actor's loss, the failure ``results/ddpg_tuning.md`` measures),
and the maintained packages that do (``rllte-core``, pinned to old matplotlib and huggingface-hub
releases) do not install beside piga's dependencies, so the update is written here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.utils import polyak_update
from torch import Tensor, nn

__all__ = ["DrQV2", "DrQV2Policy", "ScheduledNoise", "random_shift"]

#: The std of the target and actor-update action noise is clipped to this (DrQ-v2's stddev_clip).
NOISE_CLIP = 0.3
#: Pixels of replicate padding before a random shift (DrQ-v2's 4, for 84x84 frames).
SHIFT_PAD = 4


def _orthogonal(module: nn.Module) -> None:
    """DrQ-v2's initialisation: orthogonal weights (with ReLU's gain for convs), zero biases."""
    if isinstance(module, nn.Linear):
        nn.init.orthogonal_(module.weight.data)
        module.bias.data.fill_(0.0)
    elif isinstance(module, nn.Conv2d):
        nn.init.orthogonal_(module.weight.data, nn.init.calculate_gain("relu"))
        module.bias.data.fill_(0.0)


def random_shift(x: Tensor, pad: int = SHIFT_PAD, generator: torch.Generator | None = None) -> Tensor:
    """Each image of ``x`` (B, C, H, W), H = W, shifted by a random whole number of pixels in [-pad, pad]
    along each axis, the border replicated: DrQ's augmentation."""
    b, _, h, w = x.shape
    padded = F.pad(x, (pad, pad, pad, pad), mode="replicate")  # (B, C, H + 2p, W + 2p)
    shift = torch.randint(0, 2 * pad + 1, (b, 2), generator=generator).to(x.device, x.dtype)  # (B, 2) pixels, x then y
    theta = torch.zeros(b, 2, 3, device=x.device, dtype=x.dtype)  # crop H x W of the padded image at the shift
    theta[:, 0, 0] = w / (w + 2 * pad)
    theta[:, 1, 1] = h / (h + 2 * pad)
    theta[:, :, 2] = (2 * shift - 2 * pad) / (torch.tensor([w, h], device=x.device, dtype=x.dtype) + 2 * pad)
    grid = F.affine_grid(theta, [b, x.shape[1], h, w], align_corners=False)
    return F.grid_sample(padded, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


class Encoder(nn.Module):
    """uint8-valued stacks (B, K, H, W) as floats -> float32 features (B, 32·(H/2 - 7)²); DrQ-v2's convs, computed
    in bfloat16 (torch's autocast; the weights stay float32) when ``bfloat16``.

    In bfloat16 the images and weights are kept channels-last in memory (the same tensors, another layout): oneDNN's
    bfloat16 convolutions take that layout natively, and the update ran about 1.4x faster than with them reordered
    from channels-first at each call (results/drqv2_precision.md)."""

    def __init__(self, channels: int, size: int, bfloat16: bool = False):
        super().__init__()
        self.bfloat16 = bfloat16
        self.convnet = nn.Sequential(nn.Conv2d(channels, 32, 3, stride=2), nn.ReLU(),
                                     nn.Conv2d(32, 32, 3, stride=1), nn.ReLU(),
                                     nn.Conv2d(32, 32, 3, stride=1), nn.ReLU(),
                                     nn.Conv2d(32, 32, 3, stride=1), nn.ReLU())
        side = (size - 3) // 2 + 1 - 6
        self.repr_dim = 32 * side * side
        self.apply(_orthogonal)
        if bfloat16:
            self.convnet.to(memory_format=torch.channels_last)

    def forward(self, obs: Tensor) -> Tensor:
        x = obs / 255.0 - 0.5
        if self.bfloat16:
            x = x.contiguous(memory_format=torch.channels_last)
        with torch.autocast(obs.device.type, dtype=torch.bfloat16, enabled=self.bfloat16):
            features = self.convnet(x).flatten(1)  # (B, 32, S, S) -> (B, 32·S²) in that order, whatever the layout
        return features.float()


def _trunk(repr_dim: int, feature_dim: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(repr_dim, feature_dim), nn.LayerNorm(feature_dim), nn.Tanh())


class Actor(nn.Module):
    """Encoder features (B, R) -> the mean action (B, A) in [-1, 1]."""

    def __init__(self, repr_dim: int, action_dim: int, feature_dim: int, hidden: tuple[int, ...]):
        super().__init__()
        self.trunk = _trunk(repr_dim, feature_dim)
        layers: list[nn.Module] = []
        width = feature_dim
        for size in hidden:
            layers += [nn.Linear(width, size), nn.ReLU()]
            width = size
        self.policy = nn.Sequential(*layers, nn.Linear(width, action_dim))
        self.apply(_orthogonal)

    def forward(self, features: Tensor) -> Tensor:
        return torch.tanh(self.policy(self.trunk(features)))


class Critic(nn.Module):
    """Encoder features (B, R) and actions (B, A) -> two Q-values (B, 1) each."""

    def __init__(self, repr_dim: int, action_dim: int, feature_dim: int, hidden: tuple[int, ...]):
        super().__init__()
        self.trunk = _trunk(repr_dim, feature_dim)

        def head() -> nn.Sequential:
            layers: list[nn.Module] = []
            width = feature_dim + action_dim
            for size in hidden:
                layers += [nn.Linear(width, size), nn.ReLU()]
                width = size
            return nn.Sequential(*layers, nn.Linear(width, 1))

        self.q1, self.q2 = head(), head()
        self.apply(_orthogonal)

    def forward(self, features: Tensor, action: Tensor) -> tuple[Tensor, Tensor]:
        x = torch.cat([self.trunk(features), action], dim=-1)
        return self.q1(x), self.q2(x)


class DrQV2Policy(BasePolicy):
    """The encoder, actor, critic and target critic, and their Adam optimisers. ``predict`` acts with the
    mean action (SB3 adds the exploration noise in the env loop).

    Args:
        observation_space: channel-first uint8 stacks (K, H, W), H = W.
        action_space: a Box.
        lr_schedule: SB3's learning-rate schedule (constant here).
        net_arch: the hidden widths of the actor's and each Q head's MLP.
        feature_dim: the trunks' width.
        encoder_precision: "float32" or "bfloat16", the encoder's arithmetic (a model saved before the option
            has none: float32).
    """

    def __init__(self, observation_space: spaces.Box, action_space: spaces.Box, lr_schedule: Callable[[float], float],
                 net_arch: list[int] | tuple[int, ...] = (1024, 1024), feature_dim: int = 50,
                 encoder_precision: str = "float32", **kwargs: Any):
        super().__init__(observation_space, action_space, squash_output=True, normalize_images=False, **kwargs)
        channels, size = observation_space.shape[0], observation_space.shape[-1]
        action_dim = int(np.prod(action_space.shape))
        hidden = tuple(net_arch)
        if encoder_precision not in ("float32", "bfloat16"):
            raise ValueError(f"encoder_precision must be float32 or bfloat16, got {encoder_precision!r}")
        self.net_arch, self.feature_dim, self.encoder_precision = hidden, feature_dim, encoder_precision
        self.encoder = Encoder(channels, size, bfloat16=encoder_precision == "bfloat16")
        self.actor = Actor(self.encoder.repr_dim, action_dim, feature_dim, hidden)
        self.critic = Critic(self.encoder.repr_dim, action_dim, feature_dim, hidden)
        self.critic_target = Critic(self.encoder.repr_dim, action_dim, feature_dim, hidden)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.requires_grad_(False)
        lr = lr_schedule(1)
        self.encoder_optimizer = torch.optim.Adam(self.encoder.parameters(), lr=lr)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=lr)
        self.critic_optimizer = torch.optim.Adam(self.critic.parameters(), lr=lr)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(net_arch=self.net_arch, feature_dim=self.feature_dim, encoder_precision=self.encoder_precision)
        return data

    def _predict(self, observation: Tensor, deterministic: bool = True) -> Tensor:
        return self.actor(self.encoder(observation.float()))

    def forward(self, observation: Tensor, deterministic: bool = True) -> Tensor:
        return self._predict(observation, deterministic)


class ScheduledNoise(ActionNoise):
    """Gaussian action noise whose std falls linearly from ``start`` to ``end`` over ``steps`` env steps
    (DrQ-v2's ``linear(1.0, 0.1, N)``), drawn from numpy's global RNG (as SB3's own noises are, so that a
    checkpoint's RNG state continues it). ``step`` is set by :class:`DrQV2` before each action."""

    def __init__(self, action_dim: int, start: float, end: float, steps: int):
        super().__init__()
        self.action_dim, self.start, self.end, self.steps = action_dim, start, end, steps
        self.step = 0

    def std(self, step: int | None = None) -> float:
        """The std at ``step`` (default: the current one)."""
        fraction = min(1.0, (self.step if step is None else step) / self.steps) if self.steps > 0 else 1.0
        return self.start + fraction * (self.end - self.start)

    def __call__(self) -> np.ndarray:
        return np.random.normal(0.0, self.std(), size=self.action_dim).astype(np.float32)

    def __repr__(self) -> str:
        return f"ScheduledNoise(start={self.start}, end={self.end}, steps={self.steps})"


def _clipped_sample(mean: Tensor, std: float) -> Tensor:
    """``mean`` plus N(0, std) noise clipped to ±:data:`NOISE_CLIP`, then clamped to [-1, 1] with the
    gradient passed straight through the clamp (DrQ-v2's TruncatedNormal.sample)."""
    noise = (torch.randn_like(mean) * std).clamp(-NOISE_CLIP, NOISE_CLIP)
    x = mean + noise
    return x - x.detach() + x.detach().clamp(-1.0, 1.0)


class DrQV2(OffPolicyAlgorithm):
    """DrQ-v2's update (module docstring) in SB3's off-policy loop. ``action_noise`` must be a
    :class:`ScheduledNoise`: its std also sets the updates' target and actor noise."""

    policy_aliases = {"CnnPolicy": DrQV2Policy}  # noqa: RUF012  (SB3's class attribute)
    policy: DrQV2Policy

    def __init__(self, policy: Any, env: Any, learning_rate: float = 1e-4, action_noise: ScheduledNoise | None = None,
                 _init_setup_model: bool = True, **kwargs: Any):
        super().__init__(policy, env, learning_rate, action_noise=action_noise, supported_action_spaces=(spaces.Box,),
                         support_multi_env=True, sde_support=False, **kwargs)
        if _init_setup_model:  # SB3's load() sets up the model itself
            self._setup_model()

    def _sample_action(self, learning_starts: int, action_noise: ActionNoise | None = None,
                       n_envs: int = 1) -> tuple[np.ndarray, np.ndarray]:
        if isinstance(action_noise, ScheduledNoise):
            action_noise.step = self.num_timesteps
        return super()._sample_action(learning_starts, action_noise, n_envs)

    def _update_std(self) -> float:
        noise = self.action_noise
        return noise.std(self.num_timesteps) if isinstance(noise, ScheduledNoise) else 0.1

    def train(self, gradient_steps: int, batch_size: int = 256) -> None:
        policy = self.policy
        policy.set_training_mode(True)
        std = self._update_std()
        critic_losses, actor_losses = [], []
        for _ in range(gradient_steps):
            self._n_updates += 1
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = data.discounts if data.discounts is not None else self.gamma  # (B, 1): gamma^n, or less at an end
            obs = policy.encoder(random_shift(data.observations.float()))  # (B, R)
            with torch.no_grad():
                next_obs = policy.encoder(random_shift(data.next_observations.float()))  # (B, R)
                next_action = _clipped_sample(policy.actor(next_obs), std)  # (B, A)
                target_q = torch.min(*policy.critic_target(next_obs, next_action))  # (B, 1)
                target = data.rewards + (1 - data.dones) * discounts * target_q  # (B, 1)
            q1, q2 = policy.critic(obs, data.actions)
            critic_loss = F.mse_loss(q1, target) + F.mse_loss(q2, target)
            policy.encoder_optimizer.zero_grad(set_to_none=True)
            policy.critic_optimizer.zero_grad(set_to_none=True)
            critic_loss.backward()
            policy.critic_optimizer.step()
            policy.encoder_optimizer.step()

            features = obs.detach()  # the actor does not train the encoder
            action = _clipped_sample(policy.actor(features), std)
            actor_loss = -torch.min(*policy.critic(features, action)).mean()
            policy.actor_optimizer.zero_grad(set_to_none=True)
            actor_loss.backward()
            policy.actor_optimizer.step()
            polyak_update(policy.critic.parameters(), policy.critic_target.parameters(), self.tau)
            critic_losses.append(critic_loss.item())
            actor_losses.append(actor_loss.item())
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/critic_loss", float(np.mean(critic_losses)))
        self.logger.record("train/actor_loss", float(np.mean(actor_losses)))
        self.logger.record("train/noise_std", std)

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "policy.encoder_optimizer", "policy.actor_optimizer", "policy.critic_optimizer"], []
