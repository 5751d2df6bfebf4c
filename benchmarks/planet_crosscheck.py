"""Benchmark: does piga's PlaNet-style RSSM learn a pendulum file about as well as an independent PlaNet,
mbrl-lib's ``mbrl.models.planet.PlaNetModel``, at the same budget?

Both models train in this process, one step each in turn, on the same batches (the train split's chunks
drawn once per step by :class:`agents.planet.train._Sequences`, piga's own sampler, and handed to both),
from the same seed, with the settings matched wherever both models expose them: the sizes (read from
:class:`~agents.planet.config.RSSMConfig`; mbrl's convolutions are those of piga's encoder and decoder,
read from the built model), the action repeat (both take the R actions of a model step as one input and
predict their summed reward), free nats, the KL weight, the learning rate, Adam's epsilon, the gradient
clip, the batch size, the chunk length and the steps (:class:`~agents.planet.config.PlanetTrainConfig`).
mbrl's PlaNet is configured for one channel (its encoder and decoder take the channel counts as settings):
piga's frames are 64x64 gray uint8 and enter it as (1, 64, 64).

mbrl's loss is Σ(x̂ - x)² + (r̂ - r)² + kl_scale·max(KL, free nats); piga's halves the first two terms (the
Gaussian log-likelihoods without their constant). With ``--mbrl-objective matched`` (the default) mbrl's
KL weight, gradient clip and Adam epsilon are doubled, which makes its loss exactly twice piga's and its
Adam steps those of piga's objective; ``native`` keeps piga's numbers, so that mbrl weighs the KL half as
much. The page lists what could not be matched (initialisation, the first frame of a chunk, the width of
the layer before the GRU, pixel scaling).

Every ``--log-every`` steps, each model's training terms since the last record, in the same units: the
pixel MSE of its posterior reconstructions (pixels in [0, 1]), the reward MSE, and the KL term after the
free nats. After training, on the validation split (the first chunk of up to ``--valid-sequences``
sequences, a fixed seed): the reconstruction MSE per pixel, the reward MSE and KL(q || p) over the
chunk's frames 1 to L-1 (mbrl's loss does not cover frame 0), and the open-loop errors: filter the first
``OPEN_LOOP_CONTEXT`` model steps of each sequence into a posterior, then imagine PlaNet's planning
horizon of model steps from the prior under the sequence's own actions (piga: ``WorldModel.open_loop``;
mbrl: ``update_posterior``, then ``sample``), and compare the predicted rewards and frames with the real
ones. Also each model's parameter count and its seconds per training step (median).

    piga-collect --out runs/pend200.h5 --sequences 200 --seed 100
    python benchmarks/planet_crosscheck.py --data runs/pend200.h5 --steps 1500 --out results/planet_crosscheck

Writes ``OUT.json`` and ``OUT.md``. mbrl pins old releases of gymnasium and hydra, so it is not one of
piga's dependencies; install it beside piga with::

    pip install --no-deps mbrl==0.2.0 hydra-core==1.3.8 omegaconf==2.3.0 antlr4-python3-runtime==4.9.3 termcolor

(its ``mbrl.models`` imports hydra, omegaconf and termcolor, and nothing else that piga lacks). Without
it the script stops with one line that says so.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import shlex
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, get_args

import numpy as np
import torch
from torch import nn

from common import machine, machine_words, out_prefix, write_page
from agents.planet.config import LatentPlannerConfig, PlanetTrainConfig, RewardAlignment, RSSMConfig
from agents.planet.rssm import WorldModel, model_steps
from agents.planet.train import OPEN_LOOP_CONTEXT, _Sequences, check_planet_data, optimizer_step, rssm_config_for
from piga.cli.common import ArgumentParser, nonnegative_float, positive_int, seed_int
from piga.data.schema import inspect_dataset

#: How to make ``mbrl.models.planet`` importable beside piga (its wheel's own pins conflict with piga's).
MBRL_INSTALL = ("pip install --no-deps mbrl==0.2.0 hydra-core==1.3.8 omegaconf==2.3.0 "
                "antlr4-python3-runtime==4.9.3 termcolor")
#: The models compared, in the page's order.
MODELS = ("piga", "mbrl")
#: Names of the models on the page.
NAMES = {"piga": "piga (agents.planet.rssm.WorldModel)", "mbrl": "mbrl {version} (mbrl.models.planet.PlaNetModel)"}


class MbrlMissing(Exception):
    """``mbrl.models.planet`` cannot be imported."""


def import_mbrl() -> tuple[Any, Any]:
    """mbrl's ``PlaNetModel`` and ``TransitionBatch``.

    Raises:
        MbrlMissing: mbrl, or a package its import chain needs, is missing or broken (its message says why).
    """
    try:
        from mbrl.models.planet import PlaNetModel
        from mbrl.types import TransitionBatch
    except Exception as exc:  # ImportError, or a broken hydra (old releases fail on new Pythons with ValueError)
        raise MbrlMissing(" ".join(f"{type(exc).__name__}: {exc}".split())) from None
    return PlaNetModel, TransitionBatch


# ----------------------------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class Settings:
    """What both trainings share, and what mbrl is built with."""

    rssm: RSSMConfig
    train: PlanetTrainConfig
    objective: str
    """``matched`` or ``native`` (``--mbrl-objective``)."""
    log_every: int
    valid_sequences: int

    @property
    def mbrl_scale(self) -> float:
        """Factor of mbrl's loss over piga's (matched), by which its KL weight, clip and Adam epsilon grow."""
        return 2.0 if self.objective == "matched" else 1.0


def conv_layers(module: nn.Module, kind: type) -> tuple[tuple[int, int, int, int], ...]:
    """(in channels, out channels, kernel, stride) of each ``kind`` layer of ``module``, in order: mbrl's layer configs."""
    layers = [m for m in module.modules() if type(m) is kind]
    for m in layers:
        if len(set(m.kernel_size)) != 1 or len(set(m.stride)) != 1 or any(m.padding) or m.dilation != (1, 1):
            raise ValueError(f"mbrl's convolutions are square, unpadded and undilated; piga's {m} is not")
    return tuple((m.in_channels, m.out_channels, m.kernel_size[0], m.stride[0]) for m in layers)


def build_piga(settings: Settings) -> WorldModel:
    """piga's world model, initialised from ``torch.manual_seed(seed)`` as ``train_planet`` does."""
    torch.manual_seed(settings.train.seed)
    return WorldModel(settings.rssm)


def build_mbrl(planet_model: Any, settings: Settings, piga: WorldModel) -> Any:
    """mbrl's PlaNet with ``piga``'s sizes and layers, initialised from ``torch.manual_seed(seed)``; its
    samples drawn from a CPU generator of the same seed."""
    rssm, train = settings.rssm, settings.train
    encoder = conv_layers(piga.encoder, nn.Conv2d)
    decoder = conv_layers(piga.decoder, nn.ConvTranspose2d)
    torch.manual_seed(train.seed)
    return planet_model(
        obs_shape=(rssm.channels, rssm.image_size, rssm.image_size),
        obs_encoding_size=rssm.embed_size,  # the flattened convs' size: mbrl then adds no linear layer, as piga
        encoder_config=encoder,
        decoder_config=((piga.decoder.fc.out_features, 1, 1), decoder),
        latent_state_size=rssm.stoch_size,
        action_size=rssm.input_action_size,
        belief_size=rssm.deter_size,
        hidden_size_fcs=rssm.hidden_size,
        device="cpu",
        min_std=rssm.min_std,
        free_nats=train.free_nats,
        kl_scale=settings.mbrl_scale * train.kl_scale,
        grad_clip_norm=settings.mbrl_scale * train.grad_clip,
        rng=torch.Generator().manual_seed(train.seed),
    )


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


# ----------------------------------------------------------------------------------------------- training


def digest(*tensors: torch.Tensor) -> bytes:
    """A fingerprint of a batch as a model receives it."""
    h = hashlib.sha256()
    for t in tensors:
        h.update(t.contiguous().numpy().tobytes())
    return h.digest()


@dataclass
class Trainer:
    """One model's training: its step, the running sums of its terms, and what it has recorded."""

    name: str
    pixels: int
    """Pixels of a frame (C·H·W), to turn summed squared errors into per-pixel ones."""
    seconds: list[float] = field(default_factory=list)
    sums: dict[str, float] = field(default_factory=dict)
    count: int = 0
    curve: list[dict[str, float]] = field(default_factory=list)
    batches: Any = field(default_factory=hashlib.sha256)
    """The running fingerprint of every batch the model was trained on."""

    def add(self, terms: dict[str, float]) -> None:
        bad = [k for k, v in terms.items() if not math.isfinite(v)]
        if bad:
            raise FloatingPointError(f"{self.name}'s {bad[0]} became {terms[bad[0]]} at step {len(self.seconds)}")
        for k, v in terms.items():
            self.sums[k] = self.sums.get(k, 0.0) + v
        self.count += 1

    def record(self, step: int) -> None:
        self.curve.append({"step": step, **{k: v / self.count for k, v in self.sums.items()},
                           "seconds": float(sum(self.seconds))})
        self.sums, self.count = {}, 0


class PigaTrainer(Trainer):
    def __init__(self, model: WorldModel, settings: Settings):
        super().__init__("piga", settings.rssm.channels * settings.rssm.image_size ** 2)
        self.model, self.config = model.train(), settings.train
        self.optimizer = torch.optim.Adam(model.parameters(), lr=self.config.lr, eps=self.config.adam_eps)
        self.generator = torch.Generator().manual_seed(self.config.seed)

    def step(self, frames: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor) -> None:
        """One step of ``train_planet``'s loop on a batch of model steps."""
        started = time.perf_counter()
        parts = self.model.loss(frames, actions, rewards, self.config, self.generator)
        optimizer_step(self.model, self.optimizer, parts.loss, self.config.grad_clip)
        loss, reconstruction, reward = (float(x.detach()) for x in parts[:3])
        self.seconds.append(time.perf_counter() - started)
        self.batches.update(digest(frames, actions, rewards))
        kl_term = (loss - reconstruction - self.config.reward_scale * reward) / self.config.kl_scale
        self.add({"loss": loss, "pixel_mse": 2 * reconstruction / self.pixels, "reward_mse": 2 * reward,
                  "kl_term": kl_term})


class MbrlTrainer(Trainer):
    def __init__(self, model: Any, transition_batch: Any, settings: Settings):
        super().__init__("mbrl", settings.rssm.channels * settings.rssm.image_size ** 2)
        self.model, self.transition_batch, self.channels = model, transition_batch, settings.rssm.channels
        train = settings.train
        self.optimizer = torch.optim.Adam(model.parameters(), lr=train.lr, eps=settings.mbrl_scale * train.adam_eps)

    def step(self, frames: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor) -> None:
        """``PlaNetModel.update`` (its loss, clip and Adam step) on the same batch, gray frames as (B, L, 1, H, W)."""
        started = time.perf_counter()
        obs = frames.unsqueeze(2) if self.channels == 1 else frames.movedim(-1, 2)  # (B, L, C, H, W) uint8
        batch = self.transition_batch(obs=obs, act=actions, next_obs=None, rewards=rewards, terminateds=None,
                                      truncateds=None)
        loss, meta = self.model.update(batch, self.optimizer)
        self.seconds.append(time.perf_counter() - started)
        self.batches.update(digest(frames, actions, rewards))
        # mbrl's pixels are x / 256 - 0.5: its squared errors times (256 / 255)² are those of pixels in [0, 1]
        self.add({"loss": float(loss), "pixel_mse": meta["observations_loss"] / self.pixels * (256 / 255) ** 2,
                  "reward_mse": meta["reward_loss"], "kl_term": meta["kl_loss"]})


def train_both(piga: PigaTrainer, mbrl: MbrlTrainer, seqs: _Sequences, settings: Settings) -> None:
    """``steps`` steps of each model, in turn (alternating which goes first, so that a changing load affects
    both alike), each step's batch drawn once by piga's sampler and given to both."""
    train, repeat = settings.train, settings.rssm.action_repeat
    rng = np.random.default_rng(train.seed)
    for step in range(1, train.steps + 1):
        batch = seqs.batch(rng, train.batch_size, train.chunk_length, repeat)  # (B, L, H, W), (B, L, R·A), (B, L)
        for trainer in ((piga, mbrl) if step % 2 else (mbrl, piga)):
            trainer.step(*batch)
        if step % settings.log_every == 0 or step == train.steps:
            piga.record(step)
            mbrl.record(step)
            p, m = piga.curve[-1], mbrl.curve[-1]
            print(f"step {step}: pixel MSE piga {p['pixel_mse']:.5f} mbrl {m['pixel_mse']:.5f}, reward MSE piga "
                  f"{p['reward_mse']:.4f} mbrl {m['reward_mse']:.4f}, KL term piga {p['kl_term']:.3f} mbrl "
                  f"{m['kl_term']:.3f}; s/step piga {statistics.median(piga.seconds):.3f} mbrl "
                  f"{statistics.median(mbrl.seconds):.3f}", flush=True)


# ----------------------------------------------------------------------------------------------- evaluation


@dataclass
class Filtered:
    """A model's filtering of validation chunks, frames 1 to L-1 (B sequences, L model steps)."""

    frames: torch.Tensor
    """(B, L-1, H, W, C) reconstructions of the posterior samples, pixels in [0, 1]."""
    rewards: torch.Tensor
    """(B, L-1) predicted rewards from the states of frames 1 to L-1."""
    kl: torch.Tensor
    """(B, L-1) KL(q || p) summed over the stochastic state."""


def gaussian_kl(q_mean: torch.Tensor, q_std: torch.Tensor, p_mean: torch.Tensor, p_std: torch.Tensor) -> torch.Tensor:
    """KL(q || p) of diagonal Gaussians, summed over the last axis (torch.distributions' formula, for both models)."""
    q, p = torch.distributions.Normal(q_mean, q_std), torch.distributions.Normal(p_mean, p_std)
    return torch.distributions.kl_divergence(q, p).sum(-1)


def to_unit(x: torch.Tensor, divisor: float) -> torch.Tensor:
    """Model pixels x = frame / divisor - 0.5 (B, T, C, H, W) as pixels in [0, 1] of a uint8 frame: (B, T, H, W, C)."""
    return ((x + 0.5) * (divisor / 255)).movedim(2, -1)


@torch.no_grad()
def filter_piga(model: WorldModel, frames: torch.Tensor, actions: torch.Tensor, seed: int) -> Filtered:
    h, s, prior, post = model.observe(frames, actions, torch.Generator().manual_seed(seed))
    return Filtered(to_unit(model.decode(h, s), 255)[:, 1:], model.reward(h, s)[:, 1:],
                    gaussian_kl(post.mean, post.std, prior.mean, prior.std)[:, 1:])


@torch.no_grad()
def filter_mbrl(model: Any, frames: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor, seed: int) -> Filtered:
    """mbrl's ``forward``, as its loss calls it: frames 1 to L-1 under actions 0 to L-2, from a zero state."""
    model.eval()
    obs = model._process_pixel_obs(frames.unsqueeze(2))  # (B, L, 1, H, W), x / 256 - 0.5
    saved, model.rng = model.rng, torch.Generator().manual_seed(seed)
    try:
        prior, _, post, _, _, decoded, predicted = model.forward(obs[:, 1:], actions[:, :-1], rewards[:, :-1])
    finally:
        model.rng = saved
    s = model.latent_state_size
    return Filtered(to_unit(decoded, 256), predicted,
                    gaussian_kl(post[..., :s], post[..., s:], prior[..., :s], prior[..., s:]))


@torch.no_grad()
def open_loop_piga(model: WorldModel, frames: torch.Tensor, actions: torch.Tensor, context: int, horizon: int,
                   seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Imagined frames (B, H, h, w, C) in [0, 1] and rewards (B, H) of the model steps context to context + H - 1."""
    decoded, predicted = model.open_loop(frames[:, :context + horizon], actions[:, :context + horizon], context,
                                         torch.Generator().manual_seed(seed))
    return to_unit(decoded, 255)[:, context:], predicted[:, context:]


@torch.no_grad()
def open_loop_mbrl(model: Any, frames: torch.Tensor, actions: torch.Tensor, context: int, horizon: int,
                   seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The same with mbrl's API, one sequence at a time (its ``update_posterior`` takes one frame): the first
    frame with no action, then each frame with the action before it; then ``sample`` under the actions after
    frame context - 1 on."""
    model.eval()
    generator = torch.Generator().manual_seed(seed)
    imagined, predicted = [], []
    for seq_frames, seq_actions in zip(frames, actions):
        model.reset_posterior()
        state = model.update_posterior(seq_frames[0].unsqueeze(0), rng=generator)  # (1, H, W)
        for t in range(1, context):
            state = model.update_posterior(seq_frames[t].unsqueeze(0), seq_actions[t - 1], rng=generator)
        decoded, rewards = [], []
        for t in range(context - 1, context - 1 + horizon):
            latent, reward, _, state = model.sample(seq_actions[t].unsqueeze(0), state, rng=generator)
            decoded.append(model._forward_decoder(latent, state["belief"]))  # (1, C, H, W)
            rewards.append(reward.reshape(1))
        imagined.append(torch.cat(decoded))
        predicted.append(torch.cat(rewards))
    model.reset_posterior()
    return to_unit(torch.stack(imagined), 256), torch.stack(predicted)


def reward_targets(rewards: torch.Tensor, first_state: int, count: int, alignment: str) -> torch.Tensor:
    """The rewards (B, count) that the states first_state... read: with ``transition`` alignment, the state of
    model step t predicts the reward of the actions after step t - 1; with ``frame``, those after step t."""
    start = first_state - 1 if alignment == "transition" else first_state
    return rewards[:, start:start + count]


def evaluate(piga: WorldModel, mbrl: Any, settings: Settings, data: Path) -> dict[str, Any]:
    """Each model's errors on the validation split (the train split without one), and the guesses that
    know nothing (the mean frame, the mean reward) as a scale."""
    info = inspect_dataset(data)
    split = "valid" if info.split_counts["valid"] else "train"
    seqs = _Sequences(data, split, settings.valid_sequences)
    repeat, length, seed = settings.rssm.action_repeat, settings.train.chunk_length, settings.train.seed
    frames, actions, rewards = model_steps(seqs.frames, seqs.actions, seqs.rewards, repeat)  # whole sequences
    chunk = frames[:, :length], actions[:, :length], rewards[:, :length]
    real = (chunk[0].float() / 255).unsqueeze(-1)[:, 1:]  # (B, L-1, H, W, 1)
    alignment = settings.rssm.reward_alignment
    filtered = {"piga": filter_piga(piga.eval(), chunk[0], chunk[1], seed), "mbrl": filter_mbrl(mbrl, *chunk, seed)}
    targets = {"piga": reward_targets(chunk[2], 1, length - 1, alignment),
               "mbrl": reward_targets(chunk[2], 1, length - 1, "transition")}
    context = min(OPEN_LOOP_CONTEXT, frames.shape[1] - 1)
    horizon = min(LatentPlannerConfig().cem.horizon, frames.shape[1] - context)
    loops = {"piga": open_loop_piga(piga, frames, actions, context, horizon, seed),
             "mbrl": open_loop_mbrl(mbrl, frames, actions, context, horizon, seed)}
    loop_real = (frames[:, context:context + horizon].float() / 255).unsqueeze(-1)
    loop_targets = {"piga": reward_targets(rewards, context, horizon, alignment),
                    "mbrl": reward_targets(rewards, context, horizon, "transition")}
    rows = {}
    for name in MODELS:
        f, (loop_frames, loop_rewards) = filtered[name], loops[name]
        loop_error = loop_rewards - loop_targets[name]  # (B, H)
        rows[name] = {"pixel_mse": float((f.frames - real).square().mean()),
                      "reward_mse": float((f.rewards - targets[name]).square().mean()),
                      "kl": float(f.kl.mean()),
                      "open_loop_reward_mse": float(loop_error.square().mean()),
                      "open_loop_reward_abs_error": float(loop_error.abs().mean()),
                      "open_loop_reward_abs_error_by_step": loop_error.abs().mean(0).tolist(),
                      "open_loop_pixel_mse": float((loop_frames - loop_real).square().mean()),
                      "open_loop_pixel_mse_by_step": (loop_frames - loop_real).square().mean((0, 2, 3, 4)).tolist()}
    mean_frame = real.mean((0, 1), keepdim=True)
    mean_reward = seqs.rewards.mean() * repeat  # the mean reward of a model step's R env steps
    guess = {"pixel_mse": float((mean_frame - real).square().mean()),
             "reward_mse": float((targets["mbrl"] - mean_reward).square().mean()),
             "open_loop_reward_mse": float((loop_targets["mbrl"] - mean_reward).square().mean()),
             "open_loop_reward_abs_error": float((loop_targets["mbrl"] - mean_reward).abs().mean()),
             "open_loop_pixel_mse": float((mean_frame - loop_real).square().mean())}
    return {"split": split, "sequences": len(frames), "chunk_model_steps": length, "open_loop_context": context,
            "open_loop_steps": horizon, "models": rows, "mean_guess": guess}


# ----------------------------------------------------------------------------------------------- the page


def differences(settings: Settings) -> list[str]:
    """What the two trainings do not share, in words."""
    rssm, train = settings.rssm, settings.train
    out = [
        "Initialisation: mbrl applies Dreamer's (Xavier-uniform weights and zero biases for its linear and conv layers, "
        "an orthogonal GRU recurrence; its transposed convs keep PyTorch's default); piga keeps PyTorch's defaults "
        "throughout. Both draw from torch.manual_seed(seed), so no two weights are the same.",
        "The first frame of a chunk: piga filters frames 0 to L-1, the first from the zero state with a zero action; "
        "mbrl's forward filters frames 1 to L-1, the first from the zero state with the real action a_0, so frame 0 is "
        "neither encoded nor reconstructed. Its image loss and KL cover L-1 frames, piga's L; the validation numbers are "
        "over frames 1 to L-1 for both. For the open-loop test, mbrl's update_posterior filters frame 0 with a zero "
        "action as piga does (which its training never does).",
        f"The layer before the GRU: mbrl's is belief-size wide ({rssm.deter_size}), piga's hidden-size wide "
        f"({rssm.hidden_size})" + (" (the same here)." if rssm.deter_size == rssm.hidden_size else
                                   "; the parameter counts differ by it."),
        "Pixel scaling: mbrl feeds x / 256 - 0.5, piga x / 255 - 0.5; every pixel error is converted to pixels in "
        "[0, 1] (x / 255).",
        "mbrl's PlaNetModel.update also reads each parameter's gradient norm back (.item() per tensor) every step, "
        "which its seconds per step include.",
    ]
    if settings.objective == "matched":
        out.insert(0, f"The loss: mbrl's image and reward terms are plain squared errors, twice piga's (which halve "
                   f"them); mbrl was given twice piga's KL weight ({2 * train.kl_scale:g}), gradient clip "
                   f"({2 * train.grad_clip:g}) and Adam epsilon ({2 * train.adam_eps:g}), which makes its loss twice "
                   f"piga's and its Adam steps those of piga's objective.")
    else:
        out.insert(0, f"The loss: mbrl's image and reward terms are plain squared errors, twice piga's (which halve "
                   f"them), and it was given piga's KL weight ({train.kl_scale:g}): relative to the reconstruction, "
                   f"its KL weighs half as much.")
    if rssm.reward_alignment == "frame":
        out.insert(1, "The reward head: piga reads the state of the frame before the actions (--reward-alignment "
                   "frame), mbrl the state they lead to (PlaNet's, which mbrl does not let change).")
    return out


def settings_rows(settings: Settings) -> list[tuple[str, str, str]]:
    """(setting, piga, mbrl) for the page."""
    rssm, train, k = settings.rssm, settings.train, settings.mbrl_scale
    same = lambda v: (v, v)  # noqa: E731
    rows = [("deterministic / stochastic state", *same(f"{rssm.deter_size} / {rssm.stoch_size}")),
            ("MLP width", *same(str(rssm.hidden_size))),
            ("conv depth", *same(f"{rssm.depth} (x1, x2, x4, x8)")),
            ("frames", "64x64 gray uint8, (B, L, 64, 64)", "the same, as (B, L, 1, 64, 64): one-channel encoder and decoder"),
            ("action repeat", *same(f"{rssm.action_repeat} (the R actions of a model step as one input, their rewards summed)")),
            ("reward head reads", "the state after the actions" if rssm.reward_alignment == "transition" else
             "the state before the actions", "the state after the actions"),
            ("min std", *same(f"{rssm.min_std:g}")),
            ("free nats", *same(f"{train.free_nats:g}")),
            ("KL weight", f"{train.kl_scale:g}", f"{k * train.kl_scale:g}"),
            ("learning rate", *same(f"{train.lr:g}")),
            ("Adam epsilon", f"{train.adam_eps:g}", f"{k * train.adam_eps:g}"),
            ("gradient clip (global norm)", f"{train.grad_clip:g}", f"{k * train.grad_clip:g}"),
            ("batch x chunk", *same(f"{train.batch_size} x {train.chunk_length} model steps")),
            ("steps, seed", *same(f"{train.steps}, {train.seed}"))]
    return rows


def fmt(x: float) -> str:
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:,.0f}"


def page(record: dict[str, Any], settings: Settings) -> str:
    ev, models = record["valid"], record["models"]
    rows = ev["models"]
    lines = ["# PlaNet-style RSSM cross-check against mbrl-lib's PlaNet\n",
             f"Command: `{record['command']}`\n",
             (f"Data: `{record['data']['command']}`, " if record["data"].get("command") else "Data: ")
             + f"{record['data']['train_sequences']} train sequences of {record['data']['frames_per_sequence']} "
             f"frames; evaluated on the first {ev['chunk_model_steps']} model steps of {ev['sequences']} "
             f"{ev['split']} sequences.\n",
             f"Machine: {machine_words(record['machine'])}; load average {record['load_average']['before'][0]:.2f} "
             f"before, {record['load_average']['after'][0]:.2f} after.\n",
             "Both models trained in this process, a step of each in turn, on the same batches (fingerprints "
             + ("equal" if record["same_batches"] else "DIFFERENT") + ").\n",
             "## Settings\n", "| setting | piga | mbrl |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in settings_rows(settings)]
    lines += ["", "## Results on the validation split\n",
              "Pixel errors are MSEs of pixels in [0, 1]; rewards are a model step's summed reward. Filtered: the "
              f"posterior of each frame 1 to {ev['chunk_model_steps'] - 1} of the chunk. Open loop: "
              f"{ev['open_loop_context']} model steps filtered, then {ev['open_loop_steps']} imagined from the prior "
              "under the real actions. The mean guess predicts the split's mean frame and mean reward.\n",
              "| | parameters | s per step (median) | pixel MSE | reward MSE | KL (nats per frame) | open-loop reward MSE | "
              "open-loop reward abs error | open-loop pixel MSE |", "|---|---|---|---|---|---|---|---|---|"]
    for name in MODELS:
        r, m = rows[name], models[name]
        label = NAMES[name].format(version=record["mbrl_version"])
        lines.append(f"| {label} | {m['parameters']:,} | {m['seconds_per_step_median']:.3f} | {r['pixel_mse']:.5f} | "
                     f"{r['reward_mse']:.4f} | {r['kl']:.2f} | {r['open_loop_reward_mse']:.4f} | "
                     f"{r['open_loop_reward_abs_error']:.3f} | {r['open_loop_pixel_mse']:.5f} |")
    g = ev["mean_guess"]
    lines.append(f"| mean guess | | | {g['pixel_mse']:.5f} | {g['reward_mse']:.4f} | | {g['open_loop_reward_mse']:.4f} | "
                 f"{g['open_loop_reward_abs_error']:.3f} | {g['open_loop_pixel_mse']:.5f} |")
    ratio = lambda key: rows["piga"][key] / rows["mbrl"][key] if rows["mbrl"][key] else float("nan")  # noqa: E731
    lines += ["", "piga over mbrl: pixel MSE " + ", ".join(
        f"{label} {ratio(key):.2f}x" for label, key in
        (("filtered", "pixel_mse"), ("reward MSE", "reward_mse"), ("open-loop reward MSE", "open_loop_reward_mse"),
         ("open-loop pixel MSE", "open_loop_pixel_mse"))) + "; seconds per step "
        f"{models['piga']['seconds_per_step_median'] / models['mbrl']['seconds_per_step_median']:.2f}x.\n",
        "Open-loop reward abs error by imagined step:\n",
        "| step | " + " | ".join(str(k + 1) for k in range(ev["open_loop_steps"])) + " |",
        "|---|" + "---|" * ev["open_loop_steps"]]
    for name in MODELS:
        lines.append(f"| {name} | " + " | ".join(f"{x:.3f}" for x in rows[name]["open_loop_reward_abs_error_by_step"]) + " |")
    lines += ["", "## Training curves\n",
              f"Means over each {settings.log_every} steps of the training terms, in the same units for both: the pixel "
              "MSE of the posterior reconstructions (pixels in [0, 1]; piga over L frames, mbrl L-1), the reward MSE, "
              "and the KL term after the free nats.\n",
              "| step | pixel MSE piga | pixel MSE mbrl | reward MSE piga | reward MSE mbrl | KL term piga | KL term mbrl | "
              "seconds piga | seconds mbrl |", "|---|---|---|---|---|---|---|---|---|"]
    for p, m in zip(models["piga"]["curve"], models["mbrl"]["curve"]):
        lines.append(f"| {p['step']} | {p['pixel_mse']:.5f} | {m['pixel_mse']:.5f} | {p['reward_mse']:.4f} | "
                     f"{m['reward_mse']:.4f} | {p['kl_term']:.3f} | {m['kl_term']:.3f} | {p['seconds']:.0f} | "
                     f"{m['seconds']:.0f} |")
    lines += ["", "## What differs\n"] + [f"- {d}" for d in record["differences"]]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    rssm, train = RSSMConfig(), PlanetTrainConfig()
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="a pendulum HDF5 file with /rewards (piga-collect's)")
    p.add_argument("--out", type=out_prefix, default="results/planet_crosscheck", help="writes OUT.json and OUT.md (default %(default)s)")
    p.add_argument("--steps", type=positive_int, default=train.steps, help="optimiser steps of each model (default %(default)s)")
    p.add_argument("--batch-size", type=positive_int, default=train.batch_size, help="chunks per batch (default %(default)s)")
    p.add_argument("--chunk-length", type=positive_int, default=train.chunk_length,
                   help="model steps per chunk (default %(default)s)")
    p.add_argument("--deter-size", type=positive_int, default=rssm.deter_size, help="GRU state size (default %(default)s)")
    p.add_argument("--stoch-size", type=positive_int, default=rssm.stoch_size,
                   help="stochastic state size (default %(default)s)")
    p.add_argument("--hidden-size", type=positive_int, default=rssm.hidden_size, help="MLP width (default %(default)s)")
    p.add_argument("--depth", type=positive_int, default=rssm.depth, help="channels of the first conv (default %(default)s)")
    p.add_argument("--action-repeat", type=positive_int, default=rssm.action_repeat,
                   help="env steps per model step, for both models (default %(default)s)")
    p.add_argument("--reward-alignment", choices=get_args(RewardAlignment), default="transition",
                   help="the state piga's reward head reads; mbrl's is always 'transition' (default %(default)s, "
                        f"to match it; piga-baseline's is {rssm.reward_alignment!r})")
    p.add_argument("--free-nats", type=nonnegative_float, default=train.free_nats,
                   help="KL free nats of both (default %(default)s)")
    p.add_argument("--mbrl-objective", choices=("matched", "native"), default="matched",
                   help="matched: mbrl's KL weight, clip and Adam epsilon doubled, so that its loss is twice piga's; "
                        "native: piga's numbers as they are (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=train.seed, help="seed of both models, the batches and the samples "
                                                                      "(default %(default)s)")
    p.add_argument("--log-every", type=positive_int, default=train.checkpoint_every,
                   help="steps per point of the training curves (default %(default)s)")
    p.add_argument("--valid-sequences", type=positive_int, default=64,
                   help="validation sequences evaluated (default %(default)s)")
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    try:
        planet_model, transition_batch = import_mbrl()
    except MbrlMissing as exc:
        p.exit(1, f"{p.prog}: error: mbrl.models.planet is not importable ({exc}); install it beside piga with: "
                  f"{MBRL_INSTALL}\n")
    torch.set_num_threads(1)
    data = Path(args.data)
    try:
        info = inspect_dataset(data)
        rssm = rssm_config_for(info, {"deter_size": args.deter_size, "stoch_size": args.stoch_size,
                                      "hidden_size": args.hidden_size, "depth": args.depth,
                                      "action_repeat": args.action_repeat, "reward_alignment": args.reward_alignment})
        train = PlanetTrainConfig(steps=args.steps, batch_size=args.batch_size, chunk_length=args.chunk_length,
                                  free_nats=args.free_nats, seed=args.seed, threads=1)
        check_planet_data(info, train, rssm.action_repeat)
    except (OSError, ValueError) as exc:
        p.exit(1, f"{p.prog}: error: {' '.join(str(exc).split())}\n")
    if train.reward_scale != 1:
        p.exit(1, f"{p.prog}: error: mbrl's PlaNet has no reward weight; piga's is {train.reward_scale:g}\n")
    settings = Settings(rssm, train, args.mbrl_objective, args.log_every, args.valid_sequences)
    piga = build_piga(settings)
    mbrl = build_mbrl(planet_model, settings, piga)
    trainers = PigaTrainer(piga, settings), MbrlTrainer(mbrl, transition_batch, settings)
    seqs = _Sequences(data, "train")
    load_before = os.getloadavg()
    try:
        train_both(*trainers, seqs, settings)
    except FloatingPointError as exc:
        p.exit(1, f"{p.prog}: error: {exc}\n")
    valid = evaluate(piga, mbrl, settings, data)
    models = {}
    for trainer, model in zip(trainers, (piga, mbrl)):
        seconds = trainer.seconds
        models[trainer.name] = {"parameters": parameter_count(model), "seconds_per_step_median": statistics.median(seconds),
                                "seconds_per_step_mean": statistics.fmean(seconds), "train_seconds": sum(seconds),
                                "batches_sha256": trainer.batches.hexdigest(), "curve": trainer.curve}
    command = ["python", *sys.argv] if argv is None else ["python", "benchmarks/planet_crosscheck.py", *argv]
    record = {"command": shlex.join(command),
              "machine": machine(), "load_average": {"before": load_before, "after": os.getloadavg()},
              "mbrl_version": _mbrl_version(),
              "data": {"file": data.name, "command": info.attrs.get("command"), "train_sequences": len(seqs),
                       "frames_per_sequence": info.steps,
                       "split_counts": info.split_counts},
              "settings": {"rssm": rssm.to_dict(), "train": train.to_dict(), "mbrl_objective": args.mbrl_objective,
                           "mbrl_scale": settings.mbrl_scale, "log_every": args.log_every,
                           "valid_sequences": args.valid_sequences},
              "same_batches": models["piga"]["batches_sha256"] == models["mbrl"]["batches_sha256"],
              "models": models, "valid": valid, "differences": differences(settings)}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_page(out, record, page(record, settings))
    return 0


def _mbrl_version() -> str:
    import mbrl

    return str(mbrl.__version__)


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
