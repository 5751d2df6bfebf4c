"""Training the PlaNet-style world model on a data file's random-action sequences (PlaNet's protocol
in the paper: "we train PlaNet on random episodes"), and reading the run back.

The loop, one readable flow: sample a batch of ``chunk_length``-frame windows from the train
split (frames, actions and ``/rewards``), take one Adam step on PlaNet's loss
(:meth:`agents.planet.rssm.WorldModel.loss`), clip the gradient norm, and every
``checkpoint_every`` steps write an atomic ``checkpoint.pt``, one point of the learning curve and
TensorBoard scalars. Randomness comes from two explicit generators (numpy for the batches, torch
for the latent samples), saved in each checkpoint, so ``resume`` continues exactly. Both draw on the
CPU whatever ``PlanetTrainConfig.device``; the batches are then copied to the device. A non-finite
loss stops training with :class:`piga.training.train.TrainingDiverged`, naming the last good checkpoint.

A run folder holds ``config.json`` (``kind: "planet"``), ``checkpoint.pt``, ``tensorboard/`` and
``metrics.json`` (the learning curve and the final losses on the valid split).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from agents.planet.config import PlanetTrainConfig, RSSMConfig
from agents.planet.rssm import WorldModel, model_steps
from agents.planet.run import load_planet
from envs.fields import counted
from piga.data.schema import (DataFormatError, DatasetInfo, check_actions_file, check_frames_have_signal,
                              check_pixel_pendulum_file, inspect_dataset, load_actions, load_rewards, read_sequences,
                              split_indices)
from piga.data.windows import SequenceReader, loads_whole
from piga.io.progress import close_bar
from piga.io.resources import available_memory
from piga.io.atomic import OutputFolder, write_json
from piga.io.checkpoint import CHECKPOINT, RunKind, check_counts, resuming_from, write_checkpoint
from piga.io.device import module_device, resolve_device, set_threads
from piga.training.convergence import ConvergenceConfig
from piga.training.train import TrainingDiverged

__all__ = ["PlanetState", "check_planet_data", "optimizer_step", "rssm_config_for", "train_planet"]


@dataclass
class PlanetState:
    """What a checkpoint holds besides the weights."""

    step: int = 0
    """Optimiser steps taken."""
    elapsed: float = 0.0
    """Training seconds so far."""
    history: list[dict[str, float]] = field(default_factory=list)
    """The learning curve: per checkpoint, the mean losses since the previous one, the step and seconds, and the
    loss on the valid split (``valid_loss``, where the file has one)."""
    best_step: int = 0
    """The checkpoint step of the lowest valid loss so far (0: none measured), whose weights the checkpoint keeps
    as ``best_model``: a model selected on held-out sequences, never on control episodes."""
    best_valid_loss: float | None = None
    """That loss."""


class _Sequences:
    """A split's sequences (its first ``max_sequences`` with it): frames uint8 (N, T, H, W), actions (N, T, A),
    rewards (N, T); ``extra``'s train split (the iterative mode's collected episodes, all in it) appended.
    The frames are in memory, or with ``stream`` read from the file through a bounded cache
    (:class:`piga.data.windows.SequenceReader`), for a file larger than memory: the same batches either way."""

    def __init__(self, data: str | Path, split: str, max_sequences: int = 0, extra: str | Path | None = None,
                 stream: bool = False):
        limit = max_sequences or None
        rewards = load_rewards(data, split, limit=limit)
        self.reader: SequenceReader | None = None
        if stream:
            if extra is not None:
                raise ValueError("streamed sequences take no extra file")
            self.reader = SequenceReader(data, split_indices(data, split)[:limit])
            actions = load_actions(data, split, limit=limit)  # (N, T, A)
            self.frames = None
        else:
            frames, actions = read_sequences(data, split, limit=limit)
            if extra is not None:
                more_frames, more_actions = read_sequences(extra, "train")
                frames, actions = np.concatenate([frames, more_frames]), np.concatenate([actions, more_actions])
                rewards = np.concatenate([rewards, load_rewards(extra, "train")])
            self.frames = torch.from_numpy(frames)
        self.actions = torch.from_numpy(actions)
        self.rewards = torch.from_numpy(rewards)

    def __len__(self) -> int:
        return len(self.actions)

    def batch(self, rng: np.random.Generator, size: int, length: int, repeat: int = 1) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``size`` random windows of ``length`` model steps of ``repeat`` env steps each
        (:func:`agents.planet.rssm.model_steps`): frames (B, L, H, W), actions (B, L, R·A), rewards (B, L)."""
        length *= repeat  # env steps
        seq = rng.integers(len(self), size=size)
        start = rng.integers(self.actions.shape[1] - length + 1, size=size)
        rows = torch.from_numpy(seq)[:, None]
        cols = torch.from_numpy(start)[:, None] + torch.arange(length)[None]  # (B, L)
        if self.reader is not None:
            frames = torch.from_numpy(np.stack([self.reader(i)[j : j + length] for i, j in zip(seq, start)]))
            return model_steps(frames, self.actions[rows, cols], self.rewards[rows, cols], repeat)
        return model_steps(self.frames[rows, cols], self.actions[rows, cols], self.rewards[rows, cols], repeat)


def rssm_config_for(info: DatasetInfo, overrides: dict[str, Any] | None = None) -> RSSMConfig:
    """The model that fits a data file's frames and actions."""
    shape = info.image_shape
    channels = shape[2] if len(shape) == 3 else 1
    return RSSMConfig(**{"image_size": shape[0], "channels": channels, "action_dim": info.action_dim, **(overrides or {})})


def check_planet_data(info: DatasetInfo, config: PlanetTrainConfig, repeat: int = 1) -> None:
    """Refuses, before anything is written, a file the world model cannot train on (with the
    model's action repeat ``repeat``).

    Raises:
        DataFormatError: no ``/rewards``, frames that are not 64x64 gray, actions that are not the
            pendulum's one torque (piga-control could not run the model), blank frames, or
            sequences shorter than a chunk.
        ValueError: no training sequence.
    """
    from envs import PIXEL_PENDULUM

    env_id = info.attrs.get("env_id")  # files from before env ids, and imported ones, hold none
    if info.system != "pendulum" or env_id not in (None, PIXEL_PENDULUM):  # before training: no command could use it
        raise DataFormatError(f"{info.path}: the PlaNet-style agent is trained on and controls {PIXEL_PENDULUM}'s "
                              f"pendulum; this file is {info.named}" + (f" from {env_id}" if env_id else "")
                              + f" (collect one with piga-collect --env {PIXEL_PENDULUM})")
    if not info.has_rewards:
        if "source_frames" in info.attrs:  # piga-import's: no recording holds rewards, and none can be collected for it
            raise DataFormatError(f"{info.path}: has no /rewards, as no imported recording has; the PlaNet-style model "
                                  "learns a reward head from the env's rewards, so it trains on files that piga-collect "
                                  f"writes (piga-collect --env {PIXEL_PENDULUM})")
        raise DataFormatError(f"{info.path}: has no /rewards; the PlaNet-style model learns a reward head "
                              "(collect the data with piga-collect, which writes them)")
    if info.image_shape[:2] != (64, 64):
        raise DataFormatError(f"{info.path}: the PlaNet-style model takes 64x64 frames, got {info.image_shape}")
    if info.action_dim != 1:
        raise DataFormatError(f"{info.path}: has {info.action_dim} action dimensions; the PlaNet-style agent controls the "
                              "pixel pendulum, which takes one (collect the data with piga-collect)")
    if len(info.image_shape) == 3 and info.image_shape[2] != 1:
        raise DataFormatError(f"{info.path}: has colour frames {info.image_shape}; the PlaNet-style agent controls the "
                              "pixel pendulum from gray frames (collect the data with piga-collect)")
    if env_id == PIXEL_PENDULUM and "env_config" in info.attrs:  # frames its env would not render
        check_pixel_pendulum_file(info, f"the PlaNet-style agent learns the pictures that {PIXEL_PENDULUM} renders")
    if info.steps < 2:  # no chunk of any length learns motion from it
        raise DataFormatError(f"{info.path}: has {counted(info.steps, 'frame')} per sequence, and a video needs two; "
                              "collect longer sequences")
    check_frames_have_signal(info.path)
    if info.steps < config.chunk_length * repeat:
        raise ValueError(f"{info.path}: sequences of {counted(info.steps, 'frame')} are shorter than chunk_length "
                         f"{config.chunk_length}" + (f" x action repeat {repeat}" if repeat > 1 else "") + "; lower it")
    if info.split_counts["train"] < 1:
        raise ValueError(f"{info.path}: the train split is empty")


def _save(path: Path, model: WorldModel, optimizer: torch.optim.Optimizer, state: PlanetState, config: PlanetTrainConfig,
          rng: np.random.Generator, generator: torch.Generator, info: DatasetInfo,
          best: dict[str, torch.Tensor] | None = None) -> None:
    payload = {
        "best_model": best,
        "kind": RunKind.PLANET.value,
        "rssm_config": model.config.to_dict(),
        "train_config": config.to_dict(),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "state": asdict(state),
        "rng": {"numpy": rng.bit_generator.state, "torch": generator.get_state()},
        "data": {"path": str(info.path), "folder": os.getcwd(), "image_shape": list(info.image_shape), "dt": info.dt,
                 "env_id": info.attrs.get("env_id")},  # None: a file from before env ids, or an imported recording
    }
    write_checkpoint(path.parent, payload)


#: Frames filtered before the open-loop prediction of ``openloop.png`` (PlaNet's open-loop videos use 5).
OPEN_LOOP_CONTEXT = 5


@torch.no_grad()
def open_loop_check(model: WorldModel, data: str | Path, run_dir: Path, seed: int, sequences: int = 4) -> dict[str, Any]:
    """PlaNet's open-loop diagnostic on the valid split (the train split without one): filter
    :data:`OPEN_LOOP_CONTEXT` frames, imagine the rest of each sequence under its own actions;
    writes ``run_dir/openloop.png`` (real frames above imagined ones, and real against predicted
    rewards) and returns per-step errors: frame MSE (in [0, 1] units) and reward absolute error,
    averaged over ``sequences`` sequences, plus the same for an all-mean-frame and zero-reward guess."""
    from piga.evaluation.plots import openloop_figure, save_figure

    info = inspect_dataset(data)
    split = "valid" if info.split_counts["valid"] else "train"
    seqs = _Sequences(data, split, sequences)
    frames, actions, rewards = model_steps(seqs.frames, seqs.actions, seqs.rewards, model.config.action_repeat)
    context = min(OPEN_LOOP_CONTEXT, frames.shape[1] - 1)
    device = module_device(model)
    generator = torch.Generator().manual_seed(seed)
    decoded, predicted = (x.cpu() for x in model.open_loop(frames.to(device), actions.to(device), context, generator))
    imagined = (decoded.movedim(2, -1) + 0.5).clamp(0, 1)  # (B, T, H, W, C) in [0, 1]
    real = frames.float() / 255  # (B, T, H, W) gray, or (B, T, H, W, C)
    if real.dim() == 4:
        real = real.unsqueeze(-1)  # (B, T, H, W, 1)
    pixel_axes = (0, 2, 3, 4)
    frame_mse = (imagined - real).square().mean(pixel_axes)  # (T,)
    mean_frame_mse = (real.mean((0, 1), keepdim=True) - real).square().mean(pixel_axes)  # (T,) the average frame as a guess
    predicted, rewards = model.aligned_rewards(predicted, rewards)  # (B, T) or, aligned to transitions, (B, T - 1)
    reward_error = (predicted - rewards).abs().mean(0)  # (T,) or (T - 1,)
    shown = (lambda x: x.squeeze(-1)) if real.shape[-1] == 1 else (lambda x: x)  # gray as (H, W) for imshow
    save_figure(openloop_figure(shown(real).numpy(), shown(imagined).numpy(), rewards.numpy(), predicted.numpy(), context),
                run_dir / "openloop.png")
    return {"split": split, "sequences": len(frames), "context": context, "frame_mse": frame_mse.tolist(),
            "mean_frame_mse": mean_frame_mse.tolist(), "reward_abs_error": reward_error.tolist(),
            "zero_reward_abs_error": rewards.abs().mean(0).tolist()}


def did_not_learn(open_loop: dict[str, Any], ratio: float = ConvergenceConfig.blank_ratio) -> str | None:
    """Why a trained world model learned nothing, read off its :func:`open_loop_check` (None: it learned something).

    The same test as a piga run's (``ConvergenceConfig.blank_ratio``): a model must beat a guess that learned
    nothing. Its reconstructions of the frames it filters (the first ``context``) must beat the average frame, and
    its rewards the guess 0 (unless every reward is 0). A 5-step run (loss 641) passed as a run; the trained runs'
    records (``results/planet_faithful_runs/records/``) hold their errors beside the guesses'."""
    context = max(1, int(open_loop["context"]))
    frame, average = (float(np.mean(open_loop[key][:context])) for key in ("frame_mse", "mean_frame_mse"))
    if not frame < ratio * average:
        return (f"its reconstructions of the frames it filtered (MSE {frame:.4g}) are no better than the average frame "
                f"(MSE {average:.4g})")
    reward, zero = (float(np.mean(open_loop[key])) for key in ("reward_abs_error", "zero_reward_abs_error"))
    if zero > 0 and not reward < ratio * zero:
        return f"its reward predictions (mean error {reward:.4g}) are no better than predicting 0 (mean error {zero:.4g})"
    return None


def _valid_window(data: str | Path, config: PlanetTrainConfig, info: DatasetInfo, repeat: int
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """One chunk from the start of each of (up to 64 of) the valid split's sequences, as model steps: frames, actions,
    rewards (:func:`model_steps`); None without a valid split. Read once per training."""
    if not info.split_counts["valid"]:
        return None
    seqs = _Sequences(data, "valid", 64)
    length = config.chunk_length * repeat
    return model_steps(seqs.frames[:, :length], seqs.actions[:, :length], seqs.rewards[:, :length], repeat)


@torch.no_grad()
def _valid_losses(model: WorldModel, window: tuple[torch.Tensor, ...] | None, config: PlanetTrainConfig
                  ) -> dict[str, float] | None:
    """Mean losses on the valid window (:func:`_valid_window`), with a generator of its own; None without one."""
    if window is None:
        return None
    device = module_device(model)
    parts = model.loss(*(x.to(device) for x in window), config, torch.Generator().manual_seed(config.seed))
    return {name: float(value) for name, value in parts._asdict().items()}


def optimizer_step(model: WorldModel, optimizer: torch.optim.Optimizer, loss: torch.Tensor, grad_clip: float) -> None:
    """One of :func:`train_planet`'s updates: the gradient of ``loss``, clipped to global norm ``grad_clip``, and
    Adam's step."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
    optimizer.step()


def train_planet(
    data: str | Path,
    run_dir: str | Path,
    config: PlanetTrainConfig,
    rssm: RSSMConfig | None = None,
    resume: bool = False,
    progress: bool = True,
    on_checkpoint: Callable[[PlanetState], None] | None = None,
    extra_data: str | Path | None = None,
) -> tuple[WorldModel, PlanetState]:
    """Trains the world model on ``data``'s train split; writes checkpoints, TensorBoard and ``metrics.json`` to ``run_dir``.

    Nothing is written before the first checkpoint. With ``resume``, the model, optimiser, RNGs and
    step come from ``run_dir``'s checkpoint, and ``config`` should be its saved one (possibly with
    more ``steps``); ``rssm`` is ignored. ``extra_data``: a file of the same frames whose sequences
    are trained on too (:mod:`agents.planet.iterative`'s collected episodes).

    The model trains on ``config.device`` (:func:`piga.io.device.resolve_device`), where ``metrics.json``'s
    losses are measured too, and is returned on the CPU, where the latent planner runs.

    Returns:
        The trained model (eval mode, on the CPU) and the final state.

    Raises:
        ValueError: ``config.device`` is "cuda" and torch sees no CUDA device (before anything is read).
    """
    device = resolve_device(config.device)
    run_dir = Path(run_dir)
    folder = OutputFolder(run_dir)  # moved or removed while the run trains: said, not made again
    ckpt_path = run_dir / CHECKPOINT
    info = inspect_dataset(data)
    check_actions_file(data)  # the actions only: the frames may not fit in memory
    set_threads(config.threads, "PlanetTrainConfig")
    rng = np.random.default_rng(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    best: dict[str, torch.Tensor] | None = None  # the weights of the lowest valid loss, on the CPU
    if resume:
        model, ckpt = load_planet(run_dir)
        with resuming_from(ckpt_path, RunKind.PLANET):
            state = PlanetState(**ckpt["state"])
            rng.bit_generator.state = ckpt["rng"]["numpy"]
            generator.set_state(ckpt["rng"]["torch"])
            best = ckpt.get("best_model")
        check_counts(ckpt_path, RunKind.PLANET, step=state.step)
    else:
        torch.manual_seed(config.seed)  # the layers' initialisation
        model = WorldModel(rssm or rssm_config_for(info))
        state = PlanetState()
    check_planet_data(info, config, model.config.action_repeat)
    model.to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, eps=config.adam_eps)
    if resume:
        with resuming_from(ckpt_path, RunKind.PLANET):
            optimizer.load_state_dict(ckpt["optimizer"])
    n_frames = min(config.max_sequences or info.split_counts["train"], info.split_counts["train"]) * info.sequence_bytes
    seqs = _Sequences(data, "train", config.max_sequences, extra_data,
                      stream=extra_data is None and not loads_whole(n_frames, available_memory()))
    valid_window = _valid_window(data, config, info, model.config.action_repeat)
    valid: dict[str, float] | None = None  # the valid losses at the latest checkpoint of this invocation
    writer: Any = None
    model.train()
    started = time.monotonic() - state.elapsed
    sums: dict[str, float] = {}
    count = 0
    bar = tqdm(total=config.steps, initial=state.step, desc="planet", unit="step", disable=not progress)
    try:
        while state.step < config.steps:
            batch = seqs.batch(rng, config.batch_size, config.chunk_length, model.config.action_repeat)
            frames, actions, rewards = (x.to(device) for x in batch)  # uint8 (B, L, H, W), (B, L, R·A), (B, L)
            parts = model.loss(frames, actions, rewards, config, generator)
            if not torch.isfinite(parts.loss):
                good = ckpt_path if ckpt_path.exists() else None
                raise TrainingDiverged(f"loss became {parts.loss.item()} at step {state.step + 1}; "
                                       + (f"last good checkpoint: {good}" if good else "no checkpoint was written yet"))
            optimizer_step(model, optimizer, parts.loss, config.grad_clip)
            state.step += 1
            count += 1
            for name, value in parts._asdict().items():
                sums[name] = sums.get(name, 0.0) + float(value.detach())
            bar.update(1)
            if state.step % 10 == 0:
                bar.set_postfix(loss=f"{parts.loss.item():.2f}", kl=f"{parts.kl.item():.2f}", reward=f"{parts.reward.item():.3f}")
            if state.step % config.checkpoint_every == 0 or state.step == config.steps:
                state.elapsed = time.monotonic() - started
                record = {name: total / count for name, total in sums.items()}
                # the means since the last record: over steps first_step..step (a resume starts a new window)
                record.update({"step": state.step, "first_step": state.step - count + 1, "seconds": state.elapsed})
                valid = _valid_losses(model, valid_window, config)  # its own generator: the training draws are untouched
                if valid is not None:
                    record["valid_loss"] = valid["loss"]
                    if math.isfinite(valid["loss"]) and (state.best_valid_loss is None or valid["loss"] < state.best_valid_loss):
                        state.best_step, state.best_valid_loss = state.step, valid["loss"]
                        best = {name: tensor.detach().cpu().clone() for name, tensor in model.state_dict().items()}
                state.history.append(record)
                sums, count = {}, 0
                folder.make()
                _save(ckpt_path, model, optimizer, state, config, rng, generator, info, best)
                folder.check()  # before TensorBoard's writer makes its folder, and so the run's, again
                if writer is None:
                    from torch.utils.tensorboard import SummaryWriter

                    writer = SummaryWriter(str(run_dir / "tensorboard"))
                for name in ("loss", "reconstruction", "reward", "kl"):
                    writer.add_scalar(f"loss/{name}", record[name], state.step)
                if on_checkpoint is not None:
                    on_checkpoint(state)
                if config.max_minutes and state.elapsed > config.max_minutes * 60:
                    break
    finally:
        close_bar(bar)  # cleared on an error: its line is the last
        if writer is not None:
            writer.close()
    model.eval()
    folder.check()  # before the open-loop check draws into it
    metrics = {
        "kind": "planet",
        "data": str(data),
        "train_sequences": len(seqs),
        "collected_sequences": 0 if extra_data is None else inspect_dataset(extra_data).n_sequences,
        "steps": state.step,
        "train_seconds": state.elapsed,
        "device": str(device),
        "device_name": torch.cuda.get_device_name(device) if device.type == "cuda" else None,
        "learning_curve": state.history,
        # the last checkpoint's, unless this invocation wrote none (a finished run resumed)
        "valid": valid if valid is not None else _valid_losses(model, valid_window, config),
        "best_valid": None if state.best_valid_loss is None else {"step": state.best_step, "loss": state.best_valid_loss},
        "open_loop": open_loop_check(model, data, run_dir, config.seed),
    }
    with folder.kept():
        write_json(run_dir / "metrics.json", metrics)
    return model.cpu(), state
