"""A PlaNet-style recurrent state-space model (RSSM; Hafner et al., 2019) for 64x64 frames.

The latent state at frame t is (h_t, s_t): a deterministic GRU state h and a stochastic Gaussian
state s. With a_t the action applied after frame t (piga's schema) and a_{-1} = 0, s_{-1} = 0, h_{-1} = 0:

| part | map |
|---|---|
| encoder | frame x_t (C, 64, 64) -> embedding e_t (E,): four stride-2 convs, PlaNet's |
| transition | h_t = GRU(h_{t-1}, MLP(s_{t-1}, a_{t-1})) |
| prior | p(s_t | h_t) = N(μ, σ), σ = softplus(·) + min_std |
| posterior | q(s_t | h_t, e_t) = N(μ, σ) |
| decoder | (h_t, s_t) -> mean of x_t: four stride-2 transposed convs, PlaNet's |
| reward head | (h_t, s_t) -> r_t, the env's reward for a_t; with ``reward_alignment="transition"``, (h_{t+1}, s_{t+1}) -> r_t |

The loss per frame is PlaNet's: the negative log-likelihood of x_t under N(decoder, 1) (summed over
pixels), of r_t under N(head, 1), and max(KL(q || p), free_nats), averaged over the batch and time.

Pendulum's reward for a_t is -(θ_t² + 0.1·θ̇_t² + 0.001·a_t²): a function of the state of frame t
plus an action cost of at most 0.004, which the head cannot see when it reads frame t's state
(``RSSMConfig.reward_alignment="frame"``). PlaNet's alignment (``"transition"``) reads the state that
a_t leads to, whose GRU input holds a_t: the reward is then a function of what the head sees.

With an action repeat R (``RSSMConfig.action_repeat``), one model step is R env steps:
:func:`model_steps` turns env-step sequences into model steps (every R-th frame, the R actions in
between as one input of R·A numbers, their rewards summed), and the methods below take model steps.
An imagined action is held for R env steps, its R copies side by side.

Frames enter as uint8 and are scaled to [-0.5, 0.5]. Randomness (the reparameterised samples) comes
from an explicit ``torch.Generator``, drawn on the generator's device (the CPU's for a plain
``torch.Generator()``) and moved to the model's, so that a model on a GPU draws the CPU's numbers.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from agents.planet.config import PlanetTrainConfig, RSSMConfig
from piga.io.resources import meta_parameter_count

__all__ = ["RSSM", "Belief", "LossParts", "WorldModel", "frames_to_input", "held", "model_steps"]


def frames_to_input(frames: Tensor, channels: int) -> Tensor:
    """uint8 frames (..., H, W) for gray or (..., H, W, C) -> float (..., C, H, W) in [-0.5, 0.5]."""
    x = frames.float() / 255.0 - 0.5
    if channels == 1 and (x.dim() < 3 or x.shape[-1] != 1):
        return x.unsqueeze(-3)
    return x.movedim(-1, -3)


def model_steps(frames: Tensor, actions: Tensor, rewards: Tensor, repeat: int) -> tuple[Tensor, Tensor, Tensor]:
    """Env-step sequences as model steps of ``repeat`` env steps each (trailing steps dropped).

    Args:
        frames: (B, T, ...) frames; actions (B, T, A), actions[:, t] after frames[:, t]; rewards (B, T).

    Returns:
        frames (B, L, ...) = frames[:, ::R], actions (B, L, R·A) (the R actions after each kept frame,
        side by side), rewards (B, L) (their summed rewards), with L = T // R.
    """
    if repeat == 1:
        return frames, actions, rewards
    b, t = actions.shape[:2]
    steps = t // repeat
    return (frames[:, :steps * repeat:repeat], actions[:, :steps * repeat].reshape(b, steps, -1),
            rewards[:, :steps * repeat].reshape(b, steps, repeat).sum(-1))


def held(actions: Tensor, repeat: int) -> Tensor:
    """Actions (..., A) held for ``repeat`` env steps: the model's inputs (..., R·A)."""
    return actions if repeat == 1 else actions.repeat(*([1] * (actions.dim() - 1)), repeat)


class Belief(NamedTuple):
    """A batch of latent states."""

    h: Tensor
    """(B, D) deterministic GRU state."""
    s: Tensor
    """(B, S) stochastic state."""


class Gaussian(NamedTuple):
    """A diagonal Gaussian over the stochastic state."""

    mean: Tensor
    """(..., S)."""
    std: Tensor
    """(..., S)."""


class LossParts(NamedTuple):
    """The training loss and its terms (each a scalar tensor, per frame)."""

    loss: Tensor
    """reconstruction + reward_scale·reward + kl_scale·max(KL, free nats)."""
    reconstruction: Tensor
    """0.5·Σ_pixels (x - x̂)²: the image NLL without its constant."""
    reward: Tensor
    """0.5·(r - r̂)²."""
    kl: Tensor
    """KL(q || p), summed over the stochastic state (before the free nats)."""


class Encoder(nn.Module):
    """PlaNet's conv encoder: (B, C, 64, 64) -> (B, 32·depth)."""

    def __init__(self, config: RSSMConfig):
        super().__init__()
        d = config.depth
        self.net = nn.Sequential(
            nn.Conv2d(config.channels, d, 4, 2), nn.ReLU(),  # (B, d, 31, 31)
            nn.Conv2d(d, 2 * d, 4, 2), nn.ReLU(),  # (B, 2d, 14, 14)
            nn.Conv2d(2 * d, 4 * d, 4, 2), nn.ReLU(),  # (B, 4d, 6, 6)
            nn.Conv2d(4 * d, 8 * d, 4, 2), nn.ReLU(),  # (B, 8d, 2, 2)
            nn.Flatten(),
        )

    def forward(self, x: Tensor) -> Tensor:
        return self.net(x)


class Decoder(nn.Module):
    """PlaNet's transposed-conv decoder: (B, D + S) -> mean frame (B, C, 64, 64)."""

    def __init__(self, config: RSSMConfig):
        super().__init__()
        d = config.depth
        self.fc = nn.Linear(config.deter_size + config.stoch_size, 32 * d)
        self.net = nn.Sequential(
            nn.ConvTranspose2d(32 * d, 4 * d, 5, 2), nn.ReLU(),  # (B, 4d, 5, 5)
            nn.ConvTranspose2d(4 * d, 2 * d, 5, 2), nn.ReLU(),  # (B, 2d, 13, 13)
            nn.ConvTranspose2d(2 * d, d, 6, 2), nn.ReLU(),  # (B, d, 30, 30)
            nn.ConvTranspose2d(d, config.channels, 6, 2),  # (B, C, 64, 64)
        )

    def forward(self, features: Tensor) -> Tensor:
        return self.net(self.fc(features)[..., None, None])


class RSSM(nn.Module):
    """The transition, prior and posterior of the latent state."""

    def __init__(self, config: RSSMConfig):
        super().__init__()
        self.config = config
        d, s, k = config.deter_size, config.stoch_size, config.hidden_size
        self.pre_gru = nn.Linear(s + config.input_action_size, k)
        self.gru = nn.GRUCell(k, d)
        self.prior_net = nn.Sequential(nn.Linear(d, k), nn.ReLU(), nn.Linear(k, 2 * s))
        self.posterior_net = nn.Sequential(nn.Linear(d + config.embed_size, k), nn.ReLU(), nn.Linear(k, 2 * s))

    def initial(self, batch: int) -> Belief:
        """The zero state before the first frame, on the model's device: h (B, D), s (B, S)."""
        weight = self.pre_gru.weight
        return Belief(weight.new_zeros(batch, self.config.deter_size), weight.new_zeros(batch, self.config.stoch_size))

    def _gaussian(self, raw: Tensor) -> Gaussian:
        mean, std = raw.chunk(2, dim=-1)
        return Gaussian(mean, F.softplus(std) + self.config.min_std)

    def transition(self, belief: Belief, action: Tensor) -> tuple[Tensor, Gaussian]:
        """h_t (B, D) and the prior of s_t from the previous state (B, ·) and action a_{t-1} (B, R·A)."""
        x = F.relu(self.pre_gru(torch.cat([belief.s, action], -1)))
        h = self.gru(x, belief.h)
        return h, self._gaussian(self.prior_net(h))

    def posterior(self, h: Tensor, embed: Tensor) -> Gaussian:
        """q(s_t | h_t, e_t) from h (B, D) and the frame's embedding (B, E)."""
        return self._gaussian(self.posterior_net(torch.cat([h, embed], -1)))


def draw_noise(shape: tuple[int, ...], like: Tensor, generator: torch.Generator | None) -> Tensor:
    """Standard normal noise of ``shape`` in ``like``'s dtype, from ``generator`` on its device (None: torch's global
    generator of ``like``'s device), not yet moved to ``like``'s device."""
    device = like.device if generator is None else generator.device
    return torch.randn(shape, generator=generator, dtype=like.dtype, device=device)


def sample(dist: Gaussian, generator: torch.Generator | None) -> Tensor:
    """A reparameterised sample mean + std·ε, ε from ``generator`` on its device (None: torch's global
    generator of the state's device), then moved to the state's device."""
    return dist.mean + dist.std * draw_noise(tuple(dist.mean.shape), dist.mean, generator).to(dist.mean.device)


def _kl(q: Gaussian, p: Gaussian) -> Tensor:
    """KL(q || p) of diagonal Gaussians, summed over the last axis."""
    ratio = (q.std / p.std) ** 2
    return 0.5 * (ratio + ((q.mean - p.mean) / p.std) ** 2 - 1 - ratio.log()).sum(-1)


class WorldModel(nn.Module):
    """Encoder, RSSM, decoder and reward head, with PlaNet's loss.

    Args:
        config: sizes.
    """

    def __init__(self, config: RSSMConfig = RSSMConfig()):
        super().__init__()
        self.config = config
        self.encoder = Encoder(config)
        self.rssm = RSSM(config)
        self.decoder = Decoder(config)
        k = config.reward_units or config.hidden_size
        layers: list[nn.Module] = []
        for width in (config.deter_size + config.stoch_size, *[k] * (config.reward_layers - 1)):
            layers += [nn.Linear(width, k), nn.ReLU()]
        self.reward_head = nn.Sequential(*layers, nn.Linear(k, 1))  # (..., D + S) -> (..., 1)

    def embed(self, frames: Tensor) -> Tensor:
        """uint8 frames (B, T, H, W[, C]) -> embeddings (B, T, E)."""
        b, t = frames.shape[:2]
        x = frames_to_input(frames.reshape(b * t, *frames.shape[2:]), self.config.channels)  # (B·T, C, H, W)
        return self.encoder(x).reshape(b, t, -1)

    def observe(self, frames: Tensor, actions: Tensor, generator: torch.Generator | None = None
                ) -> tuple[Tensor, Tensor, Gaussian, Gaussian]:
        """Filters a batch of sequences of model steps: frames uint8 (B, T, H, W), actions (B, T, R·A),
        actions[:, t] after frames[:, t].

        Returns:
            h (B, T, D), s (B, T, S) sampled from the posteriors, the priors and the posteriors ((B, T, S) each).
        """
        b, t = frames.shape[:2]
        embeds = self.embed(frames)  # (B, T, E)
        belief = self.rssm.initial(b)
        previous = embeds.new_zeros(b, self.config.input_action_size)  # (B, R·A)
        # the T draws that sample() would make, in its order, moved in one copy: a CPU generator then costs a
        # model on a GPU one wait for the GPU per batch rather than one per step
        noise = torch.stack([draw_noise((b, self.config.stoch_size), embeds, generator) for _ in range(t)])
        noise = noise.to(embeds.device)  # (T, B, S)
        hs, ss, priors, posts = [], [], [], []
        for step in range(t):
            h, prior = self.rssm.transition(belief, previous)
            post = self.rssm.posterior(h, embeds[:, step])
            belief = Belief(h, post.mean + post.std * noise[step])
            previous = actions[:, step]
            hs.append(h)
            ss.append(belief.s)
            priors.append(prior)
            posts.append(post)
        stack = lambda xs: torch.stack(xs, 1)  # noqa: E731
        return (stack(hs), stack(ss), Gaussian(stack([p.mean for p in priors]), stack([p.std for p in priors])),
                Gaussian(stack([q.mean for q in posts]), stack([q.std for q in posts])))

    def reward(self, h: Tensor, s: Tensor) -> Tensor:
        """Predicted rewards (...,) from states (..., D) and (..., S)."""
        return self.reward_head(torch.cat([h, s], -1))[..., 0]

    def decode(self, h: Tensor, s: Tensor) -> Tensor:
        """Mean frames (..., C, H, W) in [-0.5, 0.5] units from states (..., D), (..., S)."""
        lead = h.shape[:-1]
        out = self.decoder(torch.cat([h, s], -1).reshape(-1, h.shape[-1] + s.shape[-1]))
        return out.reshape(*lead, *out.shape[1:])

    def loss(self, frames: Tensor, actions: Tensor, rewards: Tensor, config: PlanetTrainConfig,
             generator: torch.Generator | None = None) -> LossParts:
        """PlaNet's loss on a batch of model steps: frames uint8 (B, T, H, W), actions (B, T, R·A), rewards (B, T)."""
        h, s, prior, post = self.observe(frames, actions, generator)
        target = frames_to_input(frames, self.config.channels)  # (B, T, C, H, W)
        reconstruction = 0.5 * (self.decode(h, s) - target).square().sum((-3, -2, -1)).mean()
        predicted, target = self.aligned_rewards(self.reward(h, s), rewards)
        reward = 0.5 * (predicted - target).square().mean()
        kl = _kl(post, prior)  # (B, T)
        kl_term = kl.clamp_min(config.free_nats).mean()
        loss = reconstruction + config.reward_scale * reward + config.kl_scale * kl_term
        return LossParts(loss, reconstruction, reward, kl.mean())

    def aligned_rewards(self, predicted: Tensor, rewards: Tensor) -> tuple[Tensor, Tensor]:
        """The head's outputs at states (B, T) and the rewards (B, T) of the actions after each frame, paired
        as the head is trained (``RSSMConfig.reward_alignment``): with ``"transition"``, the output at
        frame t+1 against the reward of the actions after frame t, (B, T - 1) each."""
        if self.config.reward_alignment == "transition":
            return predicted[:, 1:], rewards[:, :-1]
        return predicted, rewards

    @torch.no_grad()
    def open_loop(self, frames: Tensor, actions: Tensor, context: int, generator: torch.Generator | None = None
                  ) -> tuple[Tensor, Tensor]:
        """PlaNet's open-loop prediction: filter the first ``context`` frames, then imagine the rest
        from the prior (sampled) under the sequence's own actions.

        Args:
            frames: uint8 (B, T, H, W[, C]) of model steps; only the first ``context`` are read.
            actions: (B, T, R·A), actions[:, t] after frames[:, t].

        Returns:
            Decoded frames (B, T, C, H, W) in [-0.5, 0.5] units (the first ``context`` are
            reconstructions, the rest predictions) and predicted rewards (B, T).
        """
        b, t = frames.shape[:2]
        embeds = self.embed(frames[:, :context])  # (B, context, E)
        belief = self.rssm.initial(b)
        previous = embeds.new_zeros(b, self.config.input_action_size)  # (B, R·A)
        hs, ss = [], []
        for step in range(t):
            h, prior = self.rssm.transition(belief, previous)
            belief = Belief(h, sample(self.rssm.posterior(h, embeds[:, step]) if step < context else prior, generator))
            previous = actions[:, step]
            hs.append(h)
            ss.append(belief.s)
        h, s = torch.stack(hs, 1), torch.stack(ss, 1)
        return self.decode(h, s), self.reward(h, s)

    def imagine_return(self, belief: Belief, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """Sum of predicted rewards over the H imagined model steps after ``belief`` ((1, ·) or (B, ·))
        under actions (B, H, A), each held for R env steps, with states sampled from the prior: (B,)."""
        b, horizon = actions.shape[:2]
        actions = held(actions, self.config.action_repeat)  # (B, H, R·A)
        state = Belief(belief.h.expand(b, -1), belief.s.expand(b, -1))
        total = belief.h.new_zeros(b)  # (B,)
        for step in range(horizon):
            h, prior = self.rssm.transition(state, actions[:, step])
            state = Belief(h, sample(prior, generator))
            total = total + self.reward(state.h, state.s)
        return total


def parameter_count(config: RSSMConfig) -> int:
    """The number of parameters of ``WorldModel(config)``, counted on torch's meta device (no memory)."""
    return meta_parameter_count(lambda: WorldModel(config))
