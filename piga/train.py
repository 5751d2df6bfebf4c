"""Training the world model on a data file: frames and actions only, never ``/states``.

The loop is one readable flow, in the style of cleanrl:

1. An autoencoder warm-up. For ``warmup_steps`` steps only α·L_rec trains the encoder and
   decoder, so that the coordinates mean something before the physics leans on them.
2. A rollout curriculum. The prediction horizon grows from 1 frame to T_pred over
   ``curriculum_steps``. Short rollouts keep the predicted object overlapping the true one, so the
   pixel loss has a gradient with respect to g and a even while they are far from the truth.
3. Physical parameters get their own learning rate (``lr_physics``), in log space.

Each epoch ends with an atomic checkpoint (``checkpoint.pt``). ``resume`` restores the model,
the optimiser, the step count and every RNG, and continues exactly where the run stopped. A
non-finite loss stops training with :class:`TrainingDiverged`, which names the last good
checkpoint.
"""

from __future__ import annotations

import math
import random
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from torch.utils.data import DataLoader, RandomSampler
from tqdm.auto import tqdm

from piga.atomic import atomic_output
from piga.data import DatasetInfo, check_actions_file, inspect_dataset, read_sequences
from piga.encoder import estimate_background
from piga.model import SYSTEM_SHAPES, ModelConfig, PhysicsModel, frames_to_float
from piga.runs import CHECKPOINT, load_model
from piga.windows import SequenceWindows


class TrainingDiverged(RuntimeError):
    """The loss became NaN or infinite; the message names the last good checkpoint."""


@dataclass(frozen=True)
class TrainConfig:
    """How to train. The defaults are the 'fast' recipe; other presets are in :data:`PRESETS`."""

    epochs: int = 16
    """Passes over the training windows (the cosine schedule is planned over all of them)."""
    max_minutes: float = 0.0
    """Safety wall-clock budget: stop after the first epoch that ends past it (0: no limit).
    Training results do not depend on it unless it cuts the run short."""
    batch_size: int = 32
    """Windows per step."""
    lr: float = 1e-3
    """Learning rate of the networks (encoder, velocity, decoder)."""
    lr_physics: float = 1e-2
    """Learning rate of the physical parameters (log space)."""
    optimizer: str = "adam"
    """'adam' or 'rmsprop' (the paper's)."""
    schedule: str = "cosine"
    """"cosine": after the warm-up, both learning rates follow a cosine from their value down to
    ``lr_final_fraction`` of it at the last planned step; "step": the paper's division by
    ``lr_decay_factor`` from ``lr_decay_epoch`` on."""
    lr_final_fraction: float = 0.01
    """Cosine schedule: final learning rate as a fraction of the initial one."""
    lr_decay_epoch: int = 0
    """Step schedule: divide the learning rates by ``lr_decay_factor`` from this epoch on (0: never)."""
    lr_decay_factor: float = 5.0
    """The paper divides by 5."""
    warmup_steps: int = 200
    """Steps of autoencoder-only training before the physics is used."""
    curriculum_steps: int = 600
    """Steps over which the prediction horizon grows from 1 to T_pred (0: full horizon at once)."""
    window_stride: int = 1
    """Start frames of training windows are this far apart within a sequence."""
    seed: int = 0
    """Seed of initialisation and sampling."""
    threads: int = 0
    """torch CPU threads (0: leave torch's default)."""
    grad_clip: float = 10.0
    """Gradient-norm clip of the networks (0: none)."""
    physics_grad_clip: float = 3.0
    """Adam only: clip each physical parameter's gradient to this many times its running RMS (0: off).
    One outlying batch otherwise inflates Adam's first moment long before the second catches up,
    and the next ~10 steps throw g and a several percent off (seen mid-training without it)."""
    average_final_epoch: bool = True
    """End with the physical parameters averaged (in log space) over the last epoch's steps:
    Polyak averaging, which removes most of the optimiser's step-to-step jitter."""


#: Named recipes, as overrides of the dataclass defaults. 'fast' is the defaults themselves
#: (:class:`TrainConfig`, :class:`ModelConfig`); 'paper' follows the paper's appendix.
PRESETS: dict[str, dict[str, Any]] = {
    "fast": {},
    "paper": {
        "train": {"epochs": 1000, "lr": 3e-4, "lr_physics": 3e-4, "optimizer": "rmsprop",
                  "schedule": "step", "lr_decay_epoch": 500, "warmup_steps": 0, "curriculum_steps": 0, "grad_clip": 0.0,
                  "average_final_epoch": False, "physics_grad_clip": 0.0},
        "model": {"substeps": 5, "learn_offset": True, "readout": "regress", "rec_frames": "all", "pred_trim": 0.0,
                  "velocity_correction": True},
    },
    # A continuous system filmed with a held action (a real motor, MuJoCo's 0.02 s physics steps):
    # RK4 within the frame, velocities read through it, and a learnable hinge damping.
    "continuous": {
        "model": {"integrator": "rk4", "substeps": 2, "velocity_hold": True, "learn_damping": True},
    },
}


#: The scenes' recipes (``fast`` and ``paper``), by the file's attr ``scene`` (else its ``system``).
#: What all ball and digit scenes share: templates of H/2 (the published decoder's), a pixelwise
#: mask term, the decoder's background content starting at the label-free median background, no
#: trimming (nothing unmodelled to trim), and the paper's velocity MLP on top of the backward
#: difference (at dt = 0.3 the difference alone is far from v_L: ω·dt ≈ 0.85 for the spring) with a
#: cubic Taylor term (``velocity_physics``), L = 4 input and T_pred = 6 predicted frames (the
#: published code's). Reading v_L through the engine instead (``velocity_shoot``) removes the ~1.5%
#: low bias that the cubic term leaves on k and g when fitted to true positions
#: (``benchmarks/velocity_bias.py``); it becomes the recipe once Table 1 is re-measured with it.
_SCENE_MODEL: dict[str, Any] = {"input_frames": 4, "pred_frames": 6, "pred_trim": 0.0, "velocity_correction": True,
                                "velocity_physics": True, "substeps": 5, "mask_pixelwise": True, "alpha": 2.0,
                                "init_background": True}
_SCENE_FAST_TRAIN: dict[str, Any] = {"epochs": 6, "warmup_steps": 300, "curriculum_steps": 600, "window_stride": 2}
_SCENE_PAPER: dict[str, Any] = {
    "train": {"epochs": 500, "lr": 3e-4, "lr_physics": 3e-4, "optimizer": "rmsprop", "schedule": "step",
              "lr_decay_epoch": 375, "warmup_steps": 0, "curriculum_steps": 0, "grad_clip": 0.0,
              "average_final_epoch": False, "physics_grad_clip": 0.0, "batch_size": 100},
    "model": {**_SCENE_MODEL, "readout": "regress", "rec_frames": "all"},
}
SCENE_PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    # Bouncing: nothing to learn; the wall distance is given, as the published engine hard-codes it.
    "bouncing": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 1.0, "wall_radius": 3.0}},
                 "paper": {"train": _SCENE_PAPER["train"], "model": {**_SCENE_PAPER["model"], "wall_radius": 3.0}}},
    "spring": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 1.0}}, "paper": _SCENE_PAPER},
    # Gravity: the paper's (L, T_pred, T_ext) = (4, 12, 24), as its published code's 3-body task (40-frame test sequences).
    "gravity": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 1.0, "pred_frames": 12,
                                                               "extrapolate_frames": 24}},
                "paper": {"train": _SCENE_PAPER["train"], "model": {**_SCENE_PAPER["model"], "pred_frames": 12,
                                                                    "extrapolate_frames": 24}}},
    "digits-spring": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 2.0}},
                      "paper": {"train": _SCENE_PAPER["train"], "model": {**_SCENE_PAPER["model"], "init_scale": 2.0}}},
}


def preset_for(name: str, info: DatasetInfo) -> dict[str, dict[str, Any]]:
    """The recipe ``name`` ("fast" or "paper") for a data file: the pendulum's :data:`PRESETS`, or the scene's.

    The scenes' templates are H/2 whatever the preset (:data:`SCENE_PRESETS`).
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; known: {sorted(PRESETS)}")
    if info.system == "pendulum":
        return PRESETS[name]
    scene = str(info.attrs.get("scene", info.system))
    recipes = SCENE_PRESETS.get(scene) or SCENE_PRESETS.get(info.system)
    if recipes is None:
        raise ValueError(f"{info.path}: system {info.system!r} has no physics model; known: {sorted(SYSTEM_SHAPES)}")
    recipe = recipes[name]
    size = info.image_shape[0]
    return {"train": dict(recipe["train"]), "model": {**recipe["model"], "template_size": max(size // 2, 1)}}


@dataclass
class TrainState:
    """What a checkpoint holds besides the weights."""

    epoch: int = 0
    """Epochs completed."""
    step: int = 0
    """Optimiser steps taken."""
    elapsed: float = 0.0
    """Training seconds so far (excluding evaluation)."""
    history: list[dict[str, float]] = field(default_factory=list)
    """Per-epoch means: loss, loss_pred, loss_rec, the physical parameters, seconds."""


def model_config_for(info: DatasetInfo, overrides: dict[str, Any] | None = None) -> ModelConfig:
    """The model that fits a data file: system, dt, image size and channels from its attributes."""
    if info.system not in SYSTEM_SHAPES:
        raise ValueError(f"{info.path}: system {info.system!r} has no physics model; known: {sorted(SYSTEM_SHAPES)}")
    shape = info.image_shape
    if shape[0] != shape[1]:
        raise ValueError(f"{info.path}: frames must be square, got {shape}")
    channels = shape[2] if len(shape) == 3 else 1
    n_objects = int(info.attrs.get("n_objects", SYSTEM_SHAPES[info.system][0]))
    cfg = ModelConfig(system=info.system, dt=info.dt, image_size=shape[0], channels=channels, n_objects=n_objects)
    return replace(cfg, **(overrides or {}))


def _optimizer(model: PhysicsModel, config: TrainConfig) -> torch.optim.Optimizer:
    physics = list(model.system.parameters())
    ids = {id(p) for p in physics}
    nets = [p for p in model.parameters() if id(p) not in ids]
    groups = [{"params": nets, "lr": config.lr, "name": "nets"},
              {"params": [p for p in physics if p.requires_grad], "lr": config.lr_physics, "name": "physics"}]
    if config.optimizer == "adam":
        return torch.optim.Adam(groups)
    if config.optimizer == "rmsprop":
        return torch.optim.RMSprop(groups)
    raise ValueError(f"unknown optimizer {config.optimizer!r}; expected 'adam' or 'rmsprop'")


def _rng_state() -> dict[str, Any]:
    return {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}


def _set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])


def save_checkpoint(path: Path, model: PhysicsModel, optimizer: torch.optim.Optimizer, state: TrainState,
                    train_config: TrainConfig, data_info: DatasetInfo) -> None:
    """Writes everything needed to resume or to use the model, atomically."""
    payload = {
        "model_config": model.config.to_dict(),
        "train_config": asdict(train_config),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "state": asdict(state),
        "rng": _rng_state(),
        "data": {"path": str(data_info.path), "system": data_info.system, "image_shape": list(data_info.image_shape),
                 "dt": data_info.dt},
    }
    with atomic_output(path, overwrite=True) as tmp:
        torch.save(payload, tmp)


def _background(data: str | Path, channels: int, seed: int, max_frames: int = 2000) -> torch.Tensor:
    """Label-free background of the training frames: a per-pixel median over up to ``max_frames``."""
    frames, _ = read_sequences(data, "train")
    flat = frames.reshape(-1, *frames.shape[2:])
    pick = np.random.default_rng(seed).choice(len(flat), size=min(max_frames, len(flat)), replace=False)
    sample = frames_to_float(torch.from_numpy(flat[np.sort(pick)])[:, None], channels)[:, 0]  # (F, C, H, W)
    return estimate_background(sample)


@torch.no_grad()
def _clip_to_running_rms(optimizer: torch.optim.Optimizer, params: list[torch.Tensor], factor: float) -> None:
    """Clips each gradient to ``factor`` x the bias-corrected RMS that Adam keeps for it.

    Written by hand because torch's clip_grad_* clip to a fixed norm, not to a parameter's own
    running gradient scale (the idea of Adafactor's update clipping).
    """
    for p in params:
        state = optimizer.state.get(p)
        if p.grad is None or not state or "exp_avg_sq" not in state:
            continue
        step = float(state["step"])
        if step < 20:  # the running RMS is not yet meaningful
            continue
        beta2 = next(g["betas"][1] for g in optimizer.param_groups if any(q is p for q in g["params"]))
        bound = factor * (state["exp_avg_sq"] / (1 - beta2**step)).sqrt()
        p.grad.copy_(torch.maximum(torch.minimum(p.grad, bound), -bound))


def _lr_factor(step: int, epoch: int, total_steps: int, config: TrainConfig) -> float:
    """Multiplier of the learning rates at a step (see ``TrainConfig.schedule``)."""
    if config.schedule == "step":
        return 1.0 / config.lr_decay_factor if config.lr_decay_epoch and epoch >= config.lr_decay_epoch else 1.0
    if config.schedule != "cosine":
        raise ValueError(f"unknown schedule {config.schedule!r}; expected 'cosine' or 'step'")
    span = max(total_steps - config.warmup_steps, 1)
    progress = min(max(step - config.warmup_steps, 0) / span, 1.0)
    low = config.lr_final_fraction
    return low + (1 - low) * 0.5 * (1 + math.cos(math.pi * progress))


def _horizon(step: int, config: TrainConfig, t_pred: int) -> int:
    """Prediction frames at a given step: 0 during warm-up, then growing to T_pred."""
    if step < config.warmup_steps:
        return 0
    if config.curriculum_steps <= 0:
        return t_pred
    frac = (step - config.warmup_steps) / config.curriculum_steps
    return max(1, min(t_pred, 1 + int(frac * t_pred)))


class _Scalars:
    """TensorBoard scalars, held in memory until the run folder is first written (the first checkpoint).

    So a run that fails or is interrupted before its first checkpoint leaves no ``tensorboard/``.
    """

    def __init__(self) -> None:
        self.pending: list[tuple[str, float, int]] = []
        self.writer: Any = None

    def add(self, tag: str, value: float, step: int) -> None:
        if self.writer is None:
            self.pending.append((tag, value, step))
        else:
            self.writer.add_scalar(tag, value, step)

    def open(self, folder: Path) -> None:
        """Starts writing to ``folder`` (once), beginning with the scalars held so far."""
        if self.writer is None:
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(str(folder))
            for tag, value, step in self.pending:
                self.writer.add_scalar(tag, value, step)
            self.pending.clear()

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def check_trainable(info: DatasetInfo, model_config: ModelConfig, train_config: TrainConfig) -> int:
    """Refuses, before anything is written, data that training cannot use; returns the number of train windows.

    Raises:
        ValueError (a :class:`piga.data.DataFormatError` for the file's contents): sequences shorter
        than a window, an empty train split, non-finite or absurd actions, or fewer windows than
        one batch (no step would run).
    """
    needed = model_config.window
    if info.steps < needed:
        raise ValueError(f"{info.path}: sequences have {info.steps} frames; training needs at least "
                         f"L + T_pred = {needed}")
    n_train = info.split_counts["train"]
    if not n_train:
        raise ValueError(f"{info.path}: the train split is empty")
    check_actions_file(info.path)
    windows = n_train * len(range(0, info.steps - needed + 1, train_config.window_stride))
    if windows < train_config.batch_size:
        raise ValueError(f"{info.path}: {windows} training windows ({n_train} train sequences) are fewer than one batch "
                         f"of {train_config.batch_size}, so no step would run; lower the batch size or give more data")
    return windows


def train(
    data: str | Path,
    run_dir: str | Path,
    train_config: TrainConfig,
    model_overrides: dict[str, Any] | None = None,
    resume: bool = False,
    progress: bool = True,
    on_epoch: Callable[[TrainState, PhysicsModel], None] | None = None,
) -> tuple[PhysicsModel, TrainState]:
    """Trains on the train split of ``data``; writes checkpoints and TensorBoard scalars to ``run_dir``.

    Nothing is written (not even ``run_dir``) before the first checkpoint, at the end of the first
    epoch; the data are checked first (:func:`check_trainable`).

    With ``resume``, the model, optimiser, step and RNGs come from ``run_dir``'s checkpoint and
    ``train_config`` should be the run's saved one (``TrainConfig(**ckpt["train_config"])``),
    possibly with more ``epochs``; ``model_overrides`` is ignored. Resuming with the same
    ``epochs`` continues exactly. With more ``epochs``, the cosine schedule is replanned over the
    new total: from the resumed step on, the learning rates are those a straight run of the new
    length has at that step (they rise again if the old run had finished its cosine), while the
    steps already taken keep the old schedule (and, if the old run finished, its final-epoch
    average of the physical parameters); so the result is close to, not identical with, the
    straight run.

    Returns:
        The trained model (eval mode) and the final :class:`TrainState`.
    """
    run_dir = Path(run_dir)
    info = inspect_dataset(data)
    ckpt_path = run_dir / CHECKPOINT
    if train_config.threads:
        torch.set_num_threads(train_config.threads)
    state = TrainState()
    if resume:
        model, ckpt = load_model(run_dir)
        model.train()
        optimizer = _optimizer(model, train_config)
        optimizer.load_state_dict(ckpt["optimizer"])
        state = TrainState(**ckpt["state"])
        _set_rng_state(ckpt["rng"])
    else:
        check_trainable(info, model_config_for(info, model_overrides), train_config)
        torch.manual_seed(train_config.seed)
        np.random.seed(train_config.seed)
        random.seed(train_config.seed)
        model = PhysicsModel(model_config_for(info, model_overrides))
        with torch.no_grad():
            model.encoder.background.copy_(_background(data, model.config.channels, train_config.seed))
        if model.config.init_background:
            model.decoder.init_background(model.encoder.background)
        optimizer = _optimizer(model, train_config)
    cfg = model.config
    if resume:
        check_trainable(info, cfg, train_config)
    windows = SequenceWindows(data, "train", window=cfg.window, stride=train_config.window_stride)
    writer = _Scalars()
    physics_params = [p for p in model.system.parameters() if p.requires_grad]
    physics_ids = {id(p) for p in physics_params}
    net_params = [p for p in model.parameters() if id(p) not in physics_ids]
    model.train()
    started = time.monotonic() - state.elapsed
    try:
        while state.epoch < train_config.epochs:
            if train_config.max_minutes and state.elapsed > train_config.max_minutes * 60:
                break
            # The sampler's generator depends on (seed, epoch) only, so a resumed run sees the same order.
            gen = torch.Generator().manual_seed(train_config.seed * 100_003 + state.epoch)
            loader = DataLoader(windows, batch_size=train_config.batch_size, sampler=RandomSampler(windows, generator=gen),
                                drop_last=True)
            total_steps = train_config.epochs * len(loader)
            sums = {"loss": 0.0, "loss_pred": 0.0, "loss_rec": 0.0}
            count = 0
            final_epoch = state.epoch == train_config.epochs - 1
            averages = [torch.zeros_like(p) for p in physics_params]
            bar = tqdm(loader, desc=f"epoch {state.epoch + 1}/{train_config.epochs}", leave=False, disable=not progress)
            for batch in bar:
                factor = _lr_factor(state.step, state.epoch, total_steps, train_config)
                for group in optimizer.param_groups:
                    group["lr"] = factor * (train_config.lr if group["name"] == "nets" else train_config.lr_physics)
                horizon = _horizon(state.step, train_config, cfg.pred_frames)
                out = model(batch.frames, batch.actions, pred_frames=max(horizon, 1))
                loss = out.loss if horizon > 0 else cfg.alpha * out.loss_rec
                if not torch.isfinite(loss):
                    good = ckpt_path if ckpt_path.exists() else None
                    raise TrainingDiverged(
                        f"loss became {loss.item()} at step {state.step} (epoch {state.epoch + 1}); "
                        + (f"last good checkpoint: {good}" if good else "no checkpoint was written yet")
                    )
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                if train_config.physics_grad_clip and train_config.optimizer == "adam":
                    _clip_to_running_rms(optimizer, physics_params, train_config.physics_grad_clip)
                if train_config.grad_clip:
                    torch.nn.utils.clip_grad_norm_(net_params, train_config.grad_clip)
                optimizer.step()
                state.step += 1
                count += 1
                if final_epoch and train_config.average_final_epoch:
                    with torch.no_grad():
                        for avg, p in zip(averages, physics_params):
                            avg += (p - avg) / count
                for key in sums:
                    sums[key] += float(getattr(out, key).detach()) if key != "loss" else float(loss.detach())
                if state.step % 10 == 0:
                    params = model.physical_parameters()
                    bar.set_postfix({k: f"{v:.4g}" for k, v in params.items() if k != "offset"} | {"loss": f"{loss.item():.4f}", "T": horizon})
                    for name, value in params.items():
                        writer.add(f"physics/{name}", value, state.step)
                    writer.add("loss/total", loss.item(), state.step)
                    writer.add("loss/pred", out.loss_pred.item(), state.step)
                    writer.add("loss/rec", out.loss_rec.item(), state.step)
                    writer.add("train/horizon", horizon, state.step)
                    writer.add("train/lr_factor", factor, state.step)
            bar.close()
            if final_epoch and train_config.average_final_epoch and count:
                with torch.no_grad():
                    for avg, p in zip(averages, physics_params):
                        p.copy_(avg)
            state.epoch += 1
            state.elapsed = time.monotonic() - started
            record = {k: v / max(count, 1) for k, v in sums.items()}
            record.update(model.physical_parameters())
            record.update({"epoch": state.epoch, "step": state.step, "seconds": state.elapsed})
            state.history.append(record)
            run_dir.mkdir(parents=True, exist_ok=True)
            save_checkpoint(ckpt_path, model, optimizer, state, train_config, info)
            writer.open(run_dir / "tensorboard")
            shown = ", ".join(f"{k}={v:.4g}" for k, v in model.physical_parameters().items())
            (tqdm.write if progress else print)(f"epoch {state.epoch}: loss {record['loss']:.5f} (pred {record['loss_pred']:.5f}, "
                           f"rec {record['loss_rec']:.5f}), {shown}, {state.elapsed / 60:.1f} min")
            if on_epoch is not None:
                on_epoch(state, model)
    finally:
        writer.close()
        windows.close()
    model.eval()
    return model, state
