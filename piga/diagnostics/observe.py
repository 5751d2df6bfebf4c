"""What the identified model sees in a recording: encoded angles, actions and reconstruction errors.

The diagnosis never reads ``/states`` or the file's ``effects`` attribute. Everything it knows
about the "real" system comes from here: the frames go through the model's encoder (angles in the
model's convention; Gymnasium's θ = model θ + φ) and its decoder (how well the autoencoder alone
explains each frame).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from envs import DMC_PENDULUM, PIXEL_PENDULUM
from envs.fields import counted
from piga.data.schema import SPLITS, DatasetInfo, check_actions, inspect_dataset, open_data_file, read_rows, split_indices
from piga.diagnostics.repeats import stale_frames
from piga.world.model import PhysicsModel, frames_to_float
from piga.io.runs import training_steps


class DiagnosisInputError(ValueError):
    """The model and the data cannot be compared (different systems, sizes, too little data...)."""


class UntrainedModelError(DiagnosisInputError):
    """The run's training clearly failed: its autoencoder does not draw the scene it was trained on."""


class NotTheSceneError(DiagnosisInputError):
    """The recording is not the scene the model knows: it re-renders it far worse than its training frames."""


def check_training(checkpoint: dict[str, Any] | None, rec_training: float, blank: float | None,
                   max_fraction: float, blank_of_recording: bool = False) -> None:
    """Refuses a run whose training clearly failed (:class:`UntrainedModelError`).

    Args:
        checkpoint: the run's checkpoint (its step count).
        rec_training: the model's per-frame reconstruction MSE in its last epoch
            (:func:`piga.io.runs.training_reconstruction_mse`; 0: not recorded).
        blank: the error scale: the MSE of the frames against the model's background, a render
            that draws no pendulum (:func:`piga.io.runs.training_blank_mse`); None: unknown.
        max_fraction: refuse when ``rec_training`` exceeds this fraction of ``blank``.
        blank_of_recording: ``blank`` is the recording's (the run's training file is not found): the line says so.
    """
    steps = training_steps(checkpoint)
    if steps == 0:
        raise UntrainedModelError("the model was never trained (its run took no optimiser step); train it first")
    warmup = ((checkpoint or {}).get("plan") or {}).get("warmup_steps", 0)
    if steps is not None and steps <= warmup:
        raise UntrainedModelError(f"the model's physics was never trained: all {steps} steps of its run were "
                                  f"autoencoder warm-up ({warmup} steps); train it longer")
    if not rec_training or not math.isfinite(rec_training):
        raise UntrainedModelError("the checkpoint records no finite reconstruction error, so the model's training "
                                  "cannot be checked; use a run of piga-train-model")
    if blank is not None and rec_training > max_fraction * blank:
        where = (" in the recording's frames, as its training file is not found from here (--training-data gives it)"
                 if blank_of_recording else "")
        raise UntrainedModelError(
            f"the model's training failed: it re-renders its training frames with MSE {rec_training:.3g}, "
            f"{rec_training / blank:.2g}x the error of drawing no pendulum at all ({blank:.3g}{where}); train it "
            "longer")


def check_scene(obs: Observations, rec_training: float, max_ratio: float) -> None:
    """Refuses a recording that is not the scene the model knows (:class:`NotTheSceneError`): its mean
    re-rendering error is more than ``max_ratio`` times the model's training error."""
    rec_real = float(np.mean(obs.rec_mse))
    if rec_training > 0 and not rec_real <= max_ratio * rec_training:  # NaN is refused too
        raise NotTheSceneError(
            f"this is not the scene the model knows: it re-renders these frames with MSE {rec_real:.3g}, "
            f"{rec_real / rec_training:.0f}x its training error {rec_training:.3g} (the limit is {max_ratio:g}x)")


def check_noise_explains(rec_real: float, rec_training: float, noise: float, max_ratio: float) -> None:
    """Refuses, in its own words, a recording refused as another scene (:func:`check_scene`) whose re-rendering error
    the sensor noise measured on its still pixels (``noise``, gray levels σ; 0: none named) explains: noise of σ adds
    at most (σ/255)² to a frame's MSE (a clip at the white background censors about half of it; measured with a
    default model, training MSE 3.9e-4: 0.54 to 0.62 of (σ/255)² at noise 50 to 80). Nothing is raised otherwise.

    The line names the largest noise this model reads: the σ at which the same share of (σ/255)² meets the limit,
    from this recording's own share (measured with that model: noise 60 re-renders at 83x and is diagnosed as noise
    59.6; noise 70 at 108x and 80 at 137x are refused; the line reads 65, 66 and 67 from the three).
    """
    excess = rec_real - rec_training
    if not (noise > 0 and rec_training > 0 and 0 < excess <= (noise / 255) ** 2):
        return
    readable = noise * math.sqrt((max_ratio - 1) * rec_training / excess)
    raise NotTheSceneError(
        f"these frames are too noisy to read: sensor noise of about {noise:.3g} gray levels (σ) has the model re-render "
        f"them with MSE {rec_real:.3g}, {rec_real / rec_training:.0f}x its training error {rec_training:.3g} (the limit "
        f"is {max_ratio:g}x); it reads noise up to about {math.floor(readable):d} gray levels: record with less sensor "
        "noise (more light, a lower gain), or average or denoise the frames")


@dataclass(frozen=True)
class Observations:
    """A recording as the model sees it. N sequences of T frames."""

    theta: np.ndarray
    """(N, T) float64 encoded angle, model convention, unwrapped along time."""
    actions: np.ndarray
    """(N, T) float64 commanded action u_t, applied after frame t."""
    rec_mse: np.ndarray
    """(N, T) float64 MSE of the decoder's re-rendering of each frame (pixels in [0, 1])."""
    fit: np.ndarray
    """(N,) bool: the sequence is in the fit split (the file's train split); the rest is held out."""
    dt: float
    """Seconds between frames."""
    frames: np.ndarray
    """(n, T, H, W) uint8 a few held-out sequences' frames, for pixel errors and pictures."""
    frames_index: np.ndarray
    """(n,) indices into N of ``frames``."""
    stale: np.ndarray | None = None
    """(N, T) bool: frame t repeats frame t - 1 (within 2 gray levels, :func:`~piga.diagnostics.repeats.stale_frames`); None: not known."""
    blank_mse: float | None = None
    """Mean per-frame MSE of the frames against the model's background (a render of no object); None: not known."""
    from_gymnasium: bool = True
    """The file says it was collected from Gymnasium's pendulum (``env_id``, or an ``env_config`` of
    :class:`envs.pendulum.PixelPendulumConfig`): only then is a clip at 8 rad/s Gymnasium's own."""
    impossible: dict[str, str] = field(default_factory=dict)
    """Effects that the system which made the file cannot have, by its attrs (:func:`impossible_effects`), and why."""
    damping_taken: str | None = None
    """How the system that made the file takes a damping, by its attrs (:func:`damping_taken`): "implicit"
    (MuJoCo's Euler, dm_control), "explicit" (a torque added before the step, Gymnasium's), None: not known."""
    damping_step: float | None = None
    """The physics step (s) at which that system takes it, where several make a frame (:func:`damping_step`)."""
    lossy_source: str | None = None
    """The video that piga-import read the frames from, where its format compresses with loss (:func:`lossy_source`);
    None: another source, or none said."""


#: The fewest sequences a recording gives the diagnosis.
MIN_SEQUENCES = 20


def check_compatible(model: PhysicsModel, path: str | os.PathLike[str], min_sequences: int = MIN_SEQUENCES,
                     min_steps: int = 12) -> DatasetInfo:
    """The file's info; raises :class:`DiagnosisInputError` with one clear line when ``model`` cannot diagnose ``path``."""
    info = inspect_dataset(path)
    cfg = model.config
    if cfg.system != "pendulum":
        raise DiagnosisInputError(f"the model is a {cfg.system} model; piga-diagnose handles the pendulum")
    if info.system != cfg.system:
        raise DiagnosisInputError(f"{path}: data of system {info.system!r}, but the model is a {cfg.system} model")
    if info.image_shape[:2] != (cfg.image_size, cfg.image_size) or info.channels != cfg.channels:
        fix = (f"; import or collect them at --image-size {cfg.image_size} (piga-import, piga-collect)"
               if info.channels == cfg.channels else "")
        raise DiagnosisInputError(f"{path}: frames are {info.image_shape}, the model takes {cfg.image_size}x{cfg.image_size} "
                                  f"with {cfg.channels} channel(s){fix}")
    if info.action_dim != 1:
        raise DiagnosisInputError(f"{path}: needs one action per step (the pendulum's torque), found {info.action_dim}")
    if abs(info.dt - cfg.dt) > 1e-9 * max(1.0, cfg.dt):
        step = damping_step(info.attrs)  # a simulator's frames are whole physics steps: the repeat that makes cfg.dt
        again = (f"--env-option action_repeat={round(cfg.dt / step)}" if step and round(cfg.dt / step) >= 1
                 and math.isclose(round(cfg.dt / step) * step, cfg.dt) else f"frames {cfg.dt:g} s apart")
        raise DiagnosisInputError(f"{path}: frame interval {info.dt:g} s, the model was trained at {cfg.dt:g} s; record "
                                  f"again with {again}, or identify a model on frames of this interval")
    if info.steps < min_steps:
        raise DiagnosisInputError(f"{path}: sequences of {info.steps} frames; the diagnosis needs at least {min_steps}")
    if info.n_sequences < min_sequences:
        raise DiagnosisInputError(f"{path}: {counted(info.n_sequences, 'sequence')}; the diagnosis needs at least "
                                  f"{min_sequences}")
    n_fit = len(split_indices(path, "train"))
    # Half of the minimum to fit, a fifth held out: the minimum of 20 sequences at piga-collect's default
    # split (0.8, 0.1, 0.1) gives 16 and 4, so the smallest file that collect makes by default is accepted.
    min_fit, min_held_out = min_sequences // 2, max(1, min_sequences // 5)
    if n_fit < min_fit or info.n_sequences - n_fit < min_held_out:
        n = info.n_sequences
        fix = ""  # the file's own split decides: piga-collect or piga-import writes another
        if n >= min_fit + min_held_out:  # (the shortfall named: 9 train and 11 held out were told to hold out 4)
            short = (f"trains on at least {min_fit}" if n_fit < min_fit else f"holds out at least {min_held_out}")
            fix = (f"; collect or import it again with a split that {short}, such as --split "
                   f"{n - min_held_out},{min_held_out // 2},{min_held_out - min_held_out // 2}")
        raise DiagnosisInputError(f"{path}: {n_fit} train and {n - n_fit} held-out sequences; "
                                  f"need at least {min_fit} and {min_held_out}{fix}")
    return info


@torch.no_grad()
def read_frames(model: PhysicsModel, raw: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """What the encoder reads from (B, T, H, W[, C]) uint8 frames ``raw``: the frames as floats
    (B, T, C, H, W), the coordinates (B, T, 1, 1) and the angles (B, T), unwrapped along time."""
    x = frames_to_float(torch.from_numpy(raw), model.config.channels)
    coords = model.encode(x)
    return x, coords, np.unwrap(coords[..., 0, 0].double().numpy(), axis=1)


@torch.no_grad()
def observe(model: PhysicsModel, path: str | os.PathLike[str], batch: int = 16, keep_frames: int = 40,
            progress: bool = False) -> Observations:
    """Encodes and re-renders every frame of ``path`` with ``model``.

    Args:
        model: the identified pendulum model (eval mode).
        path: a piga HDF5 file with frames and actions (``/states`` is never read).
        batch: sequences per forward pass.
        keep_frames: held-out sequences whose frames are kept for pixel errors.
    """
    from tqdm.auto import tqdm

    info = check_compatible(model, path)
    with open_data_file(path) as f:
        split = f["split"][:] if "split" in f else np.zeros(info.n_sequences, np.int8)
        n = info.n_sequences
        theta = np.empty((n, info.steps))
        rec = np.empty((n, info.steps))
        blank = np.empty((n, info.steps))
        stale = np.empty((n, info.steps), bool)
        actions = f["actions"][:, :, 0].astype(np.float64)
        held = np.flatnonzero(split != SPLITS["train"])
        keep = held[:keep_frames]
        for start in tqdm(range(0, n, batch), desc="encoding", disable=not progress):
            with read_rows(f["frames"], f"sequences {start}-{min(start + batch, n) - 1}"):
                raw = f["frames"][start : start + batch]
            stale[start : start + batch] = stale_frames(raw)
            x, coords, theta[start : start + batch] = read_frames(model, raw)
            rec[start : start + batch] = ((model.decoder(coords) - x) ** 2).mean(dim=(2, 3, 4)).double().numpy()
            blank[start : start + batch] = ((x - model.encoder.background) ** 2).mean(dim=(2, 3, 4)).double().numpy()
        with read_rows(f["frames"], "the held-out sequences kept for the report"):
            frames = f["frames"][np.sort(keep)] if len(keep) else np.zeros((0, info.steps, *info.image_shape), np.uint8)
        attrs = dict(f.attrs)
    check_actions(actions, path)
    return Observations(theta, actions, rec, split == SPLITS["train"], float(info.dt), frames, np.sort(keep), stale,
                        float(blank.mean()), from_gymnasium(attrs), impossible_effects(attrs), damping_taken(attrs),
                        damping_step(attrs), lossy_source(attrs))


#: Video containers whose usual codecs (H.264, VP9, MPEG-4 ...) compress with loss: frames read from them carry the
#: codec's errors, which a twin drawn without them lacks.
LOSSY_VIDEO = (".mp4", ".m4v", ".mov", ".avi", ".mkv", ".webm", ".wmv", ".flv", ".mpg", ".mpeg", ".ogv", ".3gp")


def lossy_source(attrs: dict) -> str | None:
    """The file's ``source`` (piga-import's: the recording it read), where its name says a lossy video format."""
    source = attrs.get("source")
    source = source.decode() if isinstance(source, bytes) else source
    return source if isinstance(source, str) and source.lower().endswith(LOSSY_VIDEO) else None


def from_gymnasium(attrs: dict) -> bool:
    """Whether a file's attributes say it was collected from Gymnasium's pendulum (piga-collect's
    ``env_id``, or, in files from before it, an ``env_config`` with the pixel pendulum's torque arrow)."""
    import json

    env_id = attrs.get("env_id")
    if env_id is not None:
        return str(env_id) == "piga/PixelPendulum-v0"
    config = attrs.get("env_config", {})
    try:  # (a file's raw attribute is JSON text; piga.data.schema.inspect_dataset's attrs hold it parsed)
        config = json.loads(config) if isinstance(config, (str, bytes)) else config
    except ValueError:
        return False
    return isinstance(config, dict) and "draw_torque_arrow" in config


#: Effects that a simulator cannot produce, by the env id that piga-collect writes into a file's attrs.
IMPOSSIBLE: dict[str, dict[str, str]] = {
    DMC_PENDULUM: {"speed_clip": "dm_control has no speed clip"},
    # (a blur of 2.6 px with 5% of the frames dropped read "the system integrates within the frame", 2 substeps, on one
    # seed of two: its BIC drop 36.7, its typical free-run drop 11.9%, just past the 10% asked)
    PIXEL_PENDULUM: {"within_frame": "Gymnasium's pendulum takes one step per frame, and piga-collect repeats no action "
                                     "there"},
}


#: How a simulator takes a damping, by the env id that piga-collect writes into a file's attrs.
DAMPING_TAKEN: dict[str, str] = {
    DMC_PENDULUM: "implicit",  # (MuJoCo's Euler: q̇ <- (q̇ + h·f) / (1 + h·r))
    PIXEL_PENDULUM: "explicit",  # (Gymnasium's step, with piga's effect wrappers' torques added before it)
}


def env_id_of(attrs: dict) -> str | None:
    """The env id that made a file: its ``env_id``, or, in files from before it, dm_control's where an
    ``env_config`` has its ``action_repeat`` and Gymnasium's where it has the pixel pendulum's torque arrow."""
    import json

    env_id = attrs.get("env_id")
    if env_id is not None:
        return str(env_id)
    try:
        config = attrs.get("env_config", "{}")
        config = json.loads(config) if isinstance(config, (str, bytes)) else config
    except (TypeError, ValueError):
        return None
    if isinstance(config, dict) and "action_repeat" in config:
        return DMC_PENDULUM
    if isinstance(config, dict) and "draw_torque_arrow" in config:
        return PIXEL_PENDULUM
    return None


def damping_step(attrs: dict) -> float | None:
    """The physics step (s) of the system that made a file, where it takes a damping implicitly at each of several
    steps per frame (dm_control: :data:`~envs.dmc.DMC_PHYSICS_DT`, ``action_repeat`` steps per frame); None: one step
    per frame, or not known."""
    from envs.dmc import DMC_PHYSICS_DT

    return DMC_PHYSICS_DT if env_id_of(attrs) == DMC_PENDULUM else None


def system_substeps(dt: float, step: float | None) -> int:
    """The physics steps per frame of a system that takes ``step`` (s) per physics step (:func:`damping_step`) at
    frames of ``dt`` (s): the M that the ``within_frame`` effect is fitted at (:attr:`piga.diagnostics.fit.Windows.substeps`);
    0 where not known, or not a whole number of steps the effect can take."""
    from piga.world.effects import WITHIN_FRAME

    if not step:
        return 0
    m = round(dt / step)
    return m if 1 < m <= max(WITHIN_FRAME.grid) and abs(m * step - dt) <= 1e-6 * dt else 0


def damping_taken(attrs: dict) -> str | None:
    """How the system that made a file takes a damping (:data:`DAMPING_TAKEN`), by its attrs; None: not known
    (an imported video, a file whose hints were deleted)."""
    env_id = env_id_of(attrs)
    return None if env_id is None else DAMPING_TAKEN.get(env_id)


def impossible_effects(attrs: dict) -> dict[str, str]:
    """Effects that the system which made a file cannot have, by its attrs (``env_id``, or an
    ``env_config`` with dm_control's ``action_repeat``), and why: a dm_control file has no speed clip, a Gymnasium
    file no motion within the frame.

    Only simulators' own physics is excluded: an effect wrapper around the env could add any
    effect, so nothing else is. Empty for a file whose attrs say nothing (an imported video, a
    blind benchmark's file with its hints deleted).
    """
    return dict(IMPOSSIBLE.get(str(env_id_of(attrs)), {}))
