"""The "VideoLSTM" baseline: a black-box frame predictor, with no objects and no physics.

```
frames x_1..x_L ─► ConvEncoder ─► z_1..z_L ─┐
                                            ▼
          LSTM cell over [z_t, u_t] ─► ẑ_{t+1} (teacher-forced on the L input frames, then fed its own ẑ)
                                            │
                         DeconvDecoder ◄────┘ ─► x̃_{L+1..L+T}        DeconvDecoder(z_t) ─► x̃ᵃᵉ
loss = Σ_{t>L} MSE(x̃_t, x_t) + α Σ_t MSE(x̃ᵃᵉ_t, x_t)      (the same loss as piga's, piga.world.model)
```

The actions u_t (the action after frame t) enter the LSTM with each latent when the system has
actions. The decoder draws its frame as the label-free median background of the training frames plus
its output (as piga's decoder may start from that background, ``init_background``); everything else
is learned. It has no physical parameters, so control and
diagnosis refuse its runs.
"""

from __future__ import annotations

import math
from typing import ClassVar

import torch
from torch import Tensor, nn

from piga.world.model import FrameModel, ModelConfig, ModelOutput, prediction_losses, window_inputs


class ConvEncoder(nn.Module):
    """Frames (F, C, H, W) -> latents (F, Z): three stride-2 convolutions and a linear layer."""

    def __init__(self, channels: int, image_size: int, latent: int, width: int = 32):
        super().__init__()
        self.convs = nn.Sequential(
            nn.Conv2d(channels, width, 4, 2, 1), nn.ReLU(),
            nn.Conv2d(width, 2 * width, 4, 2, 1), nn.ReLU(),
            nn.Conv2d(2 * width, 2 * width, 4, 2, 1), nn.ReLU(),
        )
        side = image_size
        for _ in range(3):
            side //= 2  # each convolution halves the side (floor)
        self.linear = nn.Linear(2 * width * side * side, latent)

    def forward(self, x: Tensor) -> Tensor:
        return self.linear(self.convs(x).flatten(1))


class DeconvDecoder(nn.Module):
    """Latents (F, Z) -> logits (F, C, H, W): a linear layer and three stride-2 transposed convolutions
    (to 8·ceil(H/8), cropped to H)."""

    def __init__(self, channels: int, image_size: int, latent: int, width: int = 32):
        super().__init__()
        self.side = math.ceil(image_size / 8)
        self.image_size = image_size
        self.width = 2 * width
        self.linear = nn.Linear(latent, self.width * self.side * self.side)
        self.deconvs = nn.Sequential(
            nn.ReLU(),
            nn.ConvTranspose2d(2 * width, 2 * width, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(2 * width, width, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(width, channels, 4, 2, 1),
        )

    def forward(self, z: Tensor) -> Tensor:
        h = self.linear(z).view(-1, self.width, self.side, self.side)  # (F, 2w, s, s)
        return self.deconvs(h)[..., : self.image_size, : self.image_size]  # (F, C, H, W)


class VideoLSTM(FrameModel):
    """Conv encoder per frame, an LSTM rolling the latents forward (conditioned on the actions), deconv decoder."""

    has_physics: ClassVar[bool] = False
    has_objects: ClassVar[bool] = False
    BASE_LATENT: ClassVar[int] = 128
    """Z, the size of a frame's latent, at ``ModelConfig.video_lstm_scale`` 1."""
    BASE_HIDDEN: ClassVar[int] = 256
    """The LSTM's hidden units, at scale 1."""
    BASE_WIDTH: ClassVar[int] = 32
    """The first convolution's channels (the others have twice as many), at scale 1."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.config = config
        c, h, scale = config.channels, config.image_size, config.video_lstm_scale
        self.latent, self.hidden = scale * self.BASE_LATENT, scale * self.BASE_HIDDEN  # Z and the LSTM's units
        self.encoder = ConvEncoder(c, h, self.latent, width=scale * self.BASE_WIDTH)
        self.cell = nn.LSTMCell(self.latent + config.action_dim, self.hidden)
        self.head = nn.Linear(self.hidden, self.latent)
        self.decoder = DeconvDecoder(c, h, self.latent, width=scale * self.BASE_WIDTH)
        self.register_buffer("background", torch.zeros(c, h, h))

    def set_background(self, background: Tensor) -> None:
        with torch.no_grad():
            self.background.copy_(background)

    def background_image(self) -> Tensor:
        return self.background

    def render(self, z: Tensor) -> Tensor:
        """Latents (B, T, Z) -> frames (B, T, C, H, W): the background plus the decoder's output.

        Not squashed: a sigmoid over logit(background) starts a black background's pixels on its flat tail,
        where drawing a ball has almost no gradient (on a 100-sequence spring file its reconstruction error
        after 300 steps was 0.038 per window, against 0.011 unsquashed). MSE needs no bound, and the
        evaluation scores the frames as they are."""
        b, t = z.shape[:2]
        return (self.background + self.decoder(z.flatten(0, 1)).view(b, t, *self.background.shape))

    def encode(self, frames: Tensor) -> Tensor:
        """Float frames (B, T, C, H, W) -> latents (B, T, Z)."""
        b, t = frames.shape[:2]
        return self.encoder(frames.flatten(0, 1)).view(b, t, -1)

    def roll(self, z: Tensor, actions: Tensor | None, steps: int) -> Tensor:
        """Latents of the L input frames (B, L, Z) and the actions after frames 1 .. L-1+steps
        (B, L-1+steps, A; None if unactuated) -> the predicted latents of frames L+1 .. L+steps (B, steps, Z)."""
        b, ell = z.shape[:2]
        state = (z.new_zeros(b, self.hidden), z.new_zeros(b, self.hidden))
        current, out = z[:, 0], []
        for t in range(ell - 1 + steps):
            inputs = current if actions is None else torch.cat([current, actions[:, t]], dim=1)  # (B, Z [+ A])
            state = self.cell(inputs, state)
            guess = self.head(state[0])  # (B, Z): the latent of the next frame, t+1 (from 0)
            if t >= ell - 1:
                out.append(guess)
            current = z[:, t + 1] if t + 1 < ell else guess  # teacher-forced on the inputs, then its own
        return torch.stack(out, dim=1)  # (B, steps, Z)

    def predict_frames(self, frames: Tensor, actions: Tensor | None, steps: int) -> tuple[Tensor, Tensor | None]:
        return self.render(self.roll(self.encode(frames), actions, steps)), None

    def forward(self, frames: Tensor, actions: Tensor, pred_frames: int | None = None) -> ModelOutput:
        cfg = self.config
        ell = cfg.input_frames
        x, t_pred, acts = window_inputs(cfg, frames, actions, pred_frames)  # x (B, L+T, C, H, W)
        z = self.encode(x if cfg.rec_frames == "all" else x[:, :ell])  # (B, L+T or L, Z)
        rec = self.render(z)  # (B, L+T or L, C, H, W)
        pred = self.render(self.roll(z[:, :ell], acts, t_pred))  # (B, T, C, H, W)
        loss, loss_pred, loss_rec = prediction_losses(cfg, x, pred, rec, self.training)
        return ModelOutput(loss, loss_pred, loss_rec, x, pred, rec, None, None)
