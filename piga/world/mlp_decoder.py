"""The black-box decoder of the paper's ablation (its Table 2, "black-box decoder"): an MLP from the objects'
coordinates to the frame, in place of the coordinate-consistent spatial-transformer decoder
(:mod:`piga.world.decoder`).

It takes what that decoder takes, the coordinates (..., N, D) of the objects (pixels for D = 2, an angle
for D = 1), and draws (..., C, H, W) frames, so every caller of ``model.decoder`` works with either. Nothing
ties a coordinate to where the object appears: the network must learn that mapping, which is the property
the ablation removes.

    p (..., N·D) ─► Linear ─► ReLU ─► Linear ─► ReLU ─► Linear ─► sigmoid ─► frame (..., C, H, W)

The positions are scaled to about [-1, 1] (x / H · 2 − 1) before the first layer; angles enter as they are.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

__all__ = ["MLPDecoder", "scaled_coords"]


def scaled_coords(coords: Tensor, image_size: int, coord_dim: int) -> Tensor:
    """Coordinates (..., N, D) as the black-box decoders take them: pixels (D = 2) scaled to about [-1, 1]
    (x / H · 2 − 1), angles (D = 1) as they are."""
    return coords / image_size * 2 - 1 if coord_dim == 2 else coords


class MLPDecoder(nn.Module):
    """Object coordinates (..., N, D) -> frames (..., C, H, W) in [0, 1], through a two-hidden-layer MLP."""

    def __init__(self, image_size: int, channels: int, n_objects: int, coord_dim: int, hidden: int = 200) -> None:
        super().__init__()
        self.image_size, self.channels, self.n_objects, self.coord_dim = image_size, channels, n_objects, coord_dim
        self.net = nn.Sequential(nn.Linear(n_objects * coord_dim, hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden), nn.ReLU(),
                                 nn.Linear(hidden, channels * image_size * image_size))

    @torch.no_grad()
    def init_background(self, background: Tensor) -> None:
        """Starts the drawing at ``background`` (C, H, W) in [0, 1] (the output layer's bias), as
        :meth:`piga.world.decoder.Decoder.init_background` starts the spatial-transformer decoder's."""
        out = self.net[-1]
        assert isinstance(out, nn.Linear)
        out.bias.copy_(torch.logit(background.to(out.bias), eps=1e-3).flatten())

    def forward(self, coords: Tensor) -> Tensor:
        """Coordinates (..., N, D) -> frames (..., C, H, W)."""
        lead = coords.shape[:-2]
        z = scaled_coords(coords, self.image_size, self.coord_dim).flatten(-2)  # (..., N·D), about [-1, 1]
        out = torch.sigmoid(self.net(z))  # (..., C·H·W)
        return out.view(*lead, self.channels, self.image_size, self.image_size)
