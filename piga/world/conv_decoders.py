"""Two more black-box decoders for the paper's unseen-region ablation (its Appendix D): a deconvolutional decoder and
a spatial-broadcast decoder (Watters et al. 2019), each from the objects' coordinates to the frame, in place of the
coordinate-consistent spatial-transformer decoder (:mod:`piga.world.decoder`).

Both take what that decoder takes, coordinates (..., N, D) (pixels for D = 2, an angle for D = 1), and draw
(..., C, H, W) frames in [0, 1], so every caller of ``model.decoder`` works with either (``ModelConfig.decoder``).

- :class:`DeconvDecoder`: an MLP from all objects' coordinates to a small feature map, then stride-2 transposed
  convolutions up to the frame; a learned per-pixel logit offset (the background) is added before the sigmoid.

      p (..., N·D) ─► Linear ─► ReLU ─► Linear ─► ReLU ─► Linear ─► (64, H/4, W/4) ─► ConvT ×2 ─► + bkg ─► sigmoid

- :class:`BroadcastDecoder`: each object's scaled coordinates and a one-hot of its index are tiled over the H x W
  grid with two fixed channels holding the pixel's own x and y in [-1, 1], then stride-1 convolutions (3x3, 3x3, 1x1,
  1x1, 16 channels: the per-pixel work of N maps at full resolution is what a CPU can afford) give the object's
  colour and mask logit. Objects are composed as the spatial-transformer decoder composes them: a softmax
  over the N object masks and a learned background mask, image = Σ m̃ ⊙ c (the background's content learned).

Nothing ties a coordinate to where the object appears except what the networks learn; the broadcast decoder's
coordinate channels make "draw at (x, y)" easy to express, which Watters et al. show helps within the range seen.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from piga.world.mlp_decoder import scaled_coords

__all__ = ["DeconvDecoder", "BroadcastDecoder"]


def _logit_background(param: nn.Parameter, background: Tensor) -> None:
    """Sets a (C, H, W) logit parameter so that its sigmoid is ``background`` (C, H, W) in [0, 1]."""
    with torch.no_grad():
        param.copy_(torch.logit(background.to(param), eps=1e-3))


class DeconvDecoder(nn.Module):
    """Object coordinates (..., N, D) -> frames (..., C, H, W) in [0, 1]: an MLP to a (width, H/4, W/4) feature map,
    two stride-2 transposed convolutions to (C, H, W), plus a learned per-pixel background logit, squashed."""

    def __init__(self, image_size: int, channels: int, n_objects: int, coord_dim: int, hidden: int = 200,
                 width: int = 64) -> None:
        super().__init__()
        self.image_size, self.channels, self.n_objects, self.coord_dim = image_size, channels, n_objects, coord_dim
        self.side = math.ceil(image_size / 4)
        self.width = width
        self.mlp = nn.Sequential(nn.Linear(n_objects * coord_dim, hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden), nn.ReLU(),
                                 nn.Linear(hidden, width * self.side * self.side), nn.ReLU())
        self.deconvs = nn.Sequential(nn.ConvTranspose2d(width, width, 4, 2, 1), nn.ReLU(),
                                     nn.ConvTranspose2d(width, channels, 4, 2, 1))
        self.background_logit = nn.Parameter(torch.zeros(channels, image_size, image_size))

    def init_background(self, background: Tensor) -> None:
        """Starts the drawing at ``background`` (C, H, W) in [0, 1] (the per-pixel logit offset)."""
        _logit_background(self.background_logit, background)

    def forward(self, coords: Tensor) -> Tensor:
        """Coordinates (..., N, D) -> frames (..., C, H, W)."""
        lead = coords.shape[:-2]
        z = scaled_coords(coords, self.image_size, self.coord_dim).flatten(-2).reshape(-1, self.n_objects * self.coord_dim)
        h = self.mlp(z).view(-1, self.width, self.side, self.side)  # (F, w, H/4, W/4)
        size = self.image_size
        logits = self.deconvs(h)[..., :size, :size] + self.background_logit  # (F, C, H, W)
        return torch.sigmoid(logits).view(*lead, self.channels, size, size)


class BroadcastDecoder(nn.Module):
    """Object coordinates (..., N, D) -> frames (..., C, H, W) in [0, 1]: a spatial-broadcast decoder per object
    (shared weights, the object's index as a one-hot input), composed by a softmax over masks as
    :class:`piga.world.decoder.Decoder` composes its objects."""

    def __init__(self, image_size: int, channels: int, n_objects: int, coord_dim: int, width: int = 16,
                 kernels: tuple[int, ...] = (3, 3, 1, 1)) -> None:
        super().__init__()
        self.image_size, self.channels, self.n_objects, self.coord_dim = image_size, channels, n_objects, coord_dim
        axis = (torch.arange(image_size, dtype=torch.get_default_dtype()) + 0.5) / image_size * 2 - 1  # pixel centres
        grid_y, grid_x = torch.meshgrid(axis, axis, indexing="ij")  # (H, W) each
        self.register_buffer("grid", torch.stack([grid_x, grid_y]), persistent=False)  # (2, H, W), fixed x, y
        self.register_buffer("identity", torch.eye(n_objects), persistent=False)  # (N, N), one-hot object indices
        convs: list[nn.Module] = []
        inputs = coord_dim + n_objects + 2
        for k in kernels[:-1]:
            convs += [nn.Conv2d(inputs, width, k, 1, k // 2), nn.ReLU()]
            inputs = width
        last = nn.Conv2d(inputs, channels + 1, kernels[-1], 1, kernels[-1] // 2)  # colour and mask logits
        with torch.no_grad():  # objects start faint (mask logit -4 against the background's 0): frames are mostly background
            last.bias[channels] = -4.0
        self.convs = nn.Sequential(*convs, last)
        self.background_logit = nn.Parameter(torch.zeros(channels, image_size, image_size))
        self.background_mask_logit = nn.Parameter(torch.zeros(1, image_size, image_size))

    def init_background(self, background: Tensor) -> None:
        """Starts the background's content at ``background`` (C, H, W) in [0, 1]."""
        _logit_background(self.background_logit, background)

    def forward(self, coords: Tensor) -> Tensor:
        """Coordinates (..., N, D) -> frames (..., C, H, W)."""
        lead = coords.shape[:-2]
        n, d, c, size = self.n_objects, self.coord_dim, self.channels, self.image_size
        z = scaled_coords(coords, size, d).reshape(-1, n, d)  # (F, N, D)
        frames = z.shape[0]
        ids = self.identity.to(z).expand(frames, n, n)  # (F, N, N)
        latent = torch.cat([z, ids], dim=-1).reshape(frames * n, d + n, 1, 1)  # (F·N, D + N, 1, 1)
        tiled = latent.expand(-1, -1, size, size)  # (F·N, D + N, H, W), broadcast over the grid
        grid = self.grid.to(z).expand(frames * n, 2, size, size)  # (F·N, 2, H, W)
        out = self.convs(torch.cat([tiled, grid], dim=1)).view(frames, n, c + 1, size, size)
        contents = torch.cat([torch.sigmoid(out[:, :, :c]),
                              torch.sigmoid(self.background_logit).expand(frames, 1, c, size, size)], dim=1)
        masks = torch.softmax(torch.cat([out[:, :, c:],
                                         self.background_mask_logit.expand(frames, 1, 1, size, size)], dim=1), dim=1)
        image = (masks * contents).sum(dim=1)  # (F, C, H, W), (F, N + 1, 1, H, W) masks over N + 1 layers
        return image.view(*lead, c, size, size)
