"""The coordinate-consistent decoder: learned object templates placed by inverse spatial transformers.

Each object n has a learned template: a content c^n in [0, 1]^(C, h, w) and a mask logit
m^n in R^(1, h, w). The latent coordinates of the object set a spatial transformer with the paper's
*inverse* parameters (its eq. inv_transf), so the rendered object lands exactly where the
coordinates say:

- cartesian systems (D = 2): coords (x, y) are pixel coordinates, x to the right and y downwards,
  with the image spanning [0, H] (pixel i covers [i, i + 1], its centre is at i + 0.5). The
  template's centre is drawn at (x, y). Moving the latent by (Δx, Δy) moves the object by
  exactly (Δx, Δy) pixels.
- angle systems (D = 1): the coordinate θ rotates the template about its centre, which is drawn
  at the fixed ``pivot``. Positive θ turns the object **counter-clockwise as displayed** (row
  index growing downwards), the convention of Gymnasium's ``Pendulum-v1``: a template pointing up
  at θ = 0 points left at θ = +π/2. Changing θ by Δθ rotates the object by exactly Δθ.

With a learnable per-object scale s (log-parameterised), a template pixel covers s image pixels.
The transformed masks and an untransformed background mask logit go through a softmax over the
N + 1 layers, and the image is

    image = m̃^bkg ⊙ c^bkg + Σ_n m̃^n ⊙ ĉ^n.

As in the paper's appendix, templates are not free tensors but the output of a small network with
a constant input of ones (one hidden layer of ``hidden`` tanh units, a linear output). The
background content and mask logit come from a second network of the same form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn

__all__ = ["DecoderConfig", "Decoder", "Templates", "RenderParts"]


@dataclass(frozen=True)
class DecoderConfig:
    """Configuration of :class:`Decoder`."""

    image_size: int
    """H = W, the side of the rendered image in pixels."""
    channels: int
    """C: 1 for grayscale, 3 for colour."""
    n_objects: int
    """N, the number of object templates."""
    coord_dim: int
    """D: 1 = angle about a fixed pivot, 2 = cartesian (x, y) in pixel units in [0, H]."""
    template_size: int | None = None
    """h = w, the side of each object template in template pixels; None means image_size."""
    hidden: int = 200
    """Hidden tanh units of the networks that generate the templates (paper: 200)."""
    pivot: tuple[float, float] | None = None
    """(x, y) pixel coordinates of the rotation centre for angle systems; None = image centre."""
    init_scale: float = 1.0
    """Initial scale s of every object (image pixels per template pixel; paper: 2 for balls)."""
    learn_scale: bool = True
    """Whether the per-object scale s is learned (in log space)."""

    def __post_init__(self) -> None:
        for name in ("image_size", "channels", "n_objects", "hidden"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"DecoderConfig.{name} must be an int >= 1, got {value!r}")
        if self.coord_dim not in (1, 2):
            raise ValueError(
                f"DecoderConfig.coord_dim must be 1 (angle) or 2 (x, y), got {self.coord_dim!r}"
            )
        if self.template_size is not None and (
            isinstance(self.template_size, bool)
            or not isinstance(self.template_size, int)
            or self.template_size < 1
        ):
            raise ValueError(
                f"DecoderConfig.template_size must be None or an int >= 1, got {self.template_size!r}"
            )
        if self.pivot is not None and len(self.pivot) != 2:
            raise ValueError(f"DecoderConfig.pivot must be None or (x, y), got {self.pivot!r}")
        if not (math.isfinite(self.init_scale) and self.init_scale > 0):
            raise ValueError(
                f"DecoderConfig.init_scale must be finite and > 0, got {self.init_scale!r}"
            )

    @property
    def resolved_template_size(self) -> int:
        """h: ``template_size``, or ``image_size`` when that is None."""
        return self.image_size if self.template_size is None else self.template_size

    @property
    def resolved_pivot(self) -> tuple[float, float]:
        """The pivot in pixel coordinates: ``pivot``, or the image centre when that is None."""
        if self.pivot is None:
            return (self.image_size / 2.0, self.image_size / 2.0)
        return (float(self.pivot[0]), float(self.pivot[1]))


class Templates(NamedTuple):
    """The untransformed templates (for the "learned templates" figure)."""

    contents: Tensor
    """Object contents in [0, 1], (N, C, h, h)."""
    mask_logits: Tensor
    """Object mask logits, (N, 1, h, h)."""
    background: Tensor
    """Background content in [0, 1], (C, H, H)."""
    background_mask_logit: Tensor
    """Background mask logit, (1, H, H)."""


class RenderParts(NamedTuple):
    """The layers of a rendering (for plots); ``...`` are the leading axes of the coordinates."""

    contents: Tensor
    """Transformed object contents ĉ^n, (..., N, C, H, W)."""
    masks: Tensor
    """Softmaxed masks m̃, objects first and background last, (..., N + 1, 1, H, W); sum to 1."""
    background: Tensor
    """Background content c^bkg (not transformed), (C, H, W)."""


class _TemplateGenerator(nn.Module):
    """Constant input of ones -> Linear -> tanh -> Linear: a learned tensor, reparameterised."""

    def __init__(self, hidden: int, out_features: int) -> None:
        super().__init__()
        self.hidden = nn.Linear(1, hidden)
        self.out = nn.Linear(hidden, out_features)

    def forward(self) -> Tensor:
        ones = self.out.weight.new_ones(1, 1)  # (1, 1), the constant input
        return self.out(torch.tanh(self.hidden(ones)))[0]  # (out_features,)

    @torch.no_grad()
    def set_output(self, values: Tensor) -> None:
        """Make :meth:`forward` return ``values`` exactly (output weights zeroed, bias = values)."""
        self.out.weight.zero_()
        self.out.bias.copy_(values.reshape(-1))


def _logit(x: Tensor) -> Tensor:
    """Inverse sigmoid of contents in [0, 1], clamped to the dtype's resolution."""
    eps = torch.finfo(x.dtype).eps
    return torch.logit(x.clamp(eps, 1 - eps))


class Decoder(nn.Module):
    """Render N objects at the given coordinates: (B, N, D) -> (B, C, H, W) in [0, 1].

    See the module docstring for the coordinate conventions. Leading axes are free: coordinates of
    shape (B, T, N, D) render to (B, T, C, H, W).
    """

    def __init__(self, config: DecoderConfig) -> None:
        super().__init__()
        self.config = config
        n, c = config.n_objects, config.channels
        h, size = config.resolved_template_size, config.image_size
        self._object_numel = n * (c + 1) * h * h
        self.object_generator = _TemplateGenerator(config.hidden, self._object_numel)
        self.background_generator = _TemplateGenerator(config.hidden, (c + 1) * size * size)
        self.log_scale = nn.Parameter(
            torch.full((n,), math.log(config.init_scale)), requires_grad=config.learn_scale
        )
        pivot = torch.tensor(config.resolved_pivot, dtype=torch.get_default_dtype())  # (2,), pixels
        self.register_buffer("pivot", pivot, persistent=False)

    @property
    def scale(self) -> Tensor:
        """Per-object scale s = exp(log_scale), (N,): image pixels per template pixel."""
        return self.log_scale.exp()

    # ------------------------------------------------------------------ templates
    def templates(self) -> Templates:
        """The untransformed object templates and the background."""
        cfg = self.config
        n, c, h, size = cfg.n_objects, cfg.channels, cfg.resolved_template_size, cfg.image_size
        obj = self.object_generator().view(n, c + 1, h, h)  # (N, C + 1, h, h)
        bkg = self.background_generator().view(c + 1, size, size)  # (C + 1, H, H)
        return Templates(
            contents=torch.sigmoid(obj[:, :c]),
            mask_logits=obj[:, c:],
            background=torch.sigmoid(bkg[:c]),
            background_mask_logit=bkg[c:],
        )

    def load_templates(
        self,
        contents: Tensor,
        mask_logits: Tensor,
        background: Tensor | None = None,
        background_mask_logit: Tensor | None = None,
    ) -> None:
        """Set the generators so that :meth:`templates` returns these tensors (up to clamping).

        For tests and hand-made renderers; the generators stay trainable. Contents are in [0, 1],
        shapes as in :class:`Templates`. A background left as None keeps its current value.
        """
        current = self.templates()
        expected = {
            "contents": (contents, current.contents.shape),
            "mask_logits": (mask_logits, current.mask_logits.shape),
        }
        background = current.background.detach() if background is None else background
        if background_mask_logit is None:
            background_mask_logit = current.background_mask_logit.detach()
        expected["background"] = (background, current.background.shape)
        expected["background_mask_logit"] = (background_mask_logit, current.background_mask_logit.shape)
        for name, (value, shape) in expected.items():
            if tuple(value.shape) != tuple(shape):
                raise ValueError(
                    f"load_templates: {name} must have shape {tuple(shape)}, got {tuple(value.shape)}"
                )
        dtype = self.object_generator.out.bias.dtype
        obj = torch.cat([_logit(contents.to(dtype)), mask_logits.to(dtype)], dim=1)  # (N, C + 1, h, h)
        bkg = torch.cat([_logit(background.to(dtype)), background_mask_logit.to(dtype)], dim=0)
        self.object_generator.set_output(obj)
        self.background_generator.set_output(bkg)

    @torch.no_grad()
    def init_background(self, background: Tensor) -> None:
        """Start the background content at ``background`` (C, H, W) in [0, 1]; its mask logit is kept.

        Only the background generator's output layer is set (weights zeroed, bias = the values), so
        the object templates start as before.
        """
        current = self.templates()
        if tuple(background.shape) != tuple(current.background.shape):
            raise ValueError(f"init_background: background must have shape {tuple(current.background.shape)}, "
                             f"got {tuple(background.shape)}")
        dtype = self.background_generator.out.bias.dtype
        bkg = torch.cat([_logit(background.to(dtype)), current.background_mask_logit.to(dtype)], dim=0)
        self.background_generator.set_output(bkg)

    # ------------------------------------------------------------------ rendering
    def _inverse_affine(self, coords: Tensor) -> Tensor:
        """The spatial transformer parameters ω for ``F.affine_grid``, (B, N, 2, 3).

        The forward map (the paper's eq. transf) takes a template point at offset u (template
        pixels, from the template centre) to image pixel X = t + s·R(θ)·u, with the
        counter-clockwise-as-displayed rotation R(θ) = [[cos θ, sin θ], [-sin θ, cos θ]] (y down).
        ``affine_grid`` needs the inverse, from output to source, in normalised coordinates
        (align_corners=False: pixel x of an image of side H is 2x/H - 1, and a template offset u
        is 2u/h). Hence source = A·(out - t_norm) with A = (H / (h·s))·R(θ)ᵀ, i.e.
        ω = [A | -A·t_norm], the paper's eq. inv_transf with the resolution ratio H/h.
        """
        cfg = self.config
        size, h = cfg.image_size, cfg.resolved_template_size
        batch = coords.shape[0]
        if cfg.coord_dim == 2:
            translation = coords  # (B, N, 2), pixels
            theta = coords.new_zeros(coords.shape[:-1])  # (B, N)
        else:
            translation = self.pivot.to(coords).expand(batch, cfg.n_objects, 2)  # (B, N, 2)
            theta = coords[..., 0]  # (B, N)
        t_norm = 2.0 * translation / size - 1.0  # (B, N, 2)
        cos, sin = torch.cos(theta), torch.sin(theta)  # (B, N)
        gain = size / (h * self.scale.to(coords))  # (N,)
        rot_t = torch.stack(
            [torch.stack([cos, -sin], dim=-1), torch.stack([sin, cos], dim=-1)], dim=-2
        )  # (B, N, 2, 2), R(θ)ᵀ
        a = gain[:, None, None] * rot_t  # (B, N, 2, 2)
        offset = -(a @ t_norm.unsqueeze(-1))  # (B, N, 2, 1)
        return torch.cat([a, offset], dim=-1)  # (B, N, 2, 3)

    def render_parts(self, coords: Tensor) -> RenderParts:
        """Transform every template to its coordinates and compute the softmaxed masks.

        Args:
            coords: (..., N, D) latent coordinates.
        """
        cfg = self.config
        n, d, c, size = cfg.n_objects, cfg.coord_dim, cfg.channels, cfg.image_size
        if coords.dim() < 2 or tuple(coords.shape[-2:]) != (n, d):
            raise ValueError(f"coords must have shape (..., N={n}, D={d}), got {tuple(coords.shape)}")
        lead = coords.shape[:-2]
        tpl = self.templates()
        coords = coords.reshape(-1, n, d).to(tpl.contents.dtype)  # (B, N, D)
        batch = coords.shape[0]

        omega = self._inverse_affine(coords).reshape(batch * n, 2, 3)  # (B·N, 2, 3)
        grid = F.affine_grid(omega, [batch * n, c, size, size], align_corners=False)  # (B·N, H, W, 2)

        h = cfg.resolved_template_size
        contents = tpl.contents.expand(batch, n, c, h, h).reshape(batch * n, c, h, h)
        # Contents use 'border' padding: outside the template the mask weight is zero anyway, and
        # at the template's edge this avoids blending the object's colour with black.
        hat_c = F.grid_sample(
            contents, grid, mode="bilinear", padding_mode="border", align_corners=False
        )
        hat_c = hat_c.view(batch, n, c, size, size)  # (B, N, C, H, W)

        # Masks: an object must be absent (logit -inf) outside its template. Sampling the logits
        # with zero padding would instead give logit 0 there, i.e. a faint copy of the object over
        # the whole image. So we sample the softmax numerator exp(m - max m) in [0, 1] with zero
        # padding (zero weight outside, linear coverage at the edge) and take its log back. The
        # per-object max is a constant shift that the softmax cancels, so it is detached. The
        # clamp at the dtype's smallest normal number keeps the log finite: outside, an object's
        # logit is its own peak minus ~87 (float32), far below any background logit a trained
        # decoder uses, and the gradient there is zero, not NaN.
        shift = tpl.mask_logits.detach().amax(dim=(1, 2, 3), keepdim=True)  # (N, 1, 1, 1)
        weight = torch.exp(tpl.mask_logits - shift)  # (N, 1, h, h), in (0, 1]
        weight = weight.expand(batch, n, 1, h, h).reshape(batch * n, 1, h, h)
        hat_w = F.grid_sample(weight, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
        tiny = torch.finfo(hat_w.dtype).tiny
        hat_m = hat_w.clamp_min(tiny).log().view(batch, n, 1, size, size) + shift.view(1, n, 1, 1, 1)

        bkg_m = tpl.background_mask_logit.expand(batch, 1, 1, size, size)  # (B, 1, 1, H, W)
        masks = torch.softmax(torch.cat([hat_m, bkg_m], dim=1), dim=1)  # (B, N + 1, 1, H, W)
        return RenderParts(
            contents=hat_c.reshape(*lead, n, c, size, size),
            masks=masks.reshape(*lead, n + 1, 1, size, size),
            background=tpl.background,
        )

    def forward(self, coords: Tensor) -> Tensor:
        """Render the image for coordinates (..., N, D); returns (..., C, H, W) in [0, 1]."""
        parts = self.render_parts(coords)
        objects = (parts.masks[..., :-1, :, :, :] * parts.contents).sum(dim=-4)  # (..., C, H, W)
        return objects + parts.masks[..., -1, :, :, :] * parts.background  # (..., C, H, W)
