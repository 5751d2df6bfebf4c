"""A frame autoencoder for "DDPG from a latent": trained on a data file's frames, it turns a 64x64
gray frame into a small code in [-1, 1].

Plain deterministic autoencoder, MSE loss: the paper's variant used a VAE. Two choices keep its
training from collapsing, which it did with the textbook layout (a tanh bottleneck, a sigmoid
output), leaving DDPG's "latent" a constant:

- **The decoder draws on top of the training frames' mean** (a logit offset, ``mean_logit``). The
  pendulum covers a few percent of the frame, so drawing the mean frame is a strong minimum (MSE
  equal to the pixel variance, 0.0045) that the plain decoder never left: measured on the
  benchmark's 500-sequence file, 2000 steps at learning rate 1e-3 and 500 at 3e-4.
- **The bottleneck is linear while training.** With the offset, a tanh bottleneck still saturated
  at +-1 for every frame within 100 steps on the 2000-sequence file (its gradient then vanishes).
  After training, the codes are standardised with the training frames' per-dimension mean and std
  and squashed, ``tanh(standardised / 2)``: a bounded observation space, as DDPG needs, in which
  +-2 standard deviations span +-0.76.

With both, the default 2000 steps on the baselines benchmark's 2000-sequence file give a test MSE
of 0.00032 (7% of drawing the mean), and a 5-nearest-neighbour probe reads (cos θ, sin θ) off the
code with RMSE 0.006 (``benchmarks/baseline_probes.py autoencoder``; results/ddpg_tuning.md).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from piga.data.schema import (DataFormatError, DatasetInfo, check_frames_have_signal, inspect_dataset, read_sequences,
                              split_indices)
from piga.data.windows import SequenceReader, loads_whole
from piga.io.atomic import atomic_output, torch_save
from piga.io.device import Device, resolve_device
from piga.io.resources import available_memory
from piga.io.choices import check_types

__all__ = ["AutoencoderConfig", "FrameAutoencoder", "autoencoder_seconds", "check_autoencoder_data", "load_autoencoder", "train_autoencoder"]


#: Most Adam steps the autoencoder may take: piga-train-model's most optimiser steps
#: (:data:`piga.training.train.MAX_TRAIN_STEPS`, which agents do not import), weeks on a CPU; 1e9 was taken and trained for
#: ever, without a word under --quiet.
MAX_STEPS = 10_000_000


@dataclass(frozen=True)
class AutoencoderConfig:
    """The autoencoder and how it is trained."""

    latent_size: int = 8
    """Z, the code's size (the pendulum's state is 2-D; its picture also shows the torque arrow)."""
    depth: int = 16
    """Channels of the first conv layer, doubled at each of the four."""
    steps: int = 2000
    """Adam steps, at most :data:`MAX_STEPS`."""
    batch_size: int = 64
    """Frames per step."""
    lr: float = 1e-3
    """Adam's learning rate."""
    seed: int = 0
    """Seed of initialisation and batches."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        if min(self.latent_size, self.depth, self.steps, self.batch_size) < 1 or not 0 < self.lr < math.inf or self.seed < 0:
            raise ValueError(f"AutoencoderConfig needs sizes and steps >= 1, a finite lr > 0 and seed >= 0, got latent_size="
                             f"{self.latent_size}, depth={self.depth}, steps={self.steps}, batch_size={self.batch_size}, "
                             f"lr={self.lr}, seed={self.seed}")
        if self.steps > MAX_STEPS:
            raise ValueError(f"AutoencoderConfig.steps must be at most {MAX_STEPS:,} (weeks on a CPU), got {self.steps:,}")


class FrameAutoencoder(nn.Module):
    """(B, 1, 64, 64) in [0, 1] <-> raw codes (B, Z) (:meth:`forward`); :meth:`encode` gives the
    bounded codes (B, Z) in [-1, 1] that DDPG sees."""

    def __init__(self, config: AutoencoderConfig = AutoencoderConfig()):
        super().__init__()
        self.config = config
        d, z = config.depth, config.latent_size
        self.encoder = nn.Sequential(
            nn.Conv2d(1, d, 4, 2, 1), nn.ReLU(),  # (B, d, 32, 32)
            nn.Conv2d(d, 2 * d, 4, 2, 1), nn.ReLU(),  # (B, 2d, 16, 16)
            nn.Conv2d(2 * d, 4 * d, 4, 2, 1), nn.ReLU(),  # (B, 4d, 8, 8)
            nn.Conv2d(4 * d, 8 * d, 4, 2, 1), nn.ReLU(),  # (B, 8d, 4, 4)
            nn.Flatten(), nn.Linear(8 * d * 16, z),  # (B, Z) raw code, linear (see the module's docstring)
        )
        self.decoder = nn.Sequential(
            nn.Linear(z, 8 * d * 16), nn.ReLU(), nn.Unflatten(1, (8 * d, 4, 4)),
            nn.ConvTranspose2d(8 * d, 4 * d, 4, 2, 1), nn.ReLU(),  # (B, 4d, 8, 8)
            nn.ConvTranspose2d(4 * d, 2 * d, 4, 2, 1), nn.ReLU(),  # (B, 2d, 16, 16)
            nn.ConvTranspose2d(2 * d, d, 4, 2, 1), nn.ReLU(),  # (B, d, 32, 32)
            nn.ConvTranspose2d(d, 1, 4, 2, 1),  # (B, 1, 64, 64) logits, added to mean_logit
        )
        #: logit of the training frames' mean (1, 1, 64, 64), set by :func:`train_autoencoder`
        self.register_buffer("mean_logit", torch.zeros(1, 1, 64, 64))
        #: per-dimension mean and std (Z,) of the training frames' raw codes, set by :func:`train_autoencoder`
        self.register_buffer("code_mean", torch.zeros(z))
        self.register_buffer("code_std", torch.ones(z))

    def decode(self, z: Tensor) -> Tensor:
        """Raw codes (B, Z) -> frames (B, 1, 64, 64) in [0, 1]."""
        return torch.sigmoid(self.decoder(z) + self.mean_logit)

    def forward(self, x: Tensor) -> Tensor:
        return self.decode(self.encoder(x))

    def encode(self, x: Tensor) -> Tensor:
        """Frames (B, 1, 64, 64) in [0, 1] -> bounded codes (B, Z) in [-1, 1]: standardised raw
        codes, squashed by tanh(. / 2)."""
        return torch.tanh((self.encoder(x) - self.code_mean) / (2 * self.code_std))

    @torch.inference_mode()
    def encode_frame(self, frame: np.ndarray) -> np.ndarray:
        """A uint8 frame (64, 64) -> its bounded code float32 (Z,)."""
        x = torch.from_numpy(np.ascontiguousarray(frame)).float().div(255.0)[None, None]
        return self.encode(x)[0].numpy().astype(np.float32)


def check_autoencoder_data(info: DatasetInfo) -> None:
    """Refuses, before anything is written, a file the autoencoder cannot learn from: frames other
    than gray 64x64, an empty train split, or blank frames (:func:`piga.data.schema.check_frames_have_signal`).

    Raises:
        DataFormatError: naming the file and what is wrong.
    """
    if info.image_shape not in ((64, 64), (64, 64, 1)):
        raise DataFormatError(f"{info.path}: the autoencoder takes gray 64x64 frames, got frames of shape {info.image_shape}")
    if not info.split_counts["train"]:
        raise DataFormatError(f"{info.path}: the train split is empty; the autoencoder learns from it")
    check_frames_have_signal(info.path)


class _TrainFrames:
    """A file's train frames by flat index (sequence-major): in memory, or, for a file larger than memory
    (:func:`piga.data.windows.loads_whole`), read by whole sequences through a bounded cache
    (:class:`piga.data.windows.SequenceReader`). The same frames, and the same mean, either way."""

    def __init__(self, data: str | Path, info: DatasetInfo, stream: bool):
        self.steps = info.steps
        self.count = info.split_counts["train"] * info.steps
        self.reader: SequenceReader | None = None
        self.flat: Tensor | None = None
        if stream:
            self.reader = SequenceReader(data, split_indices(data, "train"))
        else:
            frames, _ = read_sequences(data, "train")
            self.flat = torch.from_numpy(frames.reshape(-1, 1, 64, 64))  # (N·T, 1, 64, 64) uint8

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, rows: np.ndarray) -> Tensor:
        """Frames ``rows`` (B,) -> uint8 (B, 1, 64, 64)."""
        if self.flat is not None:
            return self.flat[torch.from_numpy(rows)]
        assert self.reader is not None
        return torch.from_numpy(np.stack([self.reader(r // self.steps)[r % self.steps].reshape(1, 64, 64) for r in rows]))

    def sequence(self, position: int) -> np.ndarray:
        """The frames of the split's sequence ``position``: uint8 (T, 64, 64)."""
        if self.flat is not None:
            return self.flat[position * self.steps:(position + 1) * self.steps, 0].numpy()
        assert self.reader is not None
        return self.reader(position).reshape(self.steps, 64, 64)

    def mean(self) -> Tensor:
        """The frames' mean in [0, 1]: float (1, 1, 64, 64), summed by sequence in float64."""
        total = sum(self.sequence(i).sum(axis=0, dtype=np.float64) for i in range(self.count // self.steps))
        return torch.from_numpy(total / (self.count * 255.0)).float()[None, None]

    def close(self) -> None:
        if self.reader is not None:
            self.reader.close()


def train_autoencoder(data: str | Path, config: AutoencoderConfig, out: str | Path, progress: bool = True,
                      device: Device = "auto") -> tuple[FrameAutoencoder, float]:
    """Trains on the train split's frames of ``data`` and writes the model to ``out`` atomically.

    The file also records the training's wall seconds (``train_seconds``, read by :func:`autoencoder_seconds`).
    It trains on ``device`` (:func:`piga.io.device.resolve_device`; the run's ``SB3Config.device``); the
    initialisation and the batches are drawn on the CPU, and the model is saved and returned on the CPU,
    where it encodes the env's frames. A file larger than memory is read through a bounded cache
    (:class:`_TrainFrames`), with the same batches.

    Returns:
        The model (eval mode, on the CPU) and its final training MSE (mean over the last 100 steps).
    """
    target = resolve_device(device)
    started = time.monotonic()
    info = inspect_dataset(data)
    check_autoencoder_data(info)
    flat = _TrainFrames(data, info, stream=not loads_whole(info.split_counts["train"] * info.sequence_bytes,
                                                           available_memory()))
    try:
        return _train(flat, config, out, progress, target, started)
    finally:
        flat.close()


def _train(flat: _TrainFrames, config: AutoencoderConfig, out: str | Path, progress: bool, target: torch.device,
           started: float) -> tuple[FrameAutoencoder, float]:
    """:func:`train_autoencoder`'s steps on its frames."""
    torch.manual_seed(config.seed)
    model = FrameAutoencoder(config)
    model.mean_logit.copy_(torch.logit(flat.mean().clamp(1e-3, 1 - 1e-3)))  # (1, 1, 64, 64)
    model.to(target)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    rng = np.random.default_rng(config.seed)
    recent: list[float] = []
    for _ in tqdm(range(config.steps), desc="autoencoder", disable=not progress):
        x = flat[rng.integers(len(flat), size=config.batch_size)].to(target).float() / 255.0  # (B, 1, 64, 64)
        loss = nn.functional.mse_loss(model(x), x)
        if not torch.isfinite(loss):
            raise RuntimeError(f"autoencoder training diverged (loss {loss.item()}); nothing was written")
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        recent = (recent + [loss.item()])[-100:]
    model.eval()
    with torch.inference_mode():  # the raw codes' statistics, over (at most) 4096 training frames
        sample = flat[np.sort(rng.permutation(len(flat))[:4096])].to(target).float() / 255.0
        codes = torch.cat([model.encoder(batch) for batch in sample.split(512)])  # (S, Z)
    model.code_mean.copy_(codes.mean(0))
    model.code_std.copy_(codes.std(0).clamp_min(1e-6))
    model.cpu()
    with atomic_output(out, overwrite=True) as tmp:
        torch_save({"config": asdict(config), "model": model.state_dict(), "mse": float(np.mean(recent)),
                    "train_seconds": time.monotonic() - started}, tmp)
    return model, float(np.mean(recent))


def autoencoder_seconds(path: str | Path) -> float | None:
    """The wall seconds that training the autoencoder at ``path`` took (None: a file from before they were recorded)."""
    seconds = torch.load(path, map_location="cpu", weights_only=False).get("train_seconds")
    return None if seconds is None else float(seconds)


def load_autoencoder(path: str | Path) -> FrameAutoencoder:
    """The autoencoder written by :func:`train_autoencoder` (eval mode).

    Raises:
        FileNotFoundError: no file at ``path`` (naming it, and what to do).
        ValueError: a truncated or foreign file (naming it and the cause), or one of the old layout.
    """
    from piga.io.checkpoint import RunKind, check_run_file, unreadable

    path = Path(path)
    what = "autoencoder of a latent DDPG run"
    check_run_file(path)  # a pipe: refused, not read (its open waits for ever)
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: a latent DDPG run encodes its frames with the autoencoder it was "
                                "trained with; restore it, or train the run again with --overwrite")
    try:
        payload: dict[str, Any] = torch.load(path, map_location="cpu", weights_only=False)
        state, config = payload["model"], AutoencoderConfig(**payload["config"])
        old = "code_std" not in state
    except Exception as exc:  # a truncated or foreign file
        raise unreadable(path, RunKind.DDPG, exc, what) from None
    if old:
        raise ValueError(f"{path}: an autoencoder of the old, collapsing layout (tanh bottleneck); train it again")
    try:
        model = FrameAutoencoder(config)
        model.load_state_dict(state)
    except Exception as exc:  # weights of other sizes than its config's
        raise unreadable(path, RunKind.DDPG, exc, what) from None
    return model.eval()
