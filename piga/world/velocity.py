"""Velocity estimator: the coordinates of the first L frames -> the velocity at frame L.

The paper uses an MLP with 3 hidden layers of 100 tanh units. We keep that MLP, but as a
correction on top of the backward difference ``(p_L - p_{L-1}) / dt``:

    v_L = (p_L - p_{L-1}) / dt + MLP(features)

The final layer starts at zero, so training starts from the finite difference. For a
semi-implicit Euler system such as Gymnasium's pendulum, the difference is already exact.

The MLP sees the L-1 backward differences divided by dt (and, for cartesian systems, the last
position scaled to [-1, 1]), never raw angles. Angle differences are wrapped to [-π, π), so a
pendulum crossing ±π causes no jump.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn


@dataclass(frozen=True)
class VelocityConfig:
    """Velocity estimator architecture."""

    input_frames: int = 4
    """L, frames whose coordinates are used."""
    n_objects: int = 1
    """N."""
    coord_dim: int = 1
    """D: 1 = angle (differences wrapped), 2 = cartesian pixels."""
    dt: float = 0.05
    """Seconds between frames."""
    image_size: int = 64
    """H, to scale cartesian positions to [-1, 1]."""
    hidden: int = 100
    """Units per hidden layer (the paper: 100)."""
    layers: int = 3
    """Hidden layers (the paper: 3)."""
    correction: bool = True
    """Add the MLP correction. False leaves the backward difference alone: exact for
    semi-implicit Euler at one substep (Gymnasium's pendulum). There a jointly trained correction
    can absorb part of the dynamics. One learned a term correlated -0.63 with sin θ and pushed g
    1% high, because a small change in v_L and a change in g look alike over a 10-step rollout."""


def wrap_angle(x: Tensor) -> Tensor:
    """Wraps angles to [-π, π)."""
    return torch.remainder(x + math.pi, 2 * math.pi) - math.pi


class VelocityEstimator(nn.Module):
    """Coordinates (B, L, N, D) -> velocity at frame L, (B, N, D), in coordinate units per second."""

    def __init__(self, config: VelocityConfig):
        super().__init__()
        if config.input_frames < 2:
            raise ValueError(f"the velocity estimator needs input_frames >= 2, got {config.input_frames}")
        self.config = config
        n, d, ell = config.n_objects, config.coord_dim, config.input_frames
        features = n * d * (ell - 1) + (n * d if d == 2 else 0)
        dims = [features] + [config.hidden] * config.layers
        layers: list[nn.Module] = []
        for a, b in zip(dims[:-1], dims[1:]):
            layers += [nn.Linear(a, b), nn.Tanh()]
        last = nn.Linear(dims[-1], n * d)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.mlp = nn.Sequential(*layers, last)

    def differences(self, coords: Tensor) -> Tensor:
        """Backward differences per second, (B, L-1, N, D); angles wrapped."""
        diff = coords[:, 1:] - coords[:, :-1]
        if self.config.coord_dim == 1:
            diff = wrap_angle(diff)
        return diff / self.config.dt

    def forward(self, coords: Tensor) -> Tensor:
        cfg = self.config
        if coords.dim() != 4 or coords.shape[1:] != (cfg.input_frames, cfg.n_objects, cfg.coord_dim):
            raise ValueError(
                f"velocity estimator expects (B, L={cfg.input_frames}, N={cfg.n_objects}, D={cfg.coord_dim}), "
                f"got {tuple(coords.shape)}"
            )
        diff = self.differences(coords)  # (B, L-1, N, D)
        if not cfg.correction:
            return diff[:, -1]
        # Differences of a fast pendulum reach ~8 rad/s, of balls a few px per step: scale to O(1).
        features = [diff.flatten(1) / (10.0 if cfg.coord_dim == 1 else cfg.image_size)]
        if cfg.coord_dim == 2:
            features.append(coords[:, -1].flatten(1) / (cfg.image_size / 2) - 1)
        correction = self.mlp(torch.cat(features, dim=1)).view_as(diff[:, -1])  # (B, N, D)
        scale = 10.0 if cfg.coord_dim == 1 else cfg.image_size
        return diff[:, -1] + scale * correction
