"""Evaluating a trained model on held-out sequences: parameters, frames, states, and plots.

This is the only training-side module that reads ``/states``, through
:func:`piga.data.schema.load_states`, and it does so only to *report* the encoder's angle error.

The model's angle convention relative to Gymnasium's: the encoder's centroid readout measures
the rod's direction counter-clockwise from straight up, as Gymnasium does. The physics learns an
offset φ such that upright is model angle -φ, so Gymnasium's θ = model θ + φ. The reported angle
error compares ``model θ + φ`` with the true θ, wrapped to [-π, π). It also reports the best
constant offset, to show how far the learned φ is from the best possible alignment.
"""

from __future__ import annotations

import math
import re

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from skimage.metrics import structural_similarity

from piga.data.schema import inspect_dataset, load_states, read_sequences
from piga.io.choices import check_choices
from piga.io.device import module_device
from piga.world.model import FrameModel, ObjectModel, PhysicsModel, frames_to_float
from piga.world.variants import NO_PHYSICS

#: Data-file parameter name -> model parameter name.
PARAMETER_NAMES = {"g": "g", "actuation_gain": "a", "damping": "b", "k": "k", "l": "l", "m": "m"}


@dataclass(frozen=True)
class EvalConfig:
    """What to evaluate."""

    split: Literal["train", "valid", "test"] = "test"
    """Split of held-out sequences."""
    extrapolate_frames: int | None = None
    """T_ext, frames predicted beyond T_pred (capped by the sequence length); None: the model's own
    (:attr:`piga.world.model.ModelConfig.extrapolate_frames`: 20, or 24 for gravity)."""
    max_sequences: int = 200
    """At most this many sequences (the first of the split)."""

    def __post_init__(self) -> None:
        check_choices(self)
        if self.max_sequences < 1:
            raise ValueError(f"EvalConfig.max_sequences must be >= 1, got {self.max_sequences}")

    def frames_after_input(self, model: FrameModel, sequence_steps: int) -> int:
        """T_pred + T_ext frames to predict after the L input frames, capped by the sequence length."""
        cfg = model.config
        ext = cfg.extrapolate_frames if self.extrapolate_frames is None else self.extrapolate_frames
        return min(cfg.pred_frames + ext, sequence_steps - cfg.input_frames)


def fixed_parameters(model: PhysicsModel) -> dict[str, float]:
    """The physical parameters held at a given value (gravity's g in the m run), the offset apart."""
    learned = set(model.learned_parameter_names())
    return {name: value for name, value in model.physical_parameters().items() if name not in learned and name != "offset"}


def applied_params(params: dict[str, Any], effects: Any) -> dict[str, Any]:
    """A file's true ``params`` as its frames show them: a ``gain`` effect (``piga-collect --effect gain=0.2``) scales
    the actuation gain the env applies, so a model that learned a = 0.21 from such frames was scored 79% off a true 1.
    ``effects``: the file's ``effects`` attribute as :class:`~piga.data.schema.DatasetInfo` decodes it (a dict;
    anything else: no effect)."""
    gain = effects.get("gain") if isinstance(effects, dict) else None
    if "actuation_gain" not in params or not isinstance(gain, (int, float)) or not math.isfinite(gain):
        return params
    return {**params, "actuation_gain": float(params["actuation_gain"]) * float(gain)}


def parameter_errors(model: PhysicsModel, true_params: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Learned vs true physical parameters, with relative errors, for every learned parameter the file knows.

    A parameter held fixed (gravity's g in the m run) is not reported here: it was given, not learned.
    The true a carries the file's ``actuation_sign`` (-1 for a flipped camera or motor: the frames
    show the actuation reversed), so a model that learned a > 0 from flipped frames is ~200% off.
    """
    learned = model.physical_parameters()
    names = set(model.learned_parameter_names())
    out: dict[str, dict[str, float]] = {}
    for file_name, model_name in PARAMETER_NAMES.items():
        if file_name in true_params and model_name in names:
            true = float(true_params[file_name])
            if file_name == "actuation_gain":
                true *= float(true_params.get("actuation_sign", 1.0))
            out[model_name] = {"learned": learned[model_name], "true": true,
                               # a true value of 0 has no relative scale: any other learned value is infinitely off
                               "relative_error": abs(learned[model_name] - true) / abs(true) if true
                               else (0.0 if learned[model_name] == 0 else math.inf)}
    return out


#: Sequences evaluated at a time.
EVAL_BATCH = 8


@torch.no_grad()
def rollout_frames(model: FrameModel, frames: np.ndarray, actions: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicts ``steps`` frames after the first L of each sequence.

    Args:
        frames: uint8 [B, T, H, W(, C)], T >= L.
        actions: float32 [B, T, A].
        steps: frames to predict.

    Returns:
        Predicted frames, float [B, steps, C, H, W] in [0, 1] (video-lstm's, unsquashed, may stray a little
        outside), and their coordinates [B, steps, N, D] (None
        for a model without object coordinates), computed on the model's device.
    """
    cfg = model.config
    device = module_device(model)
    x = frames_to_float(torch.from_numpy(frames[:, : cfg.input_frames]).to(device), cfg.channels)  # (B, L, C, H, W)
    acts = None
    if cfg.action_dim:
        acts = torch.from_numpy(actions[:, : cfg.input_frames - 1 + steps]).float().to(device)  # (B, L-1+S, A)
    pred, coords = model.predict_frames(x, acts, steps)
    return pred.cpu().numpy(), None if coords is None else coords.cpu().numpy()


def _ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM of two (C, H, W) images in [0, 1] (scikit-image, channel axis 0)."""
    if a.shape[0] == 1:
        return float(structural_similarity(a[0], b[0], data_range=1.0))
    return float(structural_similarity(a, b, data_range=1.0, channel_axis=0))


@torch.no_grad()
def evaluate(model: FrameModel, data: str | Path, config: EvalConfig = EvalConfig()) -> dict[str, Any]:
    """Metrics of a trained model on held-out data (see ``metrics.json`` in the README)."""
    model.eval()
    cfg = model.config
    info = inspect_dataset(data)
    frames, actions = read_sequences(data, config.split, limit=config.max_sequences)
    if len(frames) == 0:
        raise ValueError(f"{data}: split '{config.split}' is empty; nothing to evaluate")
    steps = config.frames_after_input(model, info.steps)
    squared = np.zeros(steps)  # (S,) summed squared errors
    blank = 0.0  # summed squared errors of the background alone over the prediction frames
    hold = 0.0  # and of the last input frame held still
    n_pred = min(cfg.pred_frames, steps)
    background = model.background_image().detach().cpu().numpy()  # (C, H, W)
    ssims: list[list[float]] = []  # (B, S)
    for first in range(0, len(frames), EVAL_BATCH):  # in batches: the memory stays bounded whatever max_sequences is
        part = slice(first, first + EVAL_BATCH)
        pred, _ = rollout_frames(model, frames[part], actions[part], steps)  # (b, S, C, H, W)
        truth = frames_to_float(torch.from_numpy(frames[part, cfg.input_frames : cfg.input_frames + steps]), cfg.channels).numpy()
        squared += ((pred - truth) ** 2).sum(axis=(0, 2, 3, 4), dtype=np.float64)
        blank += float(((background - truth[:, :n_pred]) ** 2).sum(dtype=np.float64))
        last = frames_to_float(torch.from_numpy(frames[part, cfg.input_frames - 1 : cfg.input_frames]), cfg.channels).numpy()  # (b, 1, C, H, W)
        hold += float(((last - truth[:, :n_pred]) ** 2).sum(dtype=np.float64))
        ssims += [[_ssim(pred[b, t], truth[b, t]) for t in range(steps)] for b in range(len(pred))]
    mse = squared / (len(frames) * int(np.prod(pred.shape[2:])))  # (S,)
    ssim = np.array(ssims).mean(0)  # (S,)
    predicted_values = len(frames) * n_pred * int(np.prod(pred.shape[2:]))  # pixel values over the prediction frames
    result: dict[str, Any] = {
        "data": str(data),
        "split": config.split,
        "model": cfg.architecture,
        "loss": cfg.loss,
        "decoder": cfg.decoder,
        "sequences": int(len(frames)),
        "input_frames": cfg.input_frames,
        "pred_frames": n_pred,
        "extrapolate_frames": steps - n_pred,
        **physical_parameters_record(model, applied_params(info.params, info.attrs.get("effects"))),
        "frame_mse_per_step": mse.tolist(),
        "frame_ssim_per_step": ssim.tolist(),
        "frame_ssim_mean": {"prediction": float(ssim[:n_pred].mean()),
                            "extrapolation": float(ssim[n_pred:].mean()) if steps > n_pred else None},
        "frame_mse_mean": {"prediction": float(mse[:n_pred].mean()),
                           "extrapolation": float(mse[n_pred:].mean()) if steps > n_pred else None},
        # the error of predicting the model's label-free background alone, for the check of a model without physics
        "frame_mse_background": blank / predicted_values,
        # and of a system that stands still: the last input frame held over the predicted ones
        "frame_mse_hold": hold / predicted_values,
    }
    if info.has_states and cfg.system == "pendulum" and isinstance(model, ObjectModel):
        result["angle"] = angle_errors(model, frames, load_states(data, config.split, limit=config.max_sequences))
    return result


def physical_parameters_record(model: FrameModel, true_params: dict[str, Any]) -> dict[str, Any]:
    """metrics.json's parameters: ``parameters``, ``parameter_errors`` and ``fixed_parameters`` for a model with
    physics; for a baseline without (:data:`piga.world.variants.NO_PHYSICS`), ``parameters`` null,
    ``physical_parameters`` null and ``physical_parameters_reason`` saying why, rather than any made-up value."""
    if isinstance(model, PhysicsModel):
        return {"parameters": model.physical_parameters(), "parameter_errors": parameter_errors(model, true_params),
                "fixed_parameters": fixed_parameters(model)}
    return {"parameters": None, "physical_parameters": None,
            "physical_parameters_reason": NO_PHYSICS[model.config.architecture]}


@torch.no_grad()
def angle_errors(model: ObjectModel, frames: np.ndarray, states: np.ndarray) -> dict[str, float]:
    """Encoder angle (plus the learned offset φ) against the true θ; evaluation only.

    Returns mean and 90th-percentile absolute errors in degrees, with the learned φ and with the
    best constant offset, and that best offset.
    """
    cfg = model.config
    device = module_device(model)
    theta = np.concatenate([model.encode(frames_to_float(torch.from_numpy(frames[i : i + EVAL_BATCH]), cfg.channels).to(device))
                            [..., 0, 0].cpu().numpy() for i in range(0, len(frames), EVAL_BATCH)])  # (B, T)
    phi = model.physical_parameters().get("offset", 0.0)
    diff = np.angle(np.exp(1j * (states[..., 0] - theta - phi)))  # true - (model + φ), wrapped
    # the constant offset that minimises the mean absolute error: the median of the differences, taken around their
    # circular mean (the circular mean alone minimises the squared error, and left the "best" offset's mean absolute
    # error above the learned one's)
    centre = float(np.angle(np.mean(np.exp(1j * diff))))
    best = float(np.angle(np.exp(1j * (centre + np.median(np.angle(np.exp(1j * (diff - centre))))))))
    resid = np.angle(np.exp(1j * (diff - best)))
    return {
        "mean_abs_error_deg": float(np.degrees(np.abs(diff)).mean()),
        "p90_abs_error_deg": float(np.degrees(np.percentile(np.abs(diff), 90))),
        "learned_offset_rad": float(phi),
        "best_extra_offset_deg": float(np.degrees(best)),
        "mean_abs_error_after_best_offset_deg": float(np.degrees(np.abs(resid)).mean()),
        "convention": "gymnasium_theta = model_theta + offset (both counter-clockwise from upright)",
    }


def true_and_error(error: dict[str, Any]) -> str:
    """A parameter's true value and relative error (:func:`parameter_errors`, or as metrics.json stores it) in words:
    "true 10, error 1.79%"; a true value of 0 has no relative error, so "true 0" alone."""
    if error["true"] == 0 or error["relative_error"] is None:
        return f"true {error['true']:g}"
    return f"true {error['true']:g}, error {100 * error['relative_error']:.2f}%"


def summary_line(metrics: dict[str, Any]) -> str:
    """One line: learned parameters with their errors (or why there are none)."""
    if metrics.get("parameters", {}) is None:
        return f"no physical parameters ({metrics.get('physical_parameters_reason', 'none recorded')})"
    flat = set((metrics.get("convergence") or {}).get("undetermined") or ())  # flat profiles: not determined
    note = "; not determined by the training frames: its profile is flat"
    errors = metrics.get("parameter_errors", {})
    parts = [f"{name}={e['learned']:.4f} ({true_and_error(e)}{note if name in flat else ''})" for name, e in errors.items()]
    # beside those, the learned ones the file gives no true value for (its params may name only some): all of them
    # where it gives none, the offset included, and the offset wherever the convergence verdict names it (a warning
    # "offset moved ..." beside a line that did not show it)
    named = re.search(r"\boffset\b", (metrics.get("convergence") or {}).get("reason") or "")
    skipped = {*errors, *metrics.get("fixed_parameters", {}), *([] if named else ["offset"])} if errors else set()
    parts += [f"{k}={v:.4f}" + (f" ({note[2:]})" if k in flat else "") for k, v in metrics.get("parameters", {}).items()
              if k not in skipped]
    return ", ".join(parts) or "no parameter (none to learn)"

