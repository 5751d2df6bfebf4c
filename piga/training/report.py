"""Everything ``piga-train-model`` leaves in RUN_DIR after training: metrics.json and the figures."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from piga.data.schema import DatasetInfo, inspect_dataset, read_sequences
from piga.evaluation.evaluate import PARAMETER_NAMES, EvalConfig, applied_params, evaluate, rollout_frames
from piga.world.model import FrameModel, ModelConfig, ObjectModel, PhysicsModel, frames_to_float
from piga.world.variants import MODELS
from piga.evaluation.plots import curves_figure, rollout_figure, save_figure, templates_figure
from piga.io.atomic import write_json
from piga.io.device import module_device
from piga.evaluation.objects import ObjectCheck, check_objects
from piga.evaluation.profile import PROFILE_SEQUENCES, parameter_profile, profile_dict
from piga.training.convergence import check_convergence
from piga.training.train import TrainState


def _image(x: np.ndarray) -> np.ndarray:
    """(C, H, W) -> (H, W) or (H, W, C)."""
    return x[0] if x.shape[0] == 1 else np.moveaxis(x, 0, -1)


#: The fewest warm-up steps after which ``piga-train-model`` checks a scene's objects before the end of a run: the
#: autoencoder has trained enough by then that a found object reads far below the threshold (0.03-0.06 of the
#: objects' contrast at ~300 steps, in results/regions_warmup.md); after a few steps nothing is drawn yet.
WARMUP_CHECK_MIN_STEPS = 250


def checks_objects(config: ModelConfig) -> bool:
    """Whether :func:`scene_objects` checks a model of ``config``: one with object slots of image coordinates (not
    the pendulum's angle, nor a black-box video model)."""
    return issubclass(MODELS[config.architecture], ObjectModel) and config.coord_dim == 2


@torch.no_grad()
def scene_objects(model: FrameModel, data: str | Path, eval_config: EvalConfig = EvalConfig(),
                  frames: np.ndarray | None = None, info: DatasetInfo | None = None) -> ObjectCheck | None:
    """Did the autoencoder find each object of a scene? :func:`~piga.evaluation.objects.check_objects` on the frames
    that the run's report is measured on (``frames``, when already read: the eval split's, or the train split's for a
    file without it), with the model's slots and the file's object count (``info``: the file's
    :func:`~piga.data.schema.inspect_dataset`, when already read); None for a model that has no objects (the
    pendulum's angle, a black-box video model). Reads and changes nothing of the model: a run checked in the middle
    of its training trains on exactly as it would have."""
    if not checks_objects(model.config):
        return None
    info = inspect_dataset(data) if info is None else info
    if frames is None:
        split = eval_config.split if info.split_counts.get(eval_config.split) else "train"
        frames = read_sequences(data, split, limit=eval_config.max_sequences)[0]
    scene = info.attrs.get("n_objects")  # the file's count, to compare with the model's slots (--objects)
    return check_objects(model, frames).with_counts(model.config.n_objects, None if scene is None else int(scene))


@torch.no_grad()
def write_run_report(model: FrameModel, state: TrainState, data: str | Path, run_dir: str | Path,
                     eval_config: EvalConfig = EvalConfig(),
                     physics_lr: Callable[[int], float] | None = None) -> dict[str, Any]:
    """Evaluates on held-out data and writes metrics.json, rollout.png, templates.png and curves.png.

    A model without object coordinates (video-lstm) or with the black-box MLP decoder has no templates to draw (no templates.png) and no objects
    to check; a model without physical parameters has only its losses in curves.png.

    For a run that recorded its plan, metrics.json also holds the convergence check
    (:func:`piga.training.convergence.check_convergence`): ``converged`` (true or false) and ``convergence``
    (the outcome, its reason and each parameter's trajectory summary). For a scene of objects it holds
    ``objects`` (:func:`piga.evaluation.objects.check_objects`), and a lost object makes the outcome
    ``untrained``: the physics fitted the objects that were found, and its parameters mean nothing.
    ``physics_lr``: the physical parameters' learning rate at a step (:func:`piga.training.train.physics_lr`), for
    the check of a parameter still moving as fast as it allows when the schedule ended.
    """
    run_dir = Path(run_dir)
    info = inspect_dataset(data)
    split = eval_config.split if info.split_counts.get(eval_config.split) else "train"
    if split != eval_config.split:
        eval_config = EvalConfig(split=split, extrapolate_frames=eval_config.extrapolate_frames,
                                 max_sequences=eval_config.max_sequences)
    metrics = evaluate(model, data, eval_config)
    frames, actions = read_sequences(data, split, limit=eval_config.max_sequences)
    objects = scene_objects(model, data, eval_config, frames, info)
    if objects is not None:
        metrics["objects"] = objects.to_dict()
    metrics["training"] = {"epochs": state.epoch, "steps": state.step, "seconds": state.elapsed,
                           "threads": torch.get_num_threads(), "device": state.device or None}
    if state.plan:
        blank = (metrics["frame_mse_mean"]["prediction"], metrics["frame_mse_background"])
        profile = None
        if isinstance(model, PhysicsModel) and state.start:
            train_frames, train_actions = read_sequences(data, "train", limit=PROFILE_SEQUENCES)
            if len(train_frames):
                profile = parameter_profile(model, train_frames, train_actions)
                metrics["profile"] = profile_dict(profile)
        convergence = check_convergence(state, objects=objects, blank=blank, hold=metrics["frame_mse_hold"],
                                        profile=profile, held_out=split != "train", physics_lr=physics_lr)
        metrics["converged"] = convergence.converged
        metrics["convergence"] = convergence.to_dict()
    write_json(run_dir / "metrics.json", metrics)

    frames, actions = frames[:3], actions[:3]
    cfg = model.config
    steps = eval_config.frames_after_input(model, info.steps)
    pred, _ = rollout_frames(model, frames, actions, steps)
    truth = frames_to_float(torch.from_numpy(frames[:, cfg.input_frames : cfg.input_frames + steps]), cfg.channels).numpy()
    to_img = lambda a: np.stack([[_image(f) for f in seq] for seq in a])  # noqa: E731
    save_figure(rollout_figure(to_img(truth), to_img(pred), cfg.input_frames, cfg.pred_frames), run_dir / "rollout.png")
    if isinstance(model, ObjectModel) and model.has_templates:
        save_figure(templates_figure(*template_images(model)), run_dir / "templates.png")
    applied = applied_params(info.params, info.attrs.get("effects"))
    true = {PARAMETER_NAMES[k]: float(v) for k, v in applied.items() if k in PARAMETER_NAMES}
    if state.history:
        save_figure(curves_figure(state.history, true), run_dir / "curves.png")
    return metrics


@torch.no_grad()
def template_images(model: ObjectModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The templates figure's images: each object's content and mask, the background and its mask."""
    cfg = model.config
    # What the decoder composes for each object at the reference pose (θ = 0, or the image centre),
    # drawn alone (the other objects far off the picture): its transformed content and its mask after
    # the softmax against the background.
    n, d = cfg.n_objects if cfg.system != "pendulum" else 1, cfg.coord_dim
    device = module_device(model)
    contents, masks = [], []
    for i in range(n):
        pose = torch.zeros(1, n, d) if d == 1 else torch.full((1, n, d), -10.0 * cfg.image_size)  # (1, N, D)
        if d == 2:
            pose[0, i] = cfg.image_size / 2
        parts = model.decoder.render_parts(pose.to(device))
        contents.append(_image(parts.contents[0, i].cpu().numpy()))  # (H, W[, C])
        masks.append(parts.masks[0, i, 0].cpu().numpy())  # (H, W)
    away = torch.full((1, n, d), -10.0 * cfg.image_size) if d == 2 else torch.zeros(1, n, d)  # (1, N, D)
    background_mask = model.decoder.render_parts(away.to(device)).masks[0, -1, 0].cpu().numpy()
    background = _image(parts.background.cpu().numpy())
    return np.stack(contents), np.stack(masks), background, background_mask
