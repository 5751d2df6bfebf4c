"""A frame autoencoder for "DDPG from a latent": trained on a data file's frames, it turns a 64x64
gray frame into a small code in [-1, 1] (a tanh bottleneck).

Plain deterministic autoencoder, MSE loss: the paper's variant used a VAE; the code's bounds are
what DDPG needs (a bounded observation space), and a tanh bottleneck gives them without a prior.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from piga.atomic import atomic_output
from piga.data import read_sequences

__all__ = ["AutoencoderConfig", "FrameAutoencoder", "load_autoencoder", "train_autoencoder"]


@dataclass(frozen=True)
class AutoencoderConfig:
    """The autoencoder and how it is trained."""

    latent_size: int = 8
    """Z, the code's size (the pendulum's state is 2-D; its picture also shows the torque arrow)."""
    depth: int = 16
    """Channels of the first conv layer, doubled at each of the four."""
    steps: int = 2000
    """Adam steps."""
    batch_size: int = 64
    """Frames per step."""
    lr: float = 1e-3
    """Adam's learning rate."""
    seed: int = 0
    """Seed of initialisation and batches."""

    def __post_init__(self) -> None:
        if min(self.latent_size, self.depth, self.steps, self.batch_size) < 1 or not self.lr > 0 or self.seed < 0:
            raise ValueError(f"AutoencoderConfig needs sizes and steps >= 1, lr > 0 and seed >= 0, got {self}")


class FrameAutoencoder(nn.Module):
    """(B, 1, 64, 64) in [0, 1] <-> codes (B, Z) in [-1, 1]."""

    def __init__(self, config: AutoencoderConfig = AutoencoderConfig()):
        super().__init__()
        self.config = config
        d, z = config.depth, config.latent_size
        self.encoder = nn.Sequential(
            nn.Conv2d(1, d, 4, 2, 1), nn.ReLU(),  # (B, d, 32, 32)
            nn.Conv2d(d, 2 * d, 4, 2, 1), nn.ReLU(),  # (B, 2d, 16, 16)
            nn.Conv2d(2 * d, 4 * d, 4, 2, 1), nn.ReLU(),  # (B, 4d, 8, 8)
            nn.Conv2d(4 * d, 8 * d, 4, 2, 1), nn.ReLU(),  # (B, 8d, 4, 4)
            nn.Flatten(), nn.Linear(8 * d * 16, z), nn.Tanh(),  # (B, Z)
        )
        self.decoder = nn.Sequential(
            nn.Linear(z, 8 * d * 16), nn.ReLU(), nn.Unflatten(1, (8 * d, 4, 4)),
            nn.ConvTranspose2d(8 * d, 4 * d, 4, 2, 1), nn.ReLU(),  # (B, 4d, 8, 8)
            nn.ConvTranspose2d(4 * d, 2 * d, 4, 2, 1), nn.ReLU(),  # (B, 2d, 16, 16)
            nn.ConvTranspose2d(2 * d, d, 4, 2, 1), nn.ReLU(),  # (B, d, 32, 32)
            nn.ConvTranspose2d(d, 1, 4, 2, 1), nn.Sigmoid(),  # (B, 1, 64, 64)
        )

    def forward(self, x: Tensor) -> Tensor:
        return self.decoder(self.encoder(x))

    @torch.inference_mode()
    def encode_frame(self, frame: np.ndarray) -> np.ndarray:
        """A uint8 frame (64, 64) -> its code float32 (Z,)."""
        x = torch.from_numpy(np.ascontiguousarray(frame)).float().div(255.0)[None, None]
        return self.encoder(x)[0].numpy().astype(np.float32)


def train_autoencoder(data: str | Path, config: AutoencoderConfig, out: str | Path, progress: bool = True) -> tuple[FrameAutoencoder, float]:
    """Trains on the train split's frames of ``data`` and writes the model to ``out`` atomically.

    Returns:
        The model (eval mode) and its final training MSE (mean over the last 100 steps).
    """
    frames, _ = read_sequences(data, "train")
    if frames.ndim != 4 or frames.shape[2:] != (64, 64):
        raise ValueError(f"{data}: the autoencoder takes gray 64x64 frames, got frames of shape {frames.shape[2:]}")
    flat = torch.from_numpy(frames.reshape(-1, 1, 64, 64))  # (N·T, 1, 64, 64) uint8
    torch.manual_seed(config.seed)
    model = FrameAutoencoder(config)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    rng = np.random.default_rng(config.seed)
    recent: list[float] = []
    for _ in tqdm(range(config.steps), desc="autoencoder", disable=not progress):
        x = flat[torch.from_numpy(rng.integers(len(flat), size=config.batch_size))].float() / 255.0
        loss = nn.functional.mse_loss(model(x), x)
        if not torch.isfinite(loss):
            raise RuntimeError(f"autoencoder training diverged (loss {loss.item()}); nothing was written")
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        recent = (recent + [loss.item()])[-100:]
    model.eval()
    with atomic_output(out, overwrite=True) as tmp:
        torch.save({"config": asdict(config), "model": model.state_dict(), "mse": float(np.mean(recent))}, tmp)
    return model, float(np.mean(recent))


def load_autoencoder(path: str | Path) -> FrameAutoencoder:
    """The autoencoder written by :func:`train_autoencoder` (eval mode)."""
    payload: dict[str, Any] = torch.load(path, map_location="cpu", weights_only=False)
    model = FrameAutoencoder(AutoencoderConfig(**payload["config"]))
    model.load_state_dict(payload["model"])
    return model.eval()
