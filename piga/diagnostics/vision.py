"""Camera-side candidates of the gap: blur, a shifted camera, exposure, sensor noise, dropped and delayed frames.

The dynamics candidates (:mod:`piga.diagnostics.fit`) explain the encoded angles. A camera effect
instead changes how a state looks, so it is fitted on the rendering side, by analysis by synthesis
with the identified decoder D:

- **Angle table.** For a camera ψ the decoder renders K angles once: R_j = V_ψ(D(θ_j)). Every
  frame x is then matched to the table, θ*(x) = argmin_j ||x - R_j||², refined by a parabola
  through the neighbouring distances (the grid is 0.5°). This is an exact search over the whole
  circle, one matrix product for all frames; no gradient descent that could stop in a local
  minimum when noise has made the encoder's angle useless.
- **Blur σ and shift (dx, dy)** (:class:`Camera`) are fitted by minimising the mean matched
  residual min_j ||x - V_ψ(D(θ_j))||² over a sample of the fit split (coordinate descent with
  bounded scalar searches), and scored on a held-out sample. V_ψ blurs with a Gaussian kernel
  (``cv2.GaussianBlur``'s, reflected border) and then translates by bilinear interpolation (border
  replicated), the equations of :mod:`envs.effects`; both act on the rows and the columns apart, as one
  matrix product per axis (:func:`blur_matrix`, :func:`warp_matrix`).
- **Zoom z** (the pendulum drawn at another size: a camera nearer or farther, or a pendulum of another length)
  scales the picture about the image centre in the same warp, before the shift. It is fitted like
  the shift, and tried only where the pendulum's drawn size (:func:`drawn_scale`) differs from the renders': a
  blur, which a zoom out partly mimics, would otherwise meet it on every blurred recording.
- **Exposure k** (a darker or brighter picture: the exposure, the lighting) multiplies every level,
  clipped at white, after the blur and the shift (:func:`fit_exposure`). Where the background shows
  it (a darker picture, or a background that is not white) it is fitted first, and the blur and the
  shift on top of it; a brighter picture on a white background shows on the pendulum alone, like a
  blur, and competes with the blur and the shift instead: the encoder, trained on one exposure, reads a picture darkened by
  15% as angles 110° off (median), while matching through the fitted exposure reads them within 0.1°.
- **Noise s** (gray levels) is fitted on the pixels that the pendulum never reaches (the decoder's
  renders over the whole circle leave them at the background): their temporal spread around the
  per-pixel median, by maximum likelihood of a rounded Gaussian censored at 0 and 255 (a white
  background clips half of the noise). Where the actions are known and every frame reads more than the
  frames after the smallest fifth of them (:func:`calm_noise`, :data:`ARROW_NOISE_FACTOR`), only those are
  read: what is drawn with the action (Gymnasium's torque arrow, larger at a larger actuation gain) is not
  in them, and sensor noise is in every frame. A clean camera
  gives s = 0 there exactly. It is named only where the pixels' changes do not persist from frame to
  frame (:func:`noise_correlation`): a moving shadow or a change of the lighting spreads them too.
- **Repeated frames** (dropped frames, a camera that starts late) are detected by
  :mod:`piga.diagnostics.repeats`; the camera stage reports what they say.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import Tensor

from piga.diagnostics.repeats import RepeatConfig, leading_repeats, repeated_frames
from piga.io.choices import check_ranges, check_types
from piga.world.model import PhysicsModel, frames_to_float

if TYPE_CHECKING:
    from piga.diagnostics.partial import PartialCamera

#: Angles in the matching table (0.5° apart).
TABLE_SIZE = 720
#: Bounds of the camera fit: blur σ in px, shift in px.
MAX_BLUR, MAX_SHIFT = 4.0, 5.0
#: Bounds of the exposure factor's fit.
MIN_EXPOSURE, MAX_EXPOSURE = 0.4, 2.5
#: Bounds of the zoom's fit (factor on the drawn size).
MIN_ZOOM, MAX_ZOOM = 0.7, 1.4
#: The unit of a named zoom.
ZOOM_UNIT = "factor on the pendulum's drawn size (about the image centre)"


@dataclass(frozen=True)
class Camera:
    """A camera model V_ψ applied to rendered frames: Gaussian blur, then a zoom about the image centre and a
    translation, then the exposure."""

    blur: float = 0.0
    """σ of the Gaussian blur (px); 0: none."""
    dx: float = 0.0
    """Shift to the right (px): x'[r, c] = x[r, c - dx]."""
    dy: float = 0.0
    """Shift down (px): x'[r, c] = x[r - dy, c]."""
    exposure: float = 1.0
    """Factor on every level, clipped at white (exposure, lighting): x' = min(k·x, 1); 1: none."""
    zoom: float = 1.0
    """Factor on the drawn size about the image centre (a camera nearer, > 1, or farther, < 1, along its axis; the
    dm_control camera's principal point and the Gymnasium pendulum's hinge are the centre): x'(p) = x(c + (p - c)/z),
    before the shift; 1: none."""

    def material(self, config: CameraConfig) -> set[str]:
        """The effects of this camera that are big enough to name: "blur", "shift", "exposure" and/or "zoom"."""
        return ({"blur"} if self.blur > config.min_blur else set()) | \
            ({"shift"} if max(abs(self.dx), abs(self.dy)) > config.min_shift else set()) | \
            ({"exposure"} if 255 * abs(self.exposure - 1) > config.min_exposure else set()) | \
            ({"zoom"} if abs(self.zoom - 1) > config.min_zoom else set())

    def describe(self, digits: int = 3) -> str:
        """Its parts that differ from no camera, "exposure 1.04" or "dx 1, dy 1", to ``digits`` significant digits."""
        return ", ".join(f"{k} {v:.{digits}g}" for k, v in self.__dict__.items() if v != getattr(Camera(), k))

    def apply(self, frames: Tensor) -> Tensor:
        """(K, C, H, W) frames in [0, 1] -> the same frames as this camera sees them."""
        x = frames
        h, w = x.shape[-2:]
        rows, columns = torch.eye(h, dtype=x.dtype), torch.eye(w, dtype=x.dtype)  # each a linear map of one axis
        if self.blur > 1e-3:  # cv2.GaussianBlur's, reflected border
            rows, columns = blur_matrix(h, self.blur, x.dtype), blur_matrix(w, self.blur, x.dtype)
        if abs(self.dx) > 1e-6 or abs(self.dy) > 1e-6 or abs(self.zoom - 1) > 1e-6:  # after the blur
            rows = warp_matrix(h, self.zoom, self.dy).to(x.dtype) @ rows
            columns = warp_matrix(w, self.zoom, self.dx).to(x.dtype) @ columns
        if self.blur > 1e-3 or abs(self.dx) > 1e-6 or abs(self.dy) > 1e-6 or abs(self.zoom - 1) > 1e-6:
            x = rows @ (x @ columns.T)
        if abs(self.exposure - 1) > 1e-6:
            x = (x * self.exposure).clamp(max=1.0)
        return x


def blur_matrix(n: int, sigma: float, dtype: torch.dtype = torch.float32) -> Tensor:
    """(n, n) matrix B of a 1-D Gaussian blur of σ ``sigma``: B @ v blurs a length-n signal v as cv2.GaussianBlur does
    for float images (kernel radius ceil(4σ), at most n - 1, normalised; border BORDER_REFLECT_101, v[-i] = v[i]).

    Blurring (K, C, H, W) frames as two matrix products (rows, then columns) is ~20x faster than as two depthwise
    convolutions (360 gray renders of 64x64 on one CPU thread: 10-12 ms against 210-260 ms)."""
    r = max(1, min(int(math.ceil(4 * sigma)), n - 1))
    k = torch.exp(-0.5 * (torch.arange(-r, r + 1, dtype=dtype) / sigma) ** 2)
    k = k / k.sum()
    source = (torch.arange(n)[:, None] + torch.arange(-r, r + 1)[None, :]).abs()  # (n, 2r + 1), reflected below 0
    source = torch.where(source > n - 1, 2 * (n - 1) - source, source)  # and above n - 1
    rows = torch.arange(n)[:, None].expand_as(source)
    return torch.zeros(n, n, dtype=dtype).index_put_((rows, source), k.expand_as(source), accumulate=True)


def warp_matrix(n: int, zoom: float, shift: float) -> Tensor:
    """(n, n) float64 matrix A of a zoom about the centre then a shift along one axis: A @ v samples a length-n signal
    v at (p - shift - c)/zoom + c for each pixel p (c = (n - 1)/2), linearly between its pixels, the coordinate held
    within [0, n - 1] (the edge pixel repeats): one axis of ``F.affine_grid`` + ``F.grid_sample`` (bilinear, border,
    align_corners False) with a diagonal affine map, which is separable. A blur and a shift as one matrix per axis:
    9 ms against 250 ms for the convolutions and the 2-D warp (360 gray renders of 64x64, one CPU thread), 33 ms
    against 510 ms in RGB."""
    p = torch.arange(n, dtype=torch.float64)
    c = (n - 1) / 2
    source = ((p - shift - c) / zoom + c).clamp(0, n - 1)  # (n,)
    low = source.floor().clamp(max=n - 2).long() if n > 1 else torch.zeros(n, dtype=torch.long)
    frac = source - low
    a = torch.zeros(n, n, dtype=torch.float64)
    a[torch.arange(n), low] = 1 - frac
    if n > 1:
        a[torch.arange(n), low + 1] += frac
    return a


@dataclass(frozen=True)
class AngleTable:
    """Renders of K angles through a camera, flattened for matching."""

    angles: Tensor
    """(K,) model-convention angles, uniformly spaced over [-π, π)."""
    renders: Tensor
    """(K, P) rendered frames, P = C·H·W, in [0, 1]."""


@torch.no_grad()
def decoder_renders(model: PhysicsModel, size: int = TABLE_SIZE) -> tuple[Tensor, Tensor]:
    """The angles (K,) of a table of ``size`` and the decoder's renders of them (K, C, H, W), before any camera:
    computed once where many cameras are tried on the same angles (the camera fits)."""
    angles = torch.arange(size, dtype=torch.float32) * (2 * math.pi / size) - math.pi
    return angles, model.decoder(angles[:, None, None])


@torch.no_grad()
def angle_table(model: PhysicsModel, camera: Camera = Camera(), size: int = TABLE_SIZE,
                renders: tuple[Tensor, Tensor] | None = None) -> AngleTable:
    """The decoder's renders of ``size`` angles (or the given :func:`decoder_renders`), seen through ``camera``."""
    angles, frames = decoder_renders(model, size) if renders is None else renders  # (K,), (K, C, H, W)
    return AngleTable(angles, camera.apply(frames).flatten(1))


@torch.no_grad()
def match(table: AngleTable, x: Tensor, batch: int = 2048) -> tuple[Tensor, Tensor]:
    """Analysis by synthesis: each frame's best angle in the table, refined by a parabola.

    Args:
        x: (M, P) frames in [0, 1], flattened like ``table.renders``.
    Returns:
        θ* (M,) in [-π, π) and the matched residual (M,) mean squared pixel error.
    """
    k = table.renders.shape[0]
    r2 = (table.renders**2).sum(1)  # (K,)
    thetas, errors = [], []
    for start in range(0, x.shape[0], batch):
        xb = x[start : start + batch]
        d = _distances(table, xb, r2)  # (m, K)
        j = d.argmin(1)  # (m,)
        d0 = d.gather(1, j[:, None])[:, 0]
        dm = d.gather(1, ((j - 1) % k)[:, None])[:, 0]
        dp = d.gather(1, ((j + 1) % k)[:, None])[:, 0]
        curv = dm - 2 * d0 + dp
        delta = torch.where(curv > 0, 0.5 * (dm - dp) / curv.clamp_min(1e-12), torch.zeros_like(d0)).clamp(-0.5, 0.5)
        step = 2 * math.pi / k
        thetas.append(torch.remainder(table.angles[j] + delta * step + math.pi, 2 * math.pi) - math.pi)
        errors.append((d0 - 0.25 * (dm - dp) * delta).clamp_min(0) / x.shape[1])
    return torch.cat(thetas), torch.cat(errors)


def _distances(table: AngleTable, x: Tensor, r2: Tensor) -> Tensor:
    """(m, K) squared distances of frames ``x`` (m, P) to the table's renders, whose squared norms are ``r2`` (K,)."""
    return (x**2).sum(1, keepdim=True) - 2 * x @ table.renders.T + r2


def matched_error(model: PhysicsModel, camera: Camera, x: Tensor, size: int = TABLE_SIZE // 2,
                  renders: tuple[Tensor, Tensor] | None = None) -> float:
    """Mean matched residual (pixel MSE) of frames ``x`` (M, P) under ``camera`` (``renders``: the
    :func:`decoder_renders` of ``size`` angles, when already computed)."""
    return float(match(angle_table(model, camera, size, renders), x)[1].mean())


def fit_camera(model: PhysicsModel, x: Tensor, blur: bool = True, shift: bool = True, rounds: int = 2,
               renders: tuple[Tensor, Tensor] | None = None, base: Camera = Camera(), zoom: bool = False,
               brighter: bool = False) -> Camera:
    """The camera (zoom, blur σ and/or shift dx, dy; with ``brighter``, an exposure of at least 1 too) that minimises
    the matched residual of frames ``x`` (M, P); the parameters not fitted keep the values of ``base`` (its exposure,
    :func:`fit_exposure`).

    Coordinate descent: bounded scalar searches on each parameter in turn, ``rounds`` times. ``renders``: the
    :func:`decoder_renders` of ``TABLE_SIZE // 2`` angles, when already computed.
    """
    from scipy.optimize import minimize_scalar

    cam = dict(base.__dict__)
    names = (["zoom"] if zoom else []) + (["dx", "dy"] if shift else []) + (["blur"] if blur else []) \
        + (["exposure"] if brighter else [])
    if not names:
        return base
    renders = decoder_renders(model, TABLE_SIZE // 2) if renders is None else renders  # the same for every camera tried
    bounds = {"blur": (0.0, MAX_BLUR), "zoom": (MIN_ZOOM, MAX_ZOOM), "dx": (-MAX_SHIFT, MAX_SHIFT),
              "dy": (-MAX_SHIFT, MAX_SHIFT), "exposure": (1.0, MAX_EXPOSURE)}
    for _ in range(rounds):
        for name in names:
            lo, hi = bounds[name]

            def objective(v: float, name: str = name) -> float:
                return matched_error(model, Camera(**{**cam, name: float(v)}), x, renders=renders)

            # a coarse scan first: the residual of a shift has side minima a pixel apart
            grid = np.linspace(lo, hi, {"blur": 9, "zoom": 15, "exposure": 16}.get(name, 11))
            best = grid[int(np.argmin([objective(v) for v in grid]))]
            step = grid[1] - grid[0]
            res = minimize_scalar(objective, bounds=(max(lo, best - step), min(hi, best + step)), method="bounded",
                                  options={"xatol": 0.01})
            cam[name] = float(res.x) if res.fun <= objective(best) else float(best)
    return Camera(**cam)


def background_exposure(frames: np.ndarray, lit: np.ndarray, background: np.ndarray) -> float | None:
    """The median, over the pixels ``lit`` (H, W; :func:`lit_pixels`), of each pixel's median over uint8 frames (M, H,
    W) divided by the decoder's ``background`` (H, W) there: the frames' exposure as the background shows it (None
    where no pixel is lit). :func:`fit_exposure` says why medians."""
    if not lit.any():
        return None
    levels = np.median(frames[:, lit], axis=0) / 255.0  # (S,)
    return float(np.median(levels / background[lit]))


def lit_pixels(still: np.ndarray, renders: tuple[Tensor, Tensor]) -> tuple[np.ndarray, np.ndarray]:
    """The decoder's background (H, W, in [0, 1]; :func:`empty_scene`) and its pixels ``still`` (H, W) that can show an
    exposure: not black, since a black background stays black under any exposure."""
    background = empty_scene(renders)[0].numpy()
    return still & (background > 0.2), background


def fit_exposure(model: PhysicsModel, frames: np.ndarray, still: np.ndarray, x: Tensor,
                 renders: tuple[Tensor, Tensor], min_change: float) -> tuple[Camera, bool]:
    """The exposure k of uint8 frames (M, H, W) (first channel), flattened in ``x`` (M, P), and whether the
    background showed it.

    Where the pixels that the pendulum never reaches (``still``, (H, W)) show it (not black), k is the median over them
    of each pixel's median over the frames divided by the decoder's background there: medians, because a least-squares
    fit is biased by sensor noise on a white background, which the clip at 255 censors from above (measured: noise
    of 20 gray levels fitted as k = 0.972, a "darker picture" of 7 gray levels), and a moving shadow covers a pixel
    in a few frames only. A white background that stays white (k within ``min_change`` gray levels of 1 there) does
    not show a brighter picture, which only lightens the pendulum: k >= 1 is then fitted by the matched residual,
    where the noise's censoring can only pull k below 1, but a blur, which lightens the rod's core too, can push it
    above (measured: blur 1.85 px fitted as k = 1.48): such a k competes with the blur and the shift.
    """
    from scipy.optimize import minimize_scalar

    lit, background = lit_pixels(still, renders)
    k = background_exposure(frames, lit, background)
    if k is not None:
        if 255 * abs(k - 1) > min_change or (background[lit] < 0.9).mean() > 0.5:  # a change, or a background that shows one
            return Camera(exposure=float(np.clip(k, MIN_EXPOSURE, MAX_EXPOSURE))), True
        lo = 1.0
    else:
        lo = MIN_EXPOSURE

    def objective(v: float) -> float:
        return matched_error(model, Camera(exposure=float(v)), x, renders=renders)

    grid = np.linspace(lo, MAX_EXPOSURE, 16)
    best = grid[int(np.argmin([objective(v) for v in grid]))]
    step = grid[1] - grid[0]
    res = minimize_scalar(objective, bounds=(max(lo, best - step), min(MAX_EXPOSURE, best + step)), method="bounded",
                          options={"xatol": 1e-3})
    return Camera(exposure=float(res.x) if res.fun <= objective(best) else float(best)), False


@torch.no_grad()
def core_brightening(model: PhysicsModel, x: Tensor, renders: tuple[Tensor, Tensor], dark: float = 0.5) -> float:
    """The median, over the pixels darker than ``dark`` in each frame's matched render (the pendulum's own, no
    camera), of the frames ``x`` (M, P) over that render: how much brighter the pendulum is than the decoder draws
    it. An exposure k brightens it by k; a change elsewhere in the picture (a missing torque arrow, which leaves
    faint pixels of the decoder's white) does not."""
    ratios = []
    for _, xb, r in _nearest_renders(model, x, renders):
        core = r < dark
        ratios.append(xb[core] / r[core].clamp_min(1e-6))
    values = torch.cat(ratios)
    return float(values.median()) if len(values) else 1.0


def rod_shows_exposure(read: float, fitted: float, config: CameraConfig) -> bool:
    """A brighter picture on white, fitted at ``fitted`` and read on the rod through the rest of the camera at ``read``
    (:func:`core_exposure`), is named: the rod brightens by more than ``min_exposure`` gray levels and by its share
    (``min_core_share``) of the fit's. A recording without the torque arrow, blurred 0.8 px, fitted 1.032 with the blur
    on the arrow's faint pixels and read "exposure 1.012" on its rod (without the blur, the same share refused it
    before the blur was fitted: :func:`core_brightening`); a real exposure of 1.3 reads 1.31."""
    return 255 * abs(read - 1) > config.min_exposure and core_shows_share(read, fitted, config)


def core_shows_share(read: float, fitted: float, config: CameraConfig) -> bool:
    """The pendulum's dark pixels, brightened by ``read``, show ``min_core_share`` of a brighter picture fitted at
    ``fitted``."""
    return read - 1 >= config.min_core_share * (fitted - 1)


def _nearest_renders(model: PhysicsModel, x: Tensor, renders: tuple[Tensor, Tensor], camera: Camera = Camera(),
                     batch: int = 2048) -> Iterator[tuple[int, Tensor, Tensor]]:
    """``(start, frames (m, P), their nearest renders (m, P) through camera)`` for the frames ``x`` (M, P), in batches."""
    table = angle_table(model, camera, renders=renders)
    r2 = (table.renders**2).sum(1)  # (K,)
    for start in range(0, len(x), batch):
        xb = x[start : start + batch]  # (m, P)
        yield start, xb, table.renders[_distances(table, xb, r2).argmin(1)]


@torch.no_grad()
def frame_core_ratios(model: PhysicsModel, x: Tensor, renders: tuple[Tensor, Tensor], dark: float = 0.5,
                      camera: Camera = Camera()) -> np.ndarray:
    """(M,) how much brighter each frame ``x`` (M, P) is than its matched render through ``camera`` on the pixels
    darker than ``dark`` in that render: the 20%-trimmed mean of their ratios (1 for a frame whose render has none).
    Trimmed, not the median: the median of ratios of whole gray levels is itself one of a few levels (a rod drawn at
    51 and brightened 1.1 read 56/51 = 1.098 in every frame, its interval of zero width)."""
    from scipy.stats import trim_mean

    out = np.ones(len(x))
    for start, xb, r in _nearest_renders(model, x, renders, camera):
        core = (r < dark).numpy()
        ratio = (xb / r.clamp_min(1e-6)).double().numpy()
        for i in np.flatnonzero(core.any(1)):
            out[start + i] = trim_mean(ratio[i, core[i]], 0.2)
    return out


def core_exposure(model: PhysicsModel, x: Tensor, clusters: np.ndarray, renders: tuple[Tensor, Tensor],
                  reference: str | None, count: int, seed: int, camera: Camera = Camera(),
                  boots: int = 400) -> tuple[float, list[float]]:
    """A brighter picture on a white background, read where it shows: how much brighter the pendulum's own dark pixels
    are than the decoder draws them through ``camera``'s blur, shift and zoom (a blur lightens the rod's core too)
    (:func:`frame_core_ratios`, median over the frames ``x`` (M, P)), relative to the
    same on ``count`` frames of the model's own training file ``reference`` (1 where it is gone or unreadable), with a
    95% interval from resampling the sequences ``clusters`` (M,) (the reference's own spread is left out).

    The matched residual, which the exposure candidate is fitted on, reads it low: frames brightened by 1.07 fitted
    k = 1.037 (the rod's soft edge, where the decoder's render is not the frame's, outweighs its core), and their core
    read 1.079 against the training file's 1.0094, 1.069; brightened by 1.05 and 1.1, 1.051 and 1.096."""
    ratios = frame_core_ratios(model, x, renders, camera=replace(camera, exposure=1.0))
    frames = reference_frames(reference, count, seed)
    own = 1.0
    if frames is not None and frames.shape[1:3] == (model.config.image_size,) * 2:
        own = float(np.median(frame_core_ratios(model, _flat(frames, model.config.channels), renders)))
    own = own if own > 0 else 1.0
    groups = [ratios[clusters == c] for c in np.unique(clusters)]
    rng = np.random.default_rng(seed)
    draws = [np.median(np.concatenate([groups[i] for i in rng.integers(len(groups), size=len(groups))]))
             for _ in range(boots)]
    lo, hi = np.percentile(draws, [2.5, 97.5])
    return float(np.median(ratios)) / own, [float(lo) / own, float(hi) / own]


@torch.no_grad()
def static_pixels(model: PhysicsModel, margin: int = 4, tolerance: float = 8 / 255, camera: Camera = Camera()) -> np.ndarray:
    """(H, W) bool: pixels that the decoder leaves at its background for every angle, ``margin`` px away, seen
    through ``camera`` (a shift of 4.9 px moved the pendulum past the margin onto pixels whose changes read "noise
    8.34"; a blur spreads it).

    "At its background" is within ``tolerance`` (8 gray levels; the pendulum is about 200 from the
    background). A decoder leaks a few gray levels of the pendulum's template across the image (measured:
    up to 2 on two default models, whose pixels within 0.5 gray levels, once eroded by the margin,
    left none at all, so that noise of 18 gray levels went unmeasured); with 8, the eroded set is
    2600-2700 of the 4096 pixels on every default model, and clean files still give a noise of 0.
    """
    import cv2

    table = angle_table(model, camera, 180)
    cfg = model.config
    frames = table.renders.view(-1, cfg.channels, cfg.image_size, cfg.image_size)
    spread = (frames - frames.median(0).values).abs().amax(dim=(0, 1)).numpy()  # (H, W)
    still = (spread < tolerance).astype(np.uint8)
    if margin > 0:
        still = cv2.erode(still, np.ones((2 * margin + 1, 2 * margin + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    return still.astype(bool)


def action_fifths(actions: np.ndarray, stale: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """(N, T - 1) masks of the frames from the second on that show the smallest and the largest fifth of the (N, T)
    actions (frame t + 1 after u_t, which Gymnasium draws as its torque arrow); None where the actions do not vary.

    A camera whose first k frames repeat the first one (``stale`` (N, T), :func:`leading_repeats`: a camera delay of
    k frames) shows u_t's arrow in frame t + 1 + k: Gymnasium at an actuation gain of 3 with a camera delay of 2 read
    "noise 61.2" from the arrows of the frames it took for calm."""
    u = np.abs(actions[:, :-1])
    if u.size == 0 or np.ptp(u) == 0:
        return None
    lead = 0 if stale is None else min(leading_repeats(stale), u.shape[1])
    shown = np.concatenate([np.zeros((len(u), lead)), u[:, :u.shape[1] - lead]], axis=1)  # (N, T - 1) the shown u
    early = np.arange(u.shape[1]) < lead  # the repeats of the first frame show no action
    return (shown <= np.quantile(u, 0.2)) & ~early, (shown >= np.quantile(u, 0.8)) & ~early


def calm_frames(actions: np.ndarray, stale: np.ndarray | None = None) -> np.ndarray | None:
    """(N, T - 1) mask of the frames from the second on that follow the smallest fifth of the (N, T) ``actions``
    (:func:`action_fifths`) and are no repeat of the frame before (``stale`` (N, T): a dropped frame shows the frame
    before it, drawn after its own action: Gymnasium at an actuation gain of 3.5 with 10% of the frames dropped read
    "noise 84.2" from the torque arrows they repeated); None where the actions do not vary."""
    fifths = action_fifths(actions, stale)
    if fifths is None:
        return None
    return fifths[0] if stale is None else fifths[0] & ~stale[:, 1:]


def calm_noise(frames: np.ndarray, seqs: np.ndarray, times: np.ndarray, actions: np.ndarray,
               still: np.ndarray, stale: np.ndarray | None = None) -> tuple[float, list[float] | None] | None:
    """:func:`noise_level` (with its interval) of the uint8 ``frames`` (M, H, W) of sequences ``seqs`` (M,) at frame
    indices ``times`` (M,) that follow the smallest fifth of the recording's (N, T) ``actions``
    (:func:`action_fifths`), on the pixels ``still`` (H, W); None where fewer than 20 of them do, or the actions do not
    vary. Sensor noise is in every frame; a change drawn with the action is not in these."""
    calm = _calm(actions, seqs, times, stale)
    if calm is None:
        return None
    noise, interval = noise_level(frames[calm], still, interval=True)
    return float(noise), interval


def noise_level(frames: np.ndarray, still: np.ndarray, interval: bool = False) -> float | tuple[float, list[float] | None]:
    """Sensor noise s (gray levels) from uint8 frames (M, H, W) on the pixels ``still`` (H, W).

    Maximum likelihood of y = clip(round(μ + s·ε), 0, 255), ε ~ N(0, 1), with μ each pixel's
    temporal median. Returns 0 when the still pixels never change (a clean camera). With
    ``interval``, also a 95% interval from the observed information in log s (None for s = 0).
    """
    from scipy.optimize import minimize_scalar
    from scipy.stats import norm

    y = frames[:, still].reshape(len(frames), -1).astype(np.int64)  # (M, S)
    if y.size == 0:
        return (float("nan"), None) if interval else float("nan")
    mu = np.sort(y, axis=0)[len(y) // 2]  # (S,) the (upper) median, an integer level
    if (y == mu).all():
        return (0.0, None) if interval else 0.0
    # the likelihood depends only on (μ, y) pairs: count them
    pairs, counts = np.unique(np.broadcast_to(mu, y.shape).ravel() * 512 + y.ravel(), return_counts=True)
    mus, ys = pairs // 512, pairs % 512

    def nll(log_s: float) -> float:
        s = math.exp(log_s)
        upper = np.where(ys >= 255, np.inf, (ys + 0.5 - mus) / s)
        lower = np.where(ys <= 0, -np.inf, (ys - 0.5 - mus) / s)
        p = np.clip(norm.cdf(upper) - norm.cdf(lower), 1e-300, 1.0)
        return float(-(counts * np.log(p)).sum())

    res = minimize_scalar(nll, bounds=(math.log(0.05), math.log(128.0)), method="bounded")
    s = math.exp(res.x) if math.exp(res.x) > 0.06 else 0.0
    if not interval:
        return s
    h = 0.01
    info = (nll(res.x + h) - 2 * nll(res.x) + nll(res.x - h)) / h**2
    ci = [s * math.exp(-1.96 / math.sqrt(info)), s * math.exp(1.96 / math.sqrt(info))] if s > 0 and info > 0 else None
    return s, ci


def noise_correlation(frames: np.ndarray, still: np.ndarray, seqs: np.ndarray) -> float:
    """Correlation of the pixels ``still`` (H, W) between successive frames of the same sequence, among uint8 frames
    (M, H, W) in the order of their sequences ``seqs`` (M,): each pixel's deviation from its own mean over the frames.

    Sensor noise is drawn anew for every frame, so its deviations are uncorrelated between any two frames, successive
    or not (measured: |r| <= 0.01 for planted noise of 4 to 20 gray levels); a change of the picture (a moving
    shadow, a change of the lighting) persists from one frame to the next. NaN where they never change or no two
    frames share a sequence.
    """
    y = frames[:, still].reshape(len(frames), -1).astype(np.float64)  # (M, S)
    d = y - y.mean(0)
    same = seqs[1:] == seqs[:-1]  # (M - 1,) successive frames of one sequence
    a, b = d[:-1][same], d[1:][same]
    den = math.sqrt(float((a**2).sum()) * float((b**2).sum()))
    return float((a * b).sum()) / den if den > 0 else float("nan")


@dataclass(frozen=True)
class CameraConfig:
    """How the camera stage decides."""

    fit_frames: int = 1000
    """Frames of the fit split that the camera is fitted on."""
    held_frames: int = 500
    """Held-out frames it is scored on."""
    min_drop: float = 0.1
    """Relative drop of the held-out matched residual that a blur or a shift needs (measured on clean
    data: 0%; 23-98% for blur 1-2 px and shifts of 1.5-2 px)."""
    min_blur: float = 0.3
    """Smallest blur σ (px) that is named."""
    min_shift: float = 0.3
    """Smallest shift (px, either axis) that is named."""
    min_exposure: float = 3.0
    """Smallest change of white by the exposure (gray levels, 255·|k - 1|) that is named."""
    min_zoom: float = 0.03
    """Smallest change of the drawn size by a zoom (|z - 1|) that is named (measured: fitted on clean Gymnasium and
    dm_control frames, z = 1.000; on the 42 recordings of the blind benchmark without a planted blur or shift, within
    0.0075 of 1, at held-out drops under 0.1%)."""
    zoom_scale: float = 0.03
    """Smallest relative difference of the pendulum's drawn size (:func:`drawn_scale`, through no camera but an
    exposure fitted first) from the decoder's renders at which a zoom is fitted and tried (measured without a camera:
    clean Gymnasium frames x0.986, dm_control x1.003; the blind benchmark's 42 recordings x0.976 to x0.989 where no
    shift is planted, among them blurs of 1.8 to 2.2 px, on which a zoom alone fitted 0.83 to 0.90 at held-out drops
    of 19 to 26%, and x0.93 to x1.13 with shifts of 0.8 to 3 px, zoom drops 4 to 9%; Gymnasium frames zoomed x0.9,
    x1.1, x1.2 read x0.88, x1.09, x1.19, dm_control at camera distance 1.1 x0.91; a dm_control pendulum of length
    0.45, x0.91 about its hinge, which is not the image centre, fitted a zoom of 0.988 at a 9% drop, not named)."""
    min_noise: float = 1.0
    """Smallest sensor noise (gray levels) that is named (a clean camera gives 0)."""
    min_core_share: float = 0.5
    """Share of a brighter picture's k - 1 that the pendulum's own dark pixels must show (:func:`core_brightening`)
    for it to be named where the white background cannot show it: a real exposure brightens them by k (measured: k =
    1.3 showed 1.31), while a recording without the torque arrow that the training frames had fitted k = 1.046 on the
    arrow's faint pixels, its pendulum brightened by 1.013."""
    max_missing: float = 0.05
    """Largest fraction of held-out frames without the pendulum in view (:func:`empty_frames`) that is diagnosed:
    beyond it the recording is refused (a file whose every second half of a sequence was blank read "blur 1.68 px";
    clean files give 0)."""
    blurs_seen: tuple[float, ...] = (1.0, 2.0, 3.0, MAX_BLUR)
    """Blurs (px) through which frames the accepted camera shows no pendulum in (:attr:`CameraFindings.missing`) are
    looked at again: a pendulum seen through one of them is in view, through a camera that differs between parts of
    the recording (measured: a blur of 2.5 px from frame 8 on, read with no camera, showed no pendulum in 64% of the
    held-out frames and 0% through these; a blank second half of every sequence stays blank through any blur)."""
    min_contrast: float = 0.1
    """Smallest share of the pendulum's contrast with the empty scene (the mean squared difference of the decoder's
    renders from it, :func:`pendulum_contrast`) that a camera must leave for frames to show the pendulum through it:
    under it the camera hides the pendulum, and the frames it matches are empty (measured on the pixel pendulum: blur
    2.5 and 4 px leave 32% and 18%, exposure 0.8 and 1.25 64% and 67%, a shift all of it; a blank second half of every
    sequence was read "exposure 2.29 from frame 12 on", which leaves 4%)."""
    max_noise_correlation: float = 0.5
    """Largest correlation of the still pixels between successive frames (:func:`noise_correlation`) with which
    their spread is named sensor noise: above it, more than half of their changes persist from frame to frame, a
    change of the picture, not noise (measured: |r| <= 0.01 for planted noise of 4 to 20 gray levels on the pixel
    and dm_control pendulums; 0.86 to 0.89 for dm_control with shadows on, whose spread read "noise 2.5")."""
    min_split_share: float = 0.15
    """Share of the groups of fit frames (the sequences, or the frame indices) that a camera fitted on all of them must
    both improve and worsen, by more than ``min_drop`` each (:func:`~piga.diagnostics.partial.split_share`), to be
    read as an effect in part of the recording only (:func:`~piga.diagnostics.partial.partial_camera`). Measured: 0.375
    to 0.5 on six pixel-pendulum recordings with an effect in half of the sequences or from frame 12 on (blur 1.5 or
    1.2 px, a shift of 3 px, exposure 0.8); 0 on a clean one, on the 42 recordings of the blind benchmark (blur up to
    2.2 px, shifts up to 3 px), on its 15 recordings with no effect, on whole-file blur 3.9 px and shift 4.9 px, and on
    two dm_control recordings."""
    max_scale_change: float = 0.06
    """Largest relative difference between the pendulum's drawn size in the recording and in the decoder's renders
    (:func:`drawn_scale`, through the accepted camera) at which a blur, a shift or a zoom may be accepted: beyond it the
    picture is zoomed (a camera nearer or farther) or the pendulum has another length, which the accepted camera (its
    zoom included) does not describe, and a shift fitted to renders of another size only takes up the difference
    (measured without the zoom candidate: dm_control at camera distance 1.2 read x0.84 and "shift -0.725 px down" at a
    21% drop, at 1.1 "shift -0.492 px down"; with it, distances 1.1 and 1.3 read "zoom 0.93" and "zoom 0.826", through
    which they are drawn x0.98 and x0.95; a dm_control pendulum of length 0.4 x0.82; the 42 recordings of the pixel
    pendulum's blind benchmark, with blur, shift, noise, exposure and physics effects, x0.98 to x1.02 through their
    accepted camera, others with blur 3 to 3.9, shift 3 to 4.9, exposure 1.3 or no torque arrow x0.97 to x1.04)."""
    max_scale_noise: float = 23.0
    """Largest sensor noise (gray levels σ, :func:`noise_level` on the pixels the pendulum never reaches) at which the
    drawn size (:func:`drawn_scale`) is measured: beyond it noise alone lights pixels far from the hinge (measured on a
    clean Gymnasium recording with planted Gaussian noise: x0.986 to x1.0 at 10 to 23, x1.019 at 24, x1.156 at 25, x2.2
    to x2.8 at 30 to 60, where "noise 59.5" was named with a note of a pendulum drawn x2.76; the blind benchmark's
    noise of 22 read within 2%). Then no size is claimed: no zoom is tried, and no blur or shift is refused for the size."""
    repeats: RepeatConfig = field(default_factory=RepeatConfig)
    """When repeated frames are named dropped frames (:mod:`piga.diagnostics.repeats`)."""

    def __post_init__(self) -> None:
        check_types(self)
        if not isinstance(self.repeats, RepeatConfig):
            raise TypeError(f"CameraConfig.repeats must be a RepeatConfig; got {self.repeats!r}")
        check_ranges(self, {"fit_frames": (1, 10_000_000), "held_frames": (1, 10_000_000), "min_drop": (0, 1),
                            "min_blur": (0, 100), "min_shift": (0, 100), "min_noise": (0, 255),
                            "min_zoom": (0, 1), "zoom_scale": (0, 10),
                            "min_exposure": (0, 255), "min_core_share": (0, 1), "max_missing": (0, 1),
                            "max_scale_change": (0, 10), "min_split_share": (0, 1), "max_scale_noise": (0, 255),
                            "max_noise_correlation": (-1, 1), "min_contrast": (0, 1)})


@dataclass
class CameraFindings:
    """What the camera stage found; ``theta`` holds the re-matched angles when a camera or noise was accepted."""

    camera: Camera
    """The accepted camera (all zero: none)."""
    noise: float
    """Sensor noise s (gray levels) on the still pixels."""
    drop_rate: float
    """Share of frames after the leading run that repeat the previous one while the pendulum moves."""
    drops: int
    """How many such frames."""
    leading: int
    """Frames 1..k repeat frame 0 in nearly every sequence (a camera that starts late)."""
    table: list[dict]
    """Candidate rows: camera, held-out matched residual, its drop against no camera, accepted."""
    matched_error_nominal: float
    """Held-out matched residual with no camera effect."""
    matched_error: float
    """... with the accepted camera: the floor of any prediction's pixel error."""
    effects: list[dict]
    """Named camera effects (blur, shift, exposure, noise, frame_drop) with value and unit."""
    theta: np.ndarray | None = None
    """(N, T) angles matched under the accepted camera (None: the encoder's angles stand)."""
    noise_correlation: float = float("nan")
    """Correlation of the still pixels between successive frames (:func:`noise_correlation`; NaN: not measured)."""
    missing: float = 0.0
    """Fraction of the held-out frames in which the pendulum is not in view (:func:`empty_frames`)."""
    scale: float | None = None
    """The pendulum's drawn size in the recording over that in the decoder's renders (:func:`drawn_scale`; None: not
    measured). Beyond ``CameraConfig.max_scale_change`` from 1, no blur or shift is accepted."""
    partial: PartialCamera | None = None
    """A camera effect that only some sequences or frame indices show (:mod:`piga.diagnostics.partial`); then
    ``camera`` is all zero, the effect is named where it shows, and ``theta`` is matched through it there."""
    split: float = 0.0
    """The largest share of groups of fit frames that a fitted camera both improved and worsened
    (:func:`~piga.diagnostics.partial.split_share`; 0: no camera was tried)."""

    matched_for_sign: bool = False
    """``theta`` holds the angles matched with no camera because the encoder's angles missed the actuation's sign
    (:func:`~piga.diagnostics.diagnose.read_with_sign`), not because a camera or noise was accepted."""
    matched_for_arrow: bool = False
    """``theta`` holds the angles matched with no camera because the vision gap lies in what is drawn with the action
    (:func:`~piga.diagnostics.diagnose.drawn_with_the_action`), through which the encoder reads its angles."""
    matched_for_codec: float | None = None
    """Where ``theta`` holds the angles matched with no camera because the recording comes from a lossy video whose
    codec's errors the encoder reads: how many times as large the nominal physics' typical one-step angle error is on
    the encoder's angles as on the matched ones (:func:`~piga.diagnostics.diagnose.codec_reading_ratio`); None
    otherwise."""

    unseen: float = 0.0
    """Fraction of the held-out frames in which the pendulum is not in view through any camera tried
    (:attr:`CameraConfig.blurs_seen`, the candidates, the accepted one); measured only where ``missing`` exceeds
    ``CameraConfig.max_missing`` (else equal to it). Well under ``missing``: the frames show the pendulum through
    another camera than the one read, which differs between parts of the recording."""

    def below_naming(self, config: CameraConfig) -> dict | None:
        """The candidate row that lowers the held-out matched residual most, by more than ``min_drop``, where no camera
        is accepted because its change is under the size that is named (``min_blur``, ``min_shift``, ``min_exposure``,
        ``min_zoom``); None where a camera is named, the size refused them, or none drops that far.

        Measured: dm_control filmed from 1.05 times as far (flip=motor), a zoom of 0.972 lowered the residual by 40% and
        a shift of -0.27 px down by 17%; on clean recordings, the 42 recordings of the blind benchmark and 15 without
        an effect, no such row (every unaccepted row with a drop over 0.1 was a part-of-file camera, named, or one
        refused for the size)."""
        if self.camera != Camera() or self.partial is not None or self.rescaled(config):
            return None
        rows = [r for r in self.table[1:] if not r["accepted"] and not r.get("rescaled") and not r.get("partial")
                and r["drop"] > config.min_drop]
        return max(rows, key=lambda r: r["drop"], default=None)

    def rescaled(self, config: CameraConfig) -> bool:
        """Whether the pendulum is drawn at another size than the model's renders (:func:`drawn_scale`)."""
        return self.scale is not None and abs(self.scale - 1) > config.max_scale_change

    @property
    def rematched(self) -> bool:
        return self.theta is not None

    @property
    def named_noise(self) -> float:
        """The sensor noise named among ``effects`` (gray levels σ; 0: none named)."""
        return next((e["value"] for e in self.effects if e["effect"] == "noise"), 0.0)


#: The factor by which the noise read over every frame must exceed that over the frames after the smallest fifth of
#: the actions for the latter to be taken: what is drawn with the action adds to it there.
ARROW_NOISE_FACTOR = 1.1


def _calm(actions: np.ndarray | None, seqs: np.ndarray, times: np.ndarray, stale: np.ndarray | None = None,
          least: int = 20) -> np.ndarray | None:
    """(M,) bool: which of the frames of sequences ``seqs`` (M,) at indices ``times`` (M,) are :func:`calm_frames` of
    the (N, T) ``actions`` and ``stale``; None where the actions are unknown or do not vary, or fewer than ``least``
    frames are left."""
    frames = calm_frames(actions, stale) if actions is not None else None
    if frames is None:
        return None
    after = times >= 1
    calm = np.zeros(len(times), bool)
    calm[after] = frames[seqs[after], times[after] - 1]
    return calm if calm.sum() >= least else None


def _lowers(row: dict) -> float:
    """How much a camera stage's candidate ``row`` lowers the held-out matched residual: of every frame, or of the
    frames after the smallest fifth of the actions where they were scored, whichever more."""
    return max(row["drop"], row.get("calm_drop", row["drop"]))


def _sample(path: str, rows: np.ndarray, count: int,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(count, H, W[, C]) uint8 random frames of sequences ``rows`` of the file, and (count,) their sequences and
    (count,) their frame indices, in the file's order."""
    from piga.data.schema import open_data_file

    with open_data_file(path) as f:
        ds = f["frames"]
        t = ds.shape[1]
        seqs = np.sort(rng.choice(rows, min(len(rows), max(1, count // t + 1) * 2), replace=False))
        frames = ds[seqs].reshape(-1, *ds.shape[2:])
    pick = np.sort(rng.choice(len(frames), min(count, len(frames)), replace=False))
    return frames[pick], np.repeat(seqs, t)[pick], np.tile(np.arange(t), len(seqs))[pick]


def camera_interval(model: PhysicsModel, camera: Camera, name: str, x: Tensor, clusters: np.ndarray,
                    step: float = 0.05) -> list[float]:
    """95% interval of one camera parameter: the sandwich (M-estimator) variance, robust to frames of a
    sequence being alike (clustered by ``clusters`` (M,)), from per-frame residual derivatives.

    ``name`` "shift" is the shift's length, sqrt(dx² + dy²), varied along its own direction."""
    errs, renders = [], decoder_renders(model)
    length = math.hypot(camera.dx, camera.dy)
    for sign in (-1, 0, 1):
        if name == "shift":
            scale = (length + sign * step) / length if length > 0 else 1.0
            cam = Camera(**{**camera.__dict__, "dx": camera.dx * scale, "dy": camera.dy * scale})
        else:
            value = getattr(camera, name) + sign * step
            cam = Camera(**{**camera.__dict__, name: max(value, 0.0) if name == "blur" else value})
        errs.append(match(angle_table(model, cam, renders=renders), x)[1].double().numpy())
    d1 = (errs[2] - errs[0]) / (2 * step)  # (M,)
    curvature = float(np.mean(errs[2] - 2 * errs[1] + errs[0])) / step**2
    sums = np.bincount(np.unique(clusters, return_inverse=True)[1], weights=d1 - d1.mean())
    value = length if name == "shift" else getattr(camera, name)
    if curvature <= 0:
        return [float("nan"), float("nan")]
    sd = math.sqrt(float((sums**2).sum())) / (len(d1) * curvature)
    return [value - 1.96 * sd, value + 1.96 * sd]


def _flat(frames: np.ndarray, channels: int = 1) -> Tensor:
    """uint8 frames (M, H, W) or (M, H, W, C) -> (M, P) in [0, 1], flattened like :class:`AngleTable` renders."""
    return frames_to_float(torch.from_numpy(np.ascontiguousarray(frames))[None], channels)[0].reshape(len(frames), -1)


@torch.no_grad()
def match_file(model: PhysicsModel, path: str, camera: Camera, batch: int = 64) -> np.ndarray:
    """(N, T) angles of every frame of ``path`` matched under ``camera``, unwrapped along time."""
    from piga.data.schema import open_data_file

    table = angle_table(model, camera)
    with open_data_file(path) as f:
        ds = f["frames"]
        n, t = ds.shape[:2]
        out = np.empty((n, t))
        for start in range(0, n, batch):
            raw = ds[start : start + batch]
            th, _ = match(table, _flat(raw.reshape(-1, *raw.shape[2:]), model.config.channels))
            out[start : start + len(raw)] = th.double().numpy().reshape(len(raw), t)
    return np.unwrap(out, axis=1)


def camera_stage(model: PhysicsModel, path: str, theta: np.ndarray, fit: np.ndarray, stale: np.ndarray | None,
                 config: CameraConfig = CameraConfig(), seed: int = 0, progress: bool = False,
                 reference: str | None = None, actions: np.ndarray | None = None) -> CameraFindings:
    """Fits and tests the camera candidates on the recording ``path``.

    Args:
        theta: (N, T) the encoder's angles (to tell a moving pendulum from a still one).
        fit: (N,) bool, the fit split.
        stale: (N, T) repeated frames (:func:`~piga.diagnostics.repeats.stale_frames`), or None.
        progress: show a progress bar over the fits.
        reference: the model's own training file, where it is there: an exposure is named relative to that file's
            (:func:`reference_exposure`), since a decoder may draw the whole scene a little darker than its frames.
        actions: (N, T) the recording's actions, where known: noise that every frame shows more of than the frames
            after the smallest fifth of them is read on those (:func:`calm_noise`), which carry nothing drawn with the
            action; the camera candidates are scored on those frames too.
    """
    from tqdm.auto import tqdm

    bar = tqdm(total=6, desc="camera candidates", disable=not progress)
    rng = np.random.default_rng(seed)
    fit_rows, held_rows = np.flatnonzero(fit), np.flatnonzero(~fit)
    raw_fit, fit_seqs, fit_times = _sample(path, fit_rows, config.fit_frames, rng)
    channels = model.config.channels
    raw_held, held_seqs, held_times = _sample(path, held_rows, config.held_frames, rng)
    x_fit, x_held = _flat(raw_fit, channels), _flat(raw_held, channels)

    renders = decoder_renders(model, TABLE_SIZE // 2)  # every candidate camera sees the same angles
    # the held-out frames after the smallest fifth of the actions, where known: a camera changes every frame, and these
    # carry nothing drawn with the action, which no camera explains (Gymnasium at an actuation gain of 5 draws its
    # torque arrow so large that a blur of 1.5 px, fitted as 1.499, lowered the residual of every frame by 7.5% alone)
    calm_held = _calm(actions, held_seqs, held_times, stale)
    x_calm = x_held[torch.from_numpy(calm_held)] if calm_held is not None else None
    e0 = matched_error(model, Camera(), x_held, renders=renders)
    table: list[dict] = [{"candidate": "none", "camera": Camera().__dict__, "held_out_matched_mse": e0, "drop": 0.0,
                          "accepted": False}]
    if x_calm is not None:
        table[0].update(held_out_calm_mse=matched_error(model, Camera(), x_calm, renders=renders), calm_drop=0.0)

    def row(name: str, cam: Camera, base: dict, needs: set[str]) -> dict:
        """A candidate's table row, scored against the row of the camera ``base`` it is fitted on top of; accepted when
        it lowers the residual enough (of every held-out frame, or of the calm ones) and ``needs`` are material."""
        e = matched_error(model, cam, x_held, renders=renders)
        drop = 1 - e / base["held_out_matched_mse"] if base["held_out_matched_mse"] > 0 else 0.0
        out = {"candidate": name, "camera": dict(cam.__dict__), "held_out_matched_mse": e, "drop": drop}
        if x_calm is not None:
            calm, calm_base = matched_error(model, cam, x_calm, renders=renders), base["held_out_calm_mse"]
            out.update(held_out_calm_mse=calm, calm_drop=1 - calm / calm_base if calm_base > 0 else 0.0)
        out["accepted"] = bool(needs <= cam.material(config) and _lowers(out) > config.min_drop)
        return out

    # the exposure first. Where the background shows it, it is fitted first and the blur and the shift on top of it:
    # a darker picture leaves every blur and shift worse than none (measured: a picture darkened by 15% gave the blur
    # candidate no drop). A brighter one, seen on the pendulum alone, competes with them.
    frames_2d = raw_fit if raw_fit.ndim == 3 else raw_fit[..., 0]
    still = static_pixels(model)
    exposed, shown = fit_exposure(model, frames_2d, still, x_fit, renders, config.min_exposure)
    lit = row("exposure", exposed, table[0], {"exposure"})
    if lit["accepted"] and not shown:  # a brighter picture on white: the pendulum itself must show it
        core = core_brightening(model, x_fit, renders)
        lit["core_brightening"] = core
        lit["accepted"] = core_shows_share(core, exposed.exposure, config)
    table.append(lit)
    first = shown and lit["accepted"]
    base, base_row = (exposed, lit) if first else (Camera(), table[0])
    e_base = base_row["held_out_matched_mse"]
    bar.update()
    label = "exposure+" if first else ""
    calm_fit = _calm(actions, fit_seqs, fit_times, stale)
    x_fit_calm = x_fit[torch.from_numpy(calm_fit)] if calm_fit is not None and x_calm is not None else None

    def candidate(name: str, base_row: dict, needs: set[str], **fit: Any) -> dict:
        """The row of the camera fitted with ``fit`` (:func:`fit_camera`'s options); one that lowers the residual of
        the calm frames alone enough is fitted again on the calm fit frames: what is drawn with the action then
        dominates every frame, and bends the fit too."""
        r = row(name, fit_camera(model, x_fit, renders=renders, **fit), base_row, needs)
        if r["accepted"] and r["drop"] <= config.min_drop and x_fit_calm is not None:
            r = {**row(name, fit_camera(model, x_fit_calm, renders=renders, **fit), base_row, needs), "fitted_on": "calm"}
        return r

    singles = [candidate(label + "blur", base_row, {"blur"}, shift=False, base=base)]
    bar.update()
    singles.append(candidate(label + "shift", base_row, {"shift"}, blur=False, base=base))
    # a zoom (a camera nearer or farther, a pendulum of another length), where the drawn size shows one: a blur or a
    # shift fitted to renders of another size takes up part of the difference (dm_control filmed from 1.1 times as far,
    # drawn x0.91, read "shift -0.492 px down"), and a picture zoomed out, which shows less of the dark pendulum, reads
    # as a brighter one (x0.9 read "exposure 1.14")
    sized = noise_level(frames_2d, still) <= config.max_scale_noise  # (beyond, noise lights pixels far from the hinge)
    scale = drawn_scale(frames_2d, renders, base) if sized else None
    zoomed = None
    if sized and (scale is None or abs(scale - 1) > config.zoom_scale):
        zoomed = candidate(label + "zoom", base_row, {"zoom"}, blur=False, shift=False, zoom=True, base=base)
        singles.append(zoomed)
    bar.update()
    table += singles
    best = max(singles if shown else [*singles, lit], key=_lowers)
    camera, e_cam = base, e_base
    if best["accepted"]:
        camera, e_cam = Camera(**best["camera"]), best["held_out_matched_mse"]
        if best is lit or best is zoomed:  # a brighter picture or a zoom: the blur and the shift on top, where material
            kind = "exposure" if best is lit else label + "zoom"
            on = x_fit_calm if best.get("fitted_on") == "calm" else x_fit
            # a brighter picture's exposure refitted with them: fitted alone it takes up part of the blur (an exposure
            # of 1.12 with a blur of 0.8 px, held at its own 1.187, read "blur 0.672; exposure 1.18")
            fitted = fit_camera(model, on, renders=renders, base=camera, zoom=best is zoomed,
                                brighter=best is lit and not shown)
            more = fitted.material(config) - {"exposure", "zoom"}
            shift = "shift" in more
            on_top = Camera(blur=fitted.blur if "blur" in more else 0.0, dx=fitted.dx if shift else 0.0,
                            dy=fitted.dy if shift else 0.0, exposure=fitted.exposure, zoom=fitted.zoom)
            both = row("+".join([kind, *sorted(more)]) if more else kind + "+blur+shift", on_top, best,
                       more or {"blur", "shift"})
        else:
            both = candidate(label + "blur+shift", best, {"blur", "shift"} - {best["candidate"].removeprefix(label)},
                             base=base)
        table.append(both)
        if both["accepted"]:
            camera, e_cam = Camera(**both["camera"]), both["held_out_matched_mse"]
        if lit["accepted"] and best is not lit and not shown:
            # a brighter picture on white beside a blur or a shift that lowers the residual more: the exposure refitted
            # with them (an exposure of 1.1 with a blur of 0.9 px read "blur 0.86" alone, the exposure never tried on
            # top, and the dynamics on angles matched through that camera "not explained ... the scene the model
            # knows?")
            current = both if both["accepted"] else best
            now = Camera(**current["camera"])
            kept = now.material(config)
            brighter = fit_camera(model, x_fit, blur="blur" in kept, shift="shift" in kept, renders=renders, base=now,
                                  zoom="zoom" in kept, brighter=True)
            lit_too = row("exposure+" + current["candidate"], brighter, current, {"exposure"})
            table.append(lit_too)
            if lit_too["accepted"]:
                camera, e_cam = brighter, lit_too["held_out_matched_mse"]
    # the pendulum's size, seen through the accepted camera: its blur widens the lit reach (a 3.9 px blur read x0.5
    # against sharp renders), its shift moves the hinge (a 3 px shift read x1.16 unshifted, x0.99 through it)
    scale = drawn_scale(frames_2d, renders, camera) if sized else None
    if scale is not None and abs(scale - 1) > config.max_scale_change:
        # a blur or a shift fitted against renders of another size only takes up the difference; a zoom that leaves
        # the size off has not found it
        for r in table:
            if {"blur", "shift", "zoom"} & set(r["candidate"].split("+")):
                r["accepted"], r["rescaled"] = False, True
        if camera.blur or camera.dx or camera.dy or camera.zoom != 1:
            camera = Camera(exposure=camera.exposure)  # an accepted exposure stays (fitted first, or the best single)
            e_cam = e_base if camera == base else lit["held_out_matched_mse"]
            scale = drawn_scale(frames_2d, renders, camera) if sized else None
    bar.update()
    # a camera effect in only part of the recording: named where it shows, with no camera of the whole recording
    from piga.diagnostics.partial import match_partial, partial_camera, partial_effects, partial_empty, partial_error

    # (the candidates refused for the size too: a blur in part of the frames shrinks the size read with no camera, a
    # 2 px blur from frame 12 on read x0.90 and "no significant gap")
    tried = [camera] if camera != Camera() else [Camera(**r["camera"]) for r in table[1:]]
    if {"blur", "shift"} <= camera.material(config):
        # each of its blur and its shift alone too: two cameras in two parts are read as one of both, which improves
        # every part (a shift of 2 px in the odd sequences and a blur of 1.5 px in the even ones read "blur 0.869 px;
        # shift 1.49 px right, 1.45 px down" at a split of 0; its shift alone split the sequences 0.49)
        tried += [replace(camera, dx=0.0, dy=0.0), replace(camera, blur=0.0)]
    partial, split = partial_camera(model, tried, frames_2d, x_fit, fit_seqs, fit_times, still, renders, config)
    theta_partial = None
    if partial is not None:
        theta_partial, partial = match_partial(model, path, partial)
        scale = None  # (a size read on frames that only partly show the camera is no size)
        camera, e_cam = Camera(), partial_error(model, partial, x_held, held_seqs, held_times, renders)
        for r in table:  # not a camera of the whole recording
            if r["accepted"]:
                r["accepted"], r["partial"] = False, True
    effects: list[dict] = []
    if camera.blur > 0:
        effects.append({"effect": "blur", "value": camera.blur, "unit": "px (Gaussian σ)",
                        "interval": camera_interval(model, camera, "blur", x_fit, fit_seqs)})
    if camera.dx or camera.dy:
        # the value is the shift's length, with its interval along its direction; dx and dy each with its own (the
        # mean of the two, "mean 1 (95% interval 1.001..1.002)" for a shift of 2 px right, said little)
        ix, iy, length = (camera_interval(model, camera, k, x_fit, fit_seqs) for k in ("dx", "dy", "shift"))
        effects.append({"effect": "shift", "value": math.hypot(camera.dx, camera.dy), "dx": camera.dx, "dy": camera.dy,
                        "dx_interval": ix, "dy_interval": iy, "unit": "px (length of the shift; dx right, dy down)",
                        "interval": length})
    if camera.zoom != 1:
        effects.append({"effect": "zoom", "value": camera.zoom, "unit": ZOOM_UNIT,
                        "interval": camera_interval(model, camera, "zoom", x_fit, fit_seqs, step=0.01)})
    if not shown and camera.exposure > 1:  # a brighter picture on white: read on the rod
        value, interval = core_exposure(model, x_fit, fit_seqs, renders, reference, config.fit_frames, seed, camera)
        if rod_shows_exposure(value, camera.exposure, config):
            effects.append({"effect": "exposure", "value": value, "unit": "factor on every gray level",
                            "interval": interval})
    elif camera.exposure != 1:  # named relative to the model's own frames
        own = reference_exposure(model, reference, still, renders, config.fit_frames, seed)
        if 255 * abs(camera.exposure / own - 1) > config.min_exposure:
            lo, hi = camera_interval(model, camera, "exposure", x_fit, fit_seqs, step=0.01)
            effects.append({"effect": "exposure", "value": camera.exposure / own, "unit": "factor on every gray level",
                            "interval": [lo / own, hi / own]})

    if partial is not None:
        own = reference_exposure(model, reference, still, renders, config.fit_frames, seed)
        effects += partial_effects(model, partial, x_fit, fit_seqs, fit_times, config, own)

    if camera.blur or camera.dx or camera.dy or camera.zoom != 1:  # the pixels the pendulum never reaches in them
        still = static_pixels(model, camera=camera)
    # Sensor noise is in every frame; what is drawn with the action is not in the frames after its smallest fifth, so
    # where every frame reads more than those (by 10%), the noise is read on them: Gymnasium at an
    # actuation gain of 3 draws its torque arrow onto pixels that the training frames' never reach ("noise 41.8 gray
    # levels" over every frame of a file with none, 0 over these), and at a gain of 4 a noise of 3 read 44.7 over every
    # frame, 2.98 over these, and at a gain of 3 a noise of 2 2.43 and 2.0. Elsewhere every frame is read (a noise of
    # 20.53 read 20.39 over them, 20.2 over the calm ones)
    noise, noise_ci = noise_level(frames_2d, still, interval=True)
    calm = (calm_noise(frames_2d, fit_seqs, fit_times, actions, still, stale) if actions is not None and noise > 0
            else None)
    if calm is not None and noise > ARROW_NOISE_FACTOR * calm[0]:
        noise, noise_ci = calm
    correlation = float("nan")
    if noise > config.min_noise:
        # a repeated frame repeats its noise: left out of the correlation
        fresh = np.ones(len(fit_seqs), bool) if stale is None else ~stale[fit_seqs, fit_times]
        correlation = noise_correlation(frames_2d[fresh], still, fit_seqs[fresh])
    noisy = noise > config.min_noise and not correlation > config.max_noise_correlation
    if noisy:
        effects.append({"effect": "noise", "value": noise, "unit": "gray levels (σ)", "interval": noise_ci})

    theta_c = None
    if camera != Camera() or noisy:
        theta_c = match_file(model, path, camera)
    if theta_partial is not None:
        theta_c = theta_partial
    bar.update()
    # whether the pendulum moves across a repeated frame: on the angles matched through the accepted camera where
    # there is one (the encoder misreads frames through another camera: a 3.9 px blur read "frame_drop 0.0118" from
    # repeats where its angles moved and the pendulum did not)
    repeats = config.repeats
    if camera != Camera():  # a step must show through it
        repeats = replace(repeats, moving=max(repeats.moving, visible_step(model, camera, repeats.visible)))
    leading, drops, drop_rate, repeat_effects = repeated_frames(stale, theta if theta_c is None else theta_c, repeats)
    effects += repeat_effects
    if partial is None:
        missing = empty_frames(model, camera, x_held, renders, config.min_contrast)
    else:  # each frame through the camera it shows (a blur of 2.5 px from frame 8 on read "not in view in 64%" with none)
        missing = partial_empty(model, partial, x_held, held_seqs, held_times, renders, config.min_contrast)
    unseen = missing
    if missing > config.max_missing:  # are they empty through every camera, or only through this one?
        unseen = empty_frames(model, [camera, *tried, *(Camera(blur=b) for b in config.blurs_seen)], x_held, renders,
                              config.min_contrast)
    bar.update()
    bar.close()
    return CameraFindings(camera, noise, drop_rate, drops, leading, table, e0, e_cam, effects, theta_c, correlation,
                          missing, scale, partial, split, unseen=unseen)


def pendulum_reach(frames: np.ndarray, background: np.ndarray, hinge: np.ndarray, sign: float) -> float | None:
    """The median over frames (M, H, W) in [0, 1] of the farthest distance (px) from ``hinge`` (2,) (row, column) of a
    pixel that the pendulum lights: one that differs from ``background`` (H, W) by more than half the pendulum's
    contrast, of the pendulum's ``sign`` (+1: brighter than the background; a shadow of the other sign is left out).
    None where under half the frames show the pendulum."""
    lit = _lit(frames - background, sign)  # (M, H, W)
    if lit is None:
        return None
    rows, cols = np.mgrid[: frames.shape[1], : frames.shape[2]]
    r = np.hypot(rows - hinge[0], cols - hinge[1])  # (H, W)
    shown = lit.any(axis=(1, 2))
    if shown.sum() < 0.5 * len(frames):
        return None
    return float(np.median(np.where(lit[shown], r, 0.0).max(axis=(1, 2))))


def _lit(d: np.ndarray, sign: float) -> np.ndarray | None:
    """Where differences ``d`` from the background (M, H, W) exceed half the pendulum's contrast (their 99.9th
    percentile) with its ``sign``; None where there is no contrast of that sign."""
    contrast = float(np.percentile(sign * d, 99.9))
    return sign * d > contrast / 2 if contrast > 0 else None


def drawn_scale(frames: np.ndarray, renders: tuple[Tensor, Tensor], camera: Camera = Camera()) -> float | None:
    """The pendulum's size in uint8 frames (M, H, W) over its size in the decoder's renders over the whole circle
    (:func:`decoder_renders`) seen through ``camera``: the ratio of their :func:`pendulum_reach` from the renders' hinge
    (the pixels they light most often; the frames' background is their per-pixel median, the renders'
    :func:`empty_scene`). A zoom or another pendulum length scales it; a shift of a pixel or sensor noise move it by a
    few percent, a blur too where ``camera`` has it. None where it cannot be measured (a pendulum that shows in under
    half the frames, or a still one, which the median takes for the background)."""
    angles, seen = renders[0], camera.apply(renders[1])
    drawn = seen[:, 0].numpy()  # (K, H, W)
    empty = empty_scene((angles, seen))[0].numpy()
    d = drawn - empty
    sign = 1.0 if d.sum() >= 0 else -1.0  # the pendulum brighter or darker than the scene
    lit = _lit(d, sign)
    if lit is None:
        return None
    often = lit.mean(0)  # (H, W) how often each pixel is lit
    hinge = np.argwhere(often >= 0.9 * often.max()).mean(0)
    own = pendulum_reach(drawn, empty, hinge, sign)
    x = frames.astype(np.float32) / 255.0
    theirs = pendulum_reach(x, np.median(x, axis=0), hinge, sign)
    return None if own is None or theirs is None or own <= 0 else theirs / own


@torch.no_grad()
def visible_step(model: PhysicsModel, camera: Camera, levels: float, size: int = 1440) -> float:
    """The smallest angle step (rad) that changes the decoder's renders through ``camera`` by ``levels`` gray levels
    (the largest pixel change, the median over the circle): a step under it can leave a frame within a repeat's
    tolerance of the one before (π where none does)."""
    renders = angle_table(model, camera, size).renders  # (K, P)
    for k in range(1, size // 2):
        if float((renders - renders.roll(-k, 0)).abs().amax(1).median()) * 255 >= levels:
            return k * 2 * math.pi / size
    return math.pi


def reference_frames(reference: str | None, count: int, seed: int) -> np.ndarray | None:
    """``count`` random uint8 frames (count, H, W[, C]) of the model's own training file ``reference``, drawn with
    ``seed``; None where there is none, or it is gone or unreadable."""
    if reference is None:
        return None
    try:
        from piga.data.schema import open_data_file

        with open_data_file(reference) as f:
            rows = np.arange(f["frames"].shape[0])
        return _sample(reference, rows, count, np.random.default_rng(seed))[0]
    except (OSError, KeyError, ValueError):
        return None


def reference_exposure(model: PhysicsModel, reference: str | None, still: np.ndarray, renders: tuple[Tensor, Tensor],
                       count: int, seed: int) -> float:
    """:func:`background_exposure` of ``count`` frames of the model's own training file ``reference``: how much
    brighter than its decoder's background its own frames are (1 where the file is gone, unreadable, of other
    frames, or its background cannot show it). A model trained on g = 3 frames drew them 1.6% darker, and its own
    training file read "exposure 1.02"."""
    frames = reference_frames(reference, count, seed)
    if frames is None:
        return 1.0
    frames = frames if frames.ndim == 3 else frames[..., 0]
    if frames.shape[1:] != still.shape:
        return 1.0
    k = background_exposure(frames, *lit_pixels(still, renders))
    return 1.0 if k is None or not k > 0 else k


def empty_scene(renders: tuple[Tensor, Tensor]) -> Tensor:
    """(C, H, W) the scene without the pendulum: the per-pixel median of the :func:`decoder_renders` over the circle
    (no pixel holds the pendulum at half of the angles)."""
    return renders[1].median(0).values


@torch.no_grad()
def empty_frames(model: PhysicsModel, camera: Camera | list[Camera], x: Tensor, renders: tuple[Tensor, Tensor],
                 min_contrast: float = 0.0) -> float:
    """The fraction of frames ``x`` (M, P) closer to the empty scene than to any render of the pendulum, through
    ``camera``: frames in which the pendulum is not in view (the empty scene: :func:`empty_scene`). A frame with the
    pendulum is far closer to its render (measured on a default model: matched MSE about 3e-4 against 2e-2 to the
    empty scene). Given several cameras, the frames so through every one of them. A camera that leaves under
    ``min_contrast`` of the pendulum's contrast (:func:`pendulum_contrast`) shows every frame empty."""
    if not len(x):
        return 0.0
    cameras = camera if isinstance(camera, list) else [camera]
    empty = torch.stack([empty_mask(model, c, x, renders, min_contrast) for c in cameras]).all(0)  # (M,)
    return float(empty.double().mean())


@torch.no_grad()
def empty_mask(model: PhysicsModel, camera: Camera, x: Tensor, renders: tuple[Tensor, Tensor],
               min_contrast: float = 0.0) -> Tensor:
    """(M,) bool: which frames ``x`` (M, P) are closer to the empty scene than to any render of the pendulum, through
    ``camera``, or all of them where ``camera`` leaves under ``min_contrast`` of the pendulum's contrast
    (:func:`empty_frames`)."""
    if pendulum_contrast(camera, renders) < min_contrast:
        return torch.ones(len(x), dtype=torch.bool)
    empty = camera.apply(empty_scene(renders)[None]).flatten(1)  # (1, P)
    _, matched = match(angle_table(model, camera, renders=renders), x)  # (M,)
    return ((x - empty) ** 2).mean(1) <= matched


@torch.no_grad()
def pendulum_contrast(camera: Camera, renders: tuple[Tensor, Tensor]) -> float:
    """The mean squared difference of the decoder's renders (:func:`decoder_renders`) from the empty scene through
    ``camera``, over that with no camera: how much of the pendulum a camera leaves to see (1: all; a blur or an
    exposure that washes it out, near 0)."""
    empty = empty_scene(renders)[None]  # (1, C, H, W)
    plain = float(((renders[1] - empty) ** 2).mean())
    seen = float(((camera.apply(renders[1]) - camera.apply(empty)) ** 2).mean())
    return seen / plain if plain > 0 else 0.0
