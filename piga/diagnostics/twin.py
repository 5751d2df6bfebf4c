"""The floor of the gap: how well an exactly right model predicts, measured on a simulated twin.

Even a model whose physics is exactly right has a held-out error, since it reads its states from
frames through the encoder. That error is the floor under which no correction can go, and the
"gap" is what the nominal model has above it. Its size depends on the encoder's errors, which are
correlated in time and depend on the angle, and on the windows (near upright, a small velocity
error grows fast). No simple noise model captures both: white angle noise overestimates the typical
window's floor 2x. So the floor is measured instead, on a twin of the held-out data:

1. each held-out sequence is re-simulated with the corrected physics, from its first two encoded
   angles and with its own actions (the twin's states are those of a system that the corrected
   model describes exactly);
2. the twin is rendered by the simulator the model was identified in (Gymnasium's Pendulum-v1
   render, resized and grayed by Gymnasium's wrappers, as :func:`envs.pendulum.make_pixel_pendulum`
   does), and the recording's repeated frames are repeated in the twin too;
3. the model encodes the twin's frames, and the corrected model predicts the twin's windows just as
   it predicts the real ones.

The floor is the simulator's: a recording whose pictures differ from the simulator's (another
camera, a codec) has its own vision error on top, which counts as part of the gap. A recording that
did not come from the simulator (another camera: a MuJoCo scene, a real pendulum) has its twin
rendered instead by the model's own decoder (``renderer="decoder"``), the picture the model learned
of that camera; that is the recording's own camera only when the autoencoder re-renders the
recording about as well as its training frames, which the caller checks. The encoder need not read
the decoder's picture as it reads the recording (on dm_control's shaded pole it reads the decoder's
flat templates worse), so the decoder's twin is calibrated to the recording's own vision noise
(:func:`calibrate_floor`): an exactly right model's errors are linear in the encoder's errors, so
its squared errors scale with their variance, which the one-step error gives on both sides (assuming
the two have alike correlations in time: an approximation, which the report names).

Frames that piga-import read from a lossy video carry the codec's errors, which move the encoder's
angles far more than the clean twin's (a clean recording written to H.264 at crf 28 gave a one-step
angle error 11x that of the same frames uncompressed, and read "not explained" at 7.4x the floor).
Their twin is filmed through H.264 too (:func:`codec_floor`), at the quality that reads its angles as
noisily as the recording's.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from envs.constants import MAX_ACTION
from piga.diagnostics import fit
from piga.diagnostics.observe import read_frames
from piga.diagnostics.residuals import one_step_residuals
from piga.diagnostics.vision import Camera, angle_table, match
from piga.world.model import PhysicsModel, frames_to_float
from piga.io.runs import Nominal


@dataclass(frozen=True)
class TwinFloor:
    """A corrected model's held-out errors on its twin (the floor of the gap)."""

    horizon: np.ndarray
    """(H,) mean squared angle error (rad²) at each horizon, as :func:`piga.diagnostics.fit.horizon_errors`."""
    windows: np.ndarray
    """(B,) each free-run window's mean squared angle error (rad²), as :func:`piga.diagnostics.fit.window_errors`."""
    residual: float = math.nan
    """The median absolute one-step acceleration residual (rad/s²) of the corrected model on the twin
    (:func:`median_residual`): the vision noise, robust to the few frames a codec makes the encoder misread."""


def twin_angles(model: fit.Model, nominal: Nominal, theta: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """(n, T) angles (model convention) of the twin of ``n`` sequences of (n, T) encoded ``theta``.

    Frames 0 and 1 are the encoded ones; from frame 2 on, ``model`` simulates with the sequence's
    actions (actions before frame 0, which a delay would need, are taken as 0).
    """
    n, t = theta.shape
    clipped = np.clip(actions[:, : t - 1], -MAX_ACTION, MAX_ACTION)
    pad = np.concatenate([np.zeros((n, fit.MAX_DELAY - 1)), clipped], 1)  # u_{-3}..u_{T-2}
    as_t = lambda x: torch.as_tensor(x, dtype=torch.float64)  # noqa: E731
    w = fit.Windows(as_t(theta[:, 1]), as_t((theta[:, 1] - theta[:, 0]) / nominal.dt), as_t(pad),
                  torch.zeros(n, t - 2, dtype=torch.float64), torch.ones(n, t - 2, dtype=torch.float64), torch.arange(n))
    with torch.no_grad():
        sim = fit.simulate(model, fit.parameters_of(model, nominal), nominal, w).numpy()  # (n, T - 2)
    return np.concatenate([theta[:, :2], sim], 1)


def render_angles(angles: np.ndarray, actions: np.ndarray, offset: float, image_size: int, arrow: bool,
                  arrow_gain: float = 1.0) -> np.ndarray:
    """(n, T, H, W) uint8 frames of the pendulum at (n, T) ``angles`` (model convention).

    Rendered as the pixel pendulum renders (Gymnasium's picture, then Gymnasium's
    ``ResizeObservation`` and ``GrayscaleObservation``); with ``arrow``, frame t shows the commanded
    torque ``arrow_gain``·u_{t-1} (none at frame 0), as :class:`envs.effects.ShowCommandedTorque` does with its
    actuation gain, at most :data:`envs.pendulum.ARROW_MAX_TORQUE`.
    """
    import gymnasium as gym
    from gymnasium.wrappers import GrayscaleObservation, ResizeObservation

    from envs.pendulum import ARROW_MAX_TORQUE, PixelPendulumConfig, make_pixel_pendulum

    env = make_pixel_pendulum(PixelPendulumConfig(image_size=image_size, draw_torque_arrow=True))
    try:
        env.reset(seed=0)
        stages = []
        wrapper = env
        while isinstance(wrapper, gym.Wrapper):
            if isinstance(wrapper, (ResizeObservation, GrayscaleObservation)):
                stages.append(wrapper)
            wrapper = wrapper.env
        stages.reverse()  # innermost first: resize, then gray
        base = env.unwrapped
        out = np.empty((*angles.shape, image_size, image_size), np.uint8)
        for i in range(angles.shape[0]):
            for j in range(angles.shape[1]):
                base.state = np.array([angles[i, j] + offset, 0.0])
                base.last_u = float(np.clip(arrow_gain * np.clip(actions[i, j - 1], -MAX_ACTION, MAX_ACTION),
                                            -ARROW_MAX_TORQUE, ARROW_MAX_TORQUE)) if arrow and j > 0 else None
                img = base.render()
                for stage in stages:
                    img = stage.observation(img)
                out[i, j] = img
    finally:
        env.close()
    return out


@torch.no_grad()
def decoder_render(network: PhysicsModel, angles: np.ndarray, batch: int = 16) -> np.ndarray:
    """(n, T, H, W[, C]) uint8 frames of (n, T) ``angles`` (model convention) drawn by the model's own decoder,
    quantised to 8 bits as a camera's would be."""
    out = []
    for start in range(0, len(angles), batch):
        coords = torch.as_tensor(angles[start : start + batch], dtype=torch.float32)[..., None, None]  # (B, T, 1, 1)
        frames = network.decoder(coords).clamp(0, 1)  # (B, T, C, H, W)
        frames = frames[:, :, 0] if frames.shape[2] == 1 else frames.permute(0, 1, 3, 4, 2)
        out.append((frames * 255).round().to(torch.uint8).numpy())
    return np.concatenate(out, 0)


def repeat_stale(frames: np.ndarray, stale: np.ndarray) -> np.ndarray:
    """(n, T, ...) frames where each stale (n, T) frame repeats the frame before it (in place; returned)."""
    for j in range(1, frames.shape[1]):
        frames[stale[:, j], j] = frames[stale[:, j], j - 1]
    return frames


def twin_floor(network: PhysicsModel, model: fit.Model, nominal: Nominal, theta: np.ndarray, actions: np.ndarray,
               stale: np.ndarray | None, stride: int, arrow: bool = True, batch: int = 16,
               renderer: str = "simulator", camera: Camera | None = None, noise: float = 0.0,
               seed: int = 0, arrow_gain: float = 1.0, crf: float | None = None) -> TwinFloor:
    """The errors of ``model`` on the twin of (n, T) encoded held-out sequences ``theta`` and ``actions``.

    Args:
        network: the identified model, whose encoder reads the twin's frames.
        model: the corrected physics (the twin's physics and the predictor).
        stale: (n, T) the recording's repeated frames, repeated in the twin too (None: none).
        stride: frames between window starts, as for the real free-run windows.
        arrow: render Gymnasium's torque arrow (as in the data the model was identified on).
        renderer: "simulator" (Gymnasium's picture) or "decoder" (the model's own, :func:`decoder_render`).
        camera: where ``theta`` are angles matched to the decoder's renders through a fitted camera (analysis by
            synthesis, :func:`piga.diagnostics.vision.match`), the twin's frames are filmed through that camera, with
            sensor ``noise`` (gray levels, drawn from ``seed``), and matched through it as the recording's were,
            instead of being read by the encoder.
        arrow_gain: the actuation gain the simulator's torque arrow is drawn with (:func:`render_angles`).
        crf: film the twin through H.264 at this constant rate factor (:func:`through_h264`); None: not.
    """
    if renderer not in ("simulator", "decoder"):
        raise ValueError(f"renderer must be 'simulator' or 'decoder', got {renderer!r}")
    angles = twin_angles(model, nominal, theta, actions)
    if renderer == "decoder":
        frames = decoder_render(network, angles, batch)
    else:
        frames = render_angles(angles, actions, nominal.offset, network.config.image_size, arrow, arrow_gain)
    if stale is not None:
        repeat_stale(frames, stale)
    if crf is not None:
        frames = through_h264(frames, crf)
    if camera is not None:
        encoded = matched_angles(network, frames, camera, noise, seed)
    else:
        encoded = np.empty(angles.shape)
        for start in range(0, len(frames), batch):
            encoded[start : start + batch] = read_frames(network, frames[start : start + batch])[2]
    rows = np.arange(len(encoded))
    w = fit.make_windows(encoded, actions, rows, None, stride, nominal.dt, stale, repeat=True)
    return TwinFloor(fit.horizon_errors(model, nominal, w), fit.window_errors(model, nominal, w),
                     median_residual(model, nominal, encoded, actions, rows, stale))


def median_residual(model: fit.Model, nominal: Nominal, theta: np.ndarray, actions: np.ndarray, rows: np.ndarray,
                    stale: np.ndarray | None) -> float:
    """The median absolute one-step acceleration residual (rad/s²) of ``model`` on sequences ``rows`` of (N, T) encoded
    ``theta``, leaving out those that touch a repeated frame."""
    res = one_step_residuals(model, nominal, theta, actions, rows, stale)
    return float(np.median(np.abs(res.rho[res.valid]))) if res.valid.any() else math.nan


@torch.no_grad()
def matched_angles(network: PhysicsModel, frames: np.ndarray, camera: Camera, noise: float, seed: int) -> np.ndarray:
    """(n, T) angles of (n, T, H, W[, C]) uint8 ``frames`` filmed through ``camera`` with Gaussian sensor ``noise``
    (gray levels; drawn from ``seed``) and quantised to 8 bits, then matched to the decoder's renders through the same
    camera, unwrapped along time (as :func:`piga.diagnostics.vision.match_file` matches a recording)."""
    n, t = frames.shape[:2]
    x = frames_to_float(torch.from_numpy(np.ascontiguousarray(frames)), network.config.channels)  # (n, T, C, H, W)
    x = camera.apply(x.flatten(0, 1))  # (n·T, C, H, W)
    if noise > 0:
        generator = torch.Generator().manual_seed(seed)
        x = x + torch.randn(x.shape, generator=generator) * (noise / 255)
    x = (x.clamp(0, 1) * 255).round() / 255  # an 8-bit camera's
    theta, _ = match(angle_table(network, camera), x.flatten(1))
    return np.unwrap(theta.double().numpy().reshape(n, t), axis=1)


#: The H.264 qualities (x264's constant rate factor: 0 lossless, 51 worst) a lossy recording's twin is filmed through
#: (with the fast preset's model on 64x64 frames, the median one-step residual rose from 2.2 to 3.5, 4.3, 5.0, 7.7 and
#: 9.3 rad/s² over crf 14 to 34; 1.0 without a codec).
CODEC_LADDER = (14, 18, 22, 26, 30, 34, 38)


def through_h264(frames: np.ndarray, crf: float) -> np.ndarray:
    """(n, T, S, S[, 3]) uint8 square ``frames`` after a round trip through H.264 (libx264, yuv420p, ``-crf crf``), the n
    sequences one after another in one video, each frame read back as piga-import reads a video's
    (:func:`piga.data.scene.scene_to_gray` for gray frames). A side of odd length is padded by its edge for the chroma's
    halving and cut back after."""
    import imageio.v3 as iio

    from piga.data.scene import scene_to_gray

    n, t, h, w = frames.shape[:4]
    gray = frames.ndim == 4
    rgb = np.repeat(frames[..., None], 3, -1) if gray else frames  # (n, T, H, W, 3)
    rgb = np.pad(rgb.reshape(n * t, h, w, 3), ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    # imageio-ffmpeg pipes the frames to ffmpeg; a temporary file, as its reader needs a seekable one
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "twin.mp4"
        iio.imwrite(path, rgb, fps=20, codec="libx264", macro_block_size=1, pixelformat="yuv420p",
                    # one encoder thread: x264's output depends on its thread count, so on the machine's cores
                    output_params=["-crf", f"{crf:g}", "-preset", "medium", "-threads", "1"], ffmpeg_log_level="quiet")
        back = np.stack(list(iio.imiter(path)))[:, :h, :w]  # (n·T, H, W, 3)
    if len(back) != n * t:
        raise RuntimeError(f"H.264 gave back {len(back)} of the twin's {n * t} frames")
    if gray:
        back = np.stack([scene_to_gray(frame, h) for frame in back])  # (n·T, H, W)
    return back.reshape(frames.shape)


def codec_floor(floor_at: Callable[[float], TwinFloor], clean: TwinFloor,
                residual: float) -> tuple[TwinFloor, float | None]:
    """The floor of a recording read from a lossy video, and the H.264 quality (crf) its twin was filmed at (None:
    the twin without a codec already reads the angles as noisily as the recording).

    ``floor_at(crf)`` is the twin filmed through H.264 at ``crf``; ``clean`` the twin without a codec; ``residual``
    the recording's median absolute one-step residual under the corrected model (:func:`median_residual`). The rungs
    of :data:`CODEC_LADDER` are tried in turn until the twin's residual reaches the recording's, and the floor is
    interpolated, in the residual, between that rung and the one before; past the last rung, the last. The codec that
    wrote the recording is unknown (its quality, its size before the import's resize, even its kind), so the twin is
    matched by its effect on the angles instead. The median, as a codec makes the encoder misread a few frames by far:
    the one-step mean squared error, dominated by them, was not even monotone in the crf (on 10 held-out sequences),
    while the median rose at every rung.

    Measured on 10 recordings written to H.264 at crf 16 to 28 and imported: the matched crf came out 1 to 3 above the
    true one, and the floor of the clean ones 1.3-2.6x their own error (the twin an import gets is drawn by the model's
    decoder, whose smoother picture the codec and the encoder treat otherwise; Gymnasium's own picture, filmed so at
    the true crf, gave 0.94x). So the floor errs high, towards "no significant gap", which
    :func:`piga.diagnostics.diagnose._through_a_codec` says beside that verdict. The recording's residual also holds
    what the corrected model still gets wrong, which moves the median little (a friction of 0.15 is 0.45 rad/s²
    against a median residual of about 6 rad/s² at crf 28).
    """
    below, crf_below = clean, None
    if not math.isfinite(residual) or not residual > clean.residual:
        return clean, None
    for crf in CODEC_LADDER:
        above = floor_at(crf)
        if above.residual >= residual:
            share = (residual - below.residual) / (above.residual - below.residual)
            mix = lambda a, b: a + share * (b - a)  # noqa: E731
            crf_at = crf if crf_below is None else float(mix(crf_below, crf))
            return TwinFloor(mix(below.horizon, above.horizon), mix(below.windows, above.windows), residual), crf_at
        if above.residual > below.residual:  # (a rung that reads no noisier than the one before is passed over)
            below, crf_below = above, crf
    return below, crf_below


def calibrate_floor(floor: TwinFloor, one_step_mse: float) -> TwinFloor:
    """``floor`` scaled down to the recording's own vision noise: by ``one_step_mse`` (the corrected
    model's held-out one-step angle MSE on the recording) over the twin's one-step MSE, where that is
    below 1.

    The twin's model is exact, so its one-step error is vision noise alone, while the recording's also
    holds whatever the corrected model still gets wrong: the ratio overstates the recording's noise
    relative to the twin's, and the scaled floor errs high (towards less closure). Never scaled up.
    """
    twin_one_step = float(floor.horizon[0])
    if not (twin_one_step > 0 and math.isfinite(one_step_mse)):
        return floor
    scale = min(1.0, one_step_mse / twin_one_step)
    return TwinFloor(floor.horizon * scale, floor.windows * scale, floor.residual)


#: The nominal error must exceed the floor by this factor for a closure to mean something (below
#: it, the three errors differ by noise and their ratio can take any value).
MEASURABLE_GAP = 1.5


def gap_closure(nominal: float, corrected: float, floor: float) -> float | None:
    """Share of the gap above the floor that the correction closes: (nominal - corrected) / (nominal - floor)."""
    return float((nominal - corrected) / (nominal - floor)) if nominal - floor > 0 and math.isfinite(floor) else None


def mean_gap_closure(nominal: float, corrected: float, floor: float) -> float | None:
    """:func:`gap_closure` of the means over all windows: None where the nominal error is not measurably above the
    floor (a ratio of noise: 0.00073 nominal, 0.000626 corrected and a floor of 0.000729 rad² gave "13192%"), and 1
    (closed) where the corrected error is at or below the floor (1.0012 was quoted as 100.1%)."""
    if not nominal > MEASURABLE_GAP * floor:
        return None
    closure = gap_closure(nominal, corrected, floor)
    return None if closure is None else min(closure, 1.0)
