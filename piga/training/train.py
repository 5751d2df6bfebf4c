"""Training the world model on a data file: frames and actions only, never ``/states``.

The loop is one readable flow, in the style of cleanrl:

0. A plan sized from the file (:func:`plan_training`): the run's steps, and the warm-up, curriculum
   and final average as fractions of them.
1. An autoencoder warm-up. For the plan's warm-up steps only α·L_rec trains the encoder and
   decoder, so that the coordinates mean something before the physics leans on them.
2. A rollout curriculum. The prediction horizon grows from 1 frame to T_pred over the plan's
   curriculum steps. Short rollouts keep the predicted object overlapping the true one, so the
   pixel loss has a gradient with respect to g and a even while they are far from the truth.
3. Physical parameters get their own learning rate (``lr_physics``), in log space.
4. A convergence check of the physical parameters at the end (:mod:`piga.training.convergence`).

The model is the one ``ModelConfig.architecture`` names (:mod:`piga.world.variants`): piga's, or a
black-box baseline without physical parameters, trained by this same loop on the same windows and loss.

Each epoch ends with an atomic checkpoint (``checkpoint.pt``). ``resume`` restores the model,
the optimiser, the step count and every RNG, and continues exactly where the run stopped. A
non-finite loss stops training with :class:`TrainingDiverged`, which names the last good
checkpoint.
"""

from __future__ import annotations

import math
import os
import random
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Literal

import numpy as np
import torch
from torch.utils.data import DataLoader, RandomSampler
from tqdm.auto import tqdm

from piga.io.atomic import FolderMovedError, OutputFolder
from piga.io.choices import check_choices, check_types
from piga.io.device import Device, resolve_device, set_threads
from piga.data.schema import (MAX_SEED, MIN_IMAGE_SIZE, DataFormatError, DatasetInfo, check_actions_file, fingerprint, legacy_seed, read_rows,
                              inspect_dataset, open_data_file, split_indices)
from piga.world.encoder import estimate_background
from piga.world.model import SYSTEM_SHAPES, FrameModel, ModelConfig, frames_to_float
from piga.world.physics import BouncingOptions, PendulumOptions
from piga.world.variants import build_model
from piga.io.checkpoint import CHECKPOINT, RunKind, check_counts, resuming_from, write_checkpoint
from piga.io.runs import load_model
from piga.data.windows import BlockShuffleSampler, SequenceWindows, loads_whole


class TrainingDiverged(RuntimeError):
    """The loss became NaN or infinite; the message names the last good checkpoint."""


@dataclass(frozen=True)
class TrainConfig:
    """How to train. The defaults are the 'fast' recipe; other recipes are in :data:`PRESETS`.

    Every schedule is sized from the data file (:func:`plan_training`): the run's length comes from
    ``budget_steps`` unless ``epochs`` is given, and the warm-up, the curriculum and the final
    average are fractions of the run, so a small or short file trains its physics as long as a large one.
    """

    epochs: int = 0
    """Passes over the training windows (0: sized from the data, the fewest whole epochs that reach
    ``budget_steps``). The cosine schedule is planned over all of them."""
    budget_steps: int = 2000
    """Optimiser steps a run is sized to when ``epochs`` is 0 (rounded up to whole epochs). 2000 identify
    g and a to 0.1% on the default file (``benchmarks/identify_time.py``), as 5400 did."""
    max_minutes: float = 0.0
    """Safety wall-clock budget: stop after the first epoch that ends past it (0: no limit).
    Training results do not depend on it unless it cuts the run short."""
    batch_size: int = 32
    """Windows per step."""
    lr: float = 1e-3
    """Learning rate of the networks (encoder, velocity, decoder)."""
    lr_physics: float = 1e-2
    """Learning rate of the physical parameters (log space)."""
    optimizer: Literal["adam", "rmsprop"] = "adam"
    """'adam' or 'rmsprop' (the paper's)."""
    schedule: Literal["cosine", "step"] = "cosine"
    """"cosine": after the warm-up, both learning rates follow a cosine from their value down to
    ``lr_final_fraction`` of it at the last planned step; "step": the paper's division by
    ``lr_decay_factor`` from ``lr_decay_epoch`` on."""
    lr_final_fraction: float = 0.01
    """Cosine schedule: final learning rate as a fraction of the initial one."""
    lr_decay_epoch: int = 0
    """Step schedule: divide the learning rates by ``lr_decay_factor`` from this epoch on (0: never)."""
    lr_decay_factor: float = 5.0
    """The paper divides by 5."""
    warmup_fraction: float = 0.04
    """Fraction of the planned steps of autoencoder-only training before the physics is used."""
    curriculum_fraction: float = 0.11
    """Fraction of the planned steps over which the prediction horizon grows from 1 to T_pred (0: full horizon at once)."""
    window_stride: int = 1
    """Start frames of training windows are this far apart within a sequence."""
    data_loading: Literal["auto", "memory", "stream"] = "auto"
    """How the train split's frames are read. "memory": loaded whole, the windows in a uniformly random
    order. "stream": read from the file through a bounded cache (``stream_cache_mb``), for a file larger
    than memory, the windows shuffled within blocks of the sequences that the cache holds
    (:class:`~piga.data.windows.BlockShuffleSampler`). "auto": "memory" when the frames need under 2 GiB
    and under a quarter of the available memory (:func:`~piga.data.windows.loads_whole`), else "stream".
    A run records the reading it used and resumes with it: the two orders differ, so the same seed
    trains another run."""
    stream_cache_mb: int = 256
    """"stream": the cache of decompressed sequences, in MiB (at most a quarter of the available memory)."""
    seed: int = 0
    """Seed of initialisation and sampling."""
    threads: int = 0
    """torch CPU threads (0: leave torch's default)."""
    device: Device = "auto"
    """Where to train (:mod:`piga.io.device`): "auto" (a CUDA GPU when torch sees one, else the CPU), "cpu" or
    "cuda". Not part of the recipe: a run resumes on any device. Sampling draws from the CPU's generator
    everywhere, but a GPU's kernels round differently (cuDNN may convolve in TF32, PyTorch's default), so a
    GPU run is not the CPU's bit for bit. No mixed precision: its effect on the identified parameters has
    not been measured."""
    seed_retries: int = 3
    """``piga-train-model``: a scene run whose object check finds an object missing, or a slot that draws
    nothing where the scene has an object for it (:mod:`piga.evaluation.objects`, which reads frames only),
    is trained again from its start with the
    next seed, up to this many times (0: never); :func:`train` itself trains once. While a retry is left, the
    missing object is also looked for at the first checkpoint after the autoencoder's warm-up, and a try that
    has lost one then is restarted at once (an object not found then was not found at the end in any run
    measured, ``benchmarks/warmup_objects.py``). Which objects an autoencoder discovers depends on its
    initialisation, as the published implementation's README says; the check makes another draw possible
    without labels. Three: on a file where a seed loses a ball two times in three (the half spring data,
    results/regions_retries.md) one retry left half the runs failing; a try lost at the warm-up costs about a
    fifth of a run."""
    grad_clip: float = 10.0
    """Gradient-norm clip of the networks (0: none)."""
    physics_grad_clip: float = 3.0
    """Adam only: clip each physical parameter's gradient to this many times its running RMS (0: off).
    One outlying batch otherwise inflates Adam's first moment long before the second catches up,
    and the next ~10 steps throw g and a several percent off (seen mid-training without it)."""
    average_fraction: float = 0.0625
    """End with the physical parameters averaged (in log space) over this last fraction of the planned
    steps: Polyak averaging, which removes most of the optimiser's step-to-step jitter (0: off)."""

    def __post_init__(self) -> None:
        check_types(self)  # a number given as text fails here, naming the field, not at a comparison below
        for name in ("epochs", "budget_steps", "lr_decay_epoch", "seed", "threads", "seed_retries", "stream_cache_mb"):
            if getattr(self, name) < 0:
                raise ValueError(f"TrainConfig.{name} must be >= 0, got {getattr(self, name)}")
        if self.seed > MAX_SEED:  # (torch's generator took it and failed with "Overflow when unpacking long long")
            raise ValueError(f"TrainConfig.seed must be <= {MAX_SEED} (2^63 - 1), got {self.seed}")
        if self.seed_retries > MAX_SEED_RETRIES:
            raise ValueError(f"TrainConfig.seed_retries must be <= {MAX_SEED_RETRIES} (each retry can cost a whole run), "
                             f"got {self.seed_retries}")
        if self.batch_size < 1 or self.window_stride < 1:
            raise ValueError(f"TrainConfig.batch_size and window_stride must be >= 1, got {self.batch_size}, "
                             f"{self.window_stride}")
        if not self.epochs and not self.budget_steps:
            raise ValueError("TrainConfig: give epochs or budget_steps (both are 0)")
        for name in ("lr", "lr_physics"):
            if not (math.isfinite(getattr(self, name)) and 0 < getattr(self, name) <= MAX_LR):
                raise ValueError(f"TrainConfig.{name} must be in (0, {MAX_LR:g}], got {getattr(self, name)}")
        if not (math.isfinite(self.lr_decay_factor) and self.lr_decay_factor > 0):
            raise ValueError(f"TrainConfig.lr_decay_factor must be finite and > 0, got {self.lr_decay_factor}")
        for name in ("warmup_fraction", "curriculum_fraction", "average_fraction", "lr_final_fraction"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"TrainConfig.{name} must be in [0, 1], got {getattr(self, name)}")
        if self.warmup_fraction + self.curriculum_fraction >= 1:
            raise ValueError("TrainConfig: warmup_fraction + curriculum_fraction must leave some steps at the full "
                             f"horizon, got {self.warmup_fraction} + {self.curriculum_fraction}")
        for name in ("max_minutes", "grad_clip", "physics_grad_clip"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"TrainConfig.{name} must be finite and >= 0, got {value}")
        check_choices(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TrainConfig:
        """The config a checkpoint saved. A run saved before the schedules were sized from the data
        (absolute ``warmup_steps``) cannot be resumed: its schedule has no fraction to replan from."""
        legacy = {"warmup_steps", "curriculum_steps", "average_final_epoch"} & set(values)
        if legacy:
            raise ValueError("the run was saved by an older piga, whose schedules were absolute steps "
                             f"({', '.join(sorted(legacy))}); train it again instead of resuming")
        return cls(**values)


#: The most optimiser steps a run may plan: 400 times the paper recipe's longest run (25,000 steps), weeks on a
#: CPU; --epochs 1e20 was taken and planned its first checkpoint after 2e18 epochs.
MAX_TRAIN_STEPS = 10_000_000
#: Learning rates above this are refused: no recipe of piga's comes within a factor 100 of it, and a
#: physics learning rate that large throws the log-space parameters to the float limits in one step.
MAX_LR = 10.0
#: The most seed retries (``--seed-retries``): a retry can cost a whole run, and where a seed loses an object two
#: times in three (the half spring data) this many leave (2/3)^11, about 1%, of runs failing; a file that fails
#: more often points at the data or the model, not at the seed (1000000 was taken, and trained without end).
MAX_SEED_RETRIES = 10


@dataclass(frozen=True)
class TrainPlan:
    """A recipe made concrete for one data file: its steps, and where the warm-up, the curriculum and
    the final average fall (:func:`plan_training`)."""

    windows: int
    """Training windows in the file (its train split)."""
    steps_per_epoch: int
    """Batches per epoch (``windows // batch_size``)."""
    epochs: int
    """Epochs planned."""
    warmup_steps: int
    """Autoencoder-only steps first."""
    curriculum_steps: int
    """Steps over which the horizon grows to T_pred."""
    average_steps: int
    """The last steps whose physical parameters are averaged (0: none)."""
    checkpoint_every: int = 1
    """Epochs between checkpoints (and printed lines): one epoch, or enough of a small file's short epochs
    to make 2% of the run, so that a file of a few windows does not spend its time saving."""

    @property
    def total_steps(self) -> int:
        """Optimiser steps planned."""
        return self.epochs * self.steps_per_epoch

    def describe(self, pred_frames: int, physics: bool = True, autoencoder: bool = True) -> str:
        """One line, e.g. "5400 steps = 16 epochs x 337 steps (10800 windows); warm-up 216, curriculum 594 (T 1->10), average of the last 337"
        (no average for a model without physical parameters, ``physics`` False; ``autoencoder`` False, a run that
        never trains on L_rec (``ModelConfig.loss`` "pred-only"): its warm-up steps predict one frame)."""
        from envs.fields import counted  # here: training runs without gymnasium's import

        if autoencoder:
            warmup = f"autoencoder warm-up {counted(self.warmup_steps, 'step')}" if self.warmup_steps else "no warm-up"
        else:
            warmup = "no autoencoder warm-up" + (f" (its warm-up of {counted(self.warmup_steps, 'step')} predicts 1 frame)"
                                                 if self.warmup_steps else "")
        curriculum = (f"curriculum {counted(self.curriculum_steps, 'step')} (T_pred 1 -> {pred_frames})"
                      if self.curriculum_steps else f"no curriculum (T_pred {pred_frames} from the first step)")
        return (f"{counted(self.total_steps, 'step')} = {counted(self.epochs, 'epoch')} x "
                f"{counted(self.steps_per_epoch, 'step')} ({counted(self.windows, 'window')}); {warmup}, {curriculum}"
                + (f", parameters averaged over the last {counted(self.average_steps, 'step')}"
                   if self.average_steps and physics else "")
                + (f"; a checkpoint every {self.checkpoint_every} epochs" if self.checkpoint_every > 1 else ""))


def largest_stride(batch: int, sequences: int, starts: int) -> int | None:
    """The largest window stride at which ``sequences`` sequences of ``starts`` start frames each (at a stride of 1)
    give at least ``batch`` windows (a sequence gives ceil(starts / stride)), or None where not even a stride of 1 does.
    """
    per_sequence = -(-batch // sequences)  # windows each sequence must give
    if per_sequence > starts:
        return None
    # ceil(starts / s) >= k  <=>  s < starts / (k - 1); any stride where one window each is enough
    return max(starts, 1) if per_sequence <= 1 else -(-starts // (per_sequence - 1)) - 1


def plan_training(config: TrainConfig, windows: int, layout: tuple[int, int] | None = None) -> TrainPlan:
    """Sizes a recipe to a file of ``windows`` training windows.

    With ``config.epochs`` 0 the run is the fewest whole epochs that reach ``budget_steps``; the
    warm-up, the curriculum and the final average are fractions of the planned steps (at least one
    step each when their fraction is not 0), so that the physics trains for most of the run whatever
    the file's size. ``layout``: the file's train sequences and the start frames one of them has at a stride of 1
    (None: not known), for the advice when there are fewer windows than a batch.
    """
    per_epoch = windows // config.batch_size
    if per_epoch < 1:
        from envs.fields import counted  # here: training runs without gymnasium's import
        stride = ""
        if config.window_stride > 1 and layout is None:
            stride = f", or lower --window-stride (now {config.window_stride})"
        elif config.window_stride > 1 and (most := largest_stride(config.batch_size, *layout)):
            # (sequences one window long give one window at any stride: no stride helps there)
            stride = f", or lower --window-stride to {most} or less (now {config.window_stride})"
        raise ValueError(f"{counted(windows, 'training window')} {'is' if windows == 1 else 'are'} fewer than one "
                         f"batch of {config.batch_size}, so no step would run; lower the batch size (--batch-size) or "
                         f"give more data{stride}")
    epochs = config.epochs or max(1, math.ceil(config.budget_steps / per_epoch))
    total = epochs * per_epoch
    if total > MAX_TRAIN_STEPS:
        asked = f"epochs={config.epochs}" if config.epochs else f"budget_steps={config.budget_steps}"
        raise ValueError(f"{asked} plans {total:,} steps ({epochs:,} epochs x {per_epoch} steps), more than "
                         f"{MAX_TRAIN_STEPS:,} (weeks of training); lower --epochs or --budget-steps")

    def part(fraction: float) -> int:
        return 0 if fraction <= 0 else max(1, int(round(fraction * total)))

    warmup, curriculum = part(config.warmup_fraction), part(config.curriculum_fraction)
    if warmup + curriculum >= total:  # a run of a few steps: keep one step at the full horizon
        warmup, curriculum = min(warmup, max(total - 1, 0) // 2), min(curriculum, max(total - 1, 0) // 2)
    return TrainPlan(windows=windows, steps_per_epoch=per_epoch, epochs=epochs, warmup_steps=warmup,
                     curriculum_steps=curriculum, average_steps=min(part(config.average_fraction), total),
                     checkpoint_every=max(1, math.ceil(0.02 * total / per_epoch)))


@dataclass(frozen=True)
class Recipe:
    """A named way to train (a preset): how (:class:`TrainConfig`) and which model (:class:`ModelConfig`).

    The model's data-file fields (``system``, ``dt``, ``image_size``, ``channels``, ``n_objects``)
    are the file's whatever the recipe says: :func:`model_config_for` sets them.
    """

    train: TrainConfig = field(default_factory=TrainConfig)
    """The training schedule and optimiser."""
    model: ModelConfig = field(default_factory=ModelConfig)
    """The model; its data-file fields are replaced by the file's."""


#: Named recipes. 'fast' is the defaults themselves (:class:`TrainConfig`, :class:`ModelConfig`);
#: 'paper' follows the paper's appendix.
PRESETS: dict[str, Recipe] = {
    "fast": Recipe(),
    "paper": Recipe(
        TrainConfig(epochs=1000, lr=3e-4, lr_physics=3e-4, optimizer="rmsprop", schedule="step", lr_decay_epoch=500,
                    warmup_fraction=0.0, curriculum_fraction=0.0, grad_clip=0.0, average_fraction=0.0, physics_grad_clip=0.0),
        ModelConfig(substeps=5, system_options=PendulumOptions(learn_offset=True), readout="regress", rec_frames="all",
                    pred_trim=0.0, velocity_correction=True),
    ),
    # A continuous system filmed with a held action (a real motor, MuJoCo's 0.02 s physics steps):
    # RK4 within the frame, velocities read through it, and a learnable hinge damping.
    "continuous": Recipe(model=ModelConfig(integrator="rk4", substeps=2, velocity_hold=True,
                                           system_options=PendulumOptions(learn_damping=True))),
}


def _scene_model(system: Literal["spring", "gravity", "bouncing"], paper: bool = False, **changes: Any) -> ModelConfig:
    """A scene's model. What all ball and digit scenes share: a pixelwise mask term, the decoder's
    background content starting at the label-free median background, no trimming (nothing unmodelled
    to trim), and the paper's velocity MLP on top of the backward difference (at dt = 0.3 the difference
    alone is far from v_L: ω·dt ≈ 0.85 for the spring), with v_L read through the engine
    (``velocity_shoot``: the velocity the engine ends the last input interval with), L = 4 input and
    T_pred = 6 predicted frames (the published code's). The cubic Taylor term that it replaced
    (``velocity_physics``) left k and g about 1.5% low (``benchmarks/velocity_bias.py``). ``paper``:
    the paper's regressing location network and reconstruction of all frames. Templates are H/2
    (the published decoder's), set from the file by :func:`preset_for`."""
    shared = ModelConfig(system=system, input_frames=4, pred_frames=6, pred_trim=0.0, velocity_correction=True,
                         velocity_shoot=True, substeps=5, mask_pixelwise=True, alpha=2.0, init_background=True)
    if paper:
        shared = replace(shared, readout="regress", rec_frames="all")
    return replace(shared, **changes)


#: The scenes' fast schedule: 1650 steps (6 epochs of the default 1000 x 30-frame file), of which the
#: first 18% train the autoencoder alone and the next 36% grow the horizon, whatever the file's size.
_SCENE_FAST_TRAIN = TrainConfig(budget_steps=1650, warmup_fraction=0.18, curriculum_fraction=0.36, average_fraction=1 / 6,
                                window_stride=2)
#: The scenes' paper schedule (the paper's appendix).
_SCENE_PAPER_TRAIN = TrainConfig(epochs=500, lr=3e-4, lr_physics=3e-4, optimizer="rmsprop", schedule="step", lr_decay_epoch=375,
                                 warmup_fraction=0.0, curriculum_fraction=0.0, grad_clip=0.0, average_fraction=0.0,
                                 physics_grad_clip=0.0, batch_size=100)

#: Bouncing: nothing to learn; the wall distance is given, as the published engine hard-codes it.
_WALL_3 = BouncingOptions(wall_radius=3.0)

#: The scenes' recipes (``fast`` and ``paper``), by the file's attr ``scene`` (else its ``system``);
#: what they share: :func:`_scene_model`.
SCENE_PRESETS: dict[str, dict[str, Recipe]] = {
    "bouncing": {"fast": Recipe(_SCENE_FAST_TRAIN, _scene_model("bouncing", init_scale=1.0, system_options=_WALL_3)),
                 "paper": Recipe(_SCENE_PAPER_TRAIN, _scene_model("bouncing", paper=True, system_options=_WALL_3))},
    "spring": {"fast": Recipe(_SCENE_FAST_TRAIN, _scene_model("spring", init_scale=1.0)),
               "paper": Recipe(_SCENE_PAPER_TRAIN, _scene_model("spring", paper=True))},
    # Gravity: the paper's (L, T_pred, T_ext) = (4, 12, 24), as its published code's 3-body task (40-frame test sequences).
    "gravity": {"fast": Recipe(_SCENE_FAST_TRAIN, _scene_model("gravity", init_scale=1.0, pred_frames=12, extrapolate_frames=24)),
                "paper": Recipe(_SCENE_PAPER_TRAIN, _scene_model("gravity", paper=True, pred_frames=12, extrapolate_frames=24))},
    "digits-spring": {"fast": Recipe(_SCENE_FAST_TRAIN, _scene_model("spring", init_scale=2.0)),
                      "paper": Recipe(_SCENE_PAPER_TRAIN, _scene_model("spring", paper=True, init_scale=2.0))},
}


#: Presets whose epoch is one pass over the file's sequences, one window each (the paper's: 500 epochs of
#: its 5000 sequences are 25,000 steps at batch 100; every window of a 30-frame sequence would be 21 times as many).
ONE_WINDOW_PER_SEQUENCE = ("paper",)


def preset_for(name: str, info: DatasetInfo) -> Recipe:
    """The recipe ``name`` (a key of :data:`PRESETS`) for a data file: the pendulum's, or the scene's
    (:data:`SCENE_PRESETS`), whose templates are H/2 whatever the preset. A preset of
    :data:`ONE_WINDOW_PER_SEQUENCE` takes the first window of each sequence (its window stride is the file's
    sequence length)."""
    recipe = _preset(name, info)
    if name in ONE_WINDOW_PER_SEQUENCE:
        recipe = replace(recipe, train=replace(recipe.train, window_stride=max(info.steps, 1)))
    return recipe


def _preset(name: str, info: DatasetInfo) -> Recipe:
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; known: {', '.join(sorted(PRESETS))}")
    if info.system == "pendulum":
        return PRESETS[name]
    scene = str(info.attrs.get("scene", info.system))
    recipes = SCENE_PRESETS.get(scene) or SCENE_PRESETS.get(info.system)
    if recipes is None:
        raise ValueError(f"{info.path}: system {info.system!r} has no physics model; known: {', '.join(sorted(SYSTEM_SHAPES))}")
    if name not in recipes:
        raise ValueError(f"preset {name!r} is the pendulum's; a {scene} file has {', '.join(sorted(recipes))}")
    recipe = recipes[name]
    return replace(recipe, model=replace(recipe.model, template_size=max(info.image_shape[0] // 2, 1)))


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
    start: dict[str, float] = field(default_factory=dict)
    """The learned physical parameters before the first step."""
    trace: list[list[float]] = field(default_factory=list)
    """[step, value of each learned parameter (``start``'s order)] every few steps: the trajectory the
    convergence check reads."""
    average: list[list[float]] = field(default_factory=list)
    """Running Polyak average of the physical-parameter tensors (flattened), over the final steps so far."""
    average_count: int = 0
    """Steps in ``average``."""
    plan: dict[str, int] = field(default_factory=dict)
    """The run's :class:`TrainPlan` (as a dict), for the convergence check."""
    device: str = ""
    """The torch device the latest training ran on ("cpu", "cuda:0"; empty in runs saved before it was recorded)."""


#: The fewest frames the physics predicts in a training window (T_pred) when a file's sequences are
#: too short for the recipe's: below this a window says too little about the dynamics.
MIN_PRED_FRAMES = 4


def pred_frames_for(model: ModelConfig, steps: int) -> int:
    """T_pred for sequences of ``steps`` frames: the recipe's, or, when they are shorter than its window
    L + T_pred, the frames they hold after the L input frames, down to :data:`MIN_PRED_FRAMES` (a window
    still longer than the sequences is refused by :func:`check_trainable`)."""
    if steps >= model.window:
        return model.pred_frames
    return max(steps - model.input_frames, min(MIN_PRED_FRAMES, model.pred_frames))


def model_config_for(info: DatasetInfo, model: ModelConfig | None = None, n_objects: int | None = None) -> ModelConfig:
    """``model`` (None: the fast recipe's) fitted to a data file: system, dt, image size, channels and
    objects from its attributes (``n_objects``: the model's object slots instead, ``piga-train-model --objects``). Sequences shorter than the recipe's window L + T_pred shorten T_pred
    to what they hold, down to :data:`MIN_PRED_FRAMES` (:func:`check_trainable` refuses shorter ones)."""
    if info.system not in SYSTEM_SHAPES:
        raise ValueError(f"{info.path}: system {info.system!r} has no physics model; known: {', '.join(sorted(SYSTEM_SHAPES))}")
    actions = SYSTEM_SHAPES[info.system][2]
    if info.action_dim != actions:  # a pendulum file labelled 'spring' trained as a scene, and blamed a lost object
        raise ValueError(f"{info.path}: its attribute 'system' says {info.system!r}, whose model takes {actions} action "
                         f"dimension(s), but /actions has {info.action_dim}; fix the attribute, or the file")
    shape = info.image_shape
    if shape[0] != shape[1]:
        raise ValueError(f"{info.path}: frames of {shape[0]}x{shape[1]} px; the model takes square frames: crop or "
                         "resize them (piga-import crops a video's or an image stack's centre square and resizes it to "
                         "--image-size)")
    if shape[0] < MIN_IMAGE_SIZE:
        raise ValueError(f"{info.path}: frames of {shape[0]}x{shape[1]} px are too small to learn from; "
                         f"at least {MIN_IMAGE_SIZE}x{MIN_IMAGE_SIZE}")
    channels = info.channels
    if n_objects is None:
        n_objects = int(info.attrs.get("n_objects", SYSTEM_SHAPES[info.system][0]))
    model = model or ModelConfig()
    options = model.system_options
    if model.system != info.system:  # another system's model: only its default options make way for the file's
        if options != type(options)():
            raise ValueError(f"{info.path}: {options} are a {model.system} model's, not a {info.system} model's")
        options = None
    return replace(model, system=info.system, system_options=options, dt=info.dt, image_size=shape[0], channels=channels,
                   n_objects=n_objects, pred_frames=pred_frames_for(model, info.steps))


def _optimizer(model: FrameModel, config: TrainConfig) -> torch.optim.Optimizer:
    physics = model.physics_parameters()  # none for a model without physics: its group stays empty
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


def save_checkpoint(path: Path, model: FrameModel, optimizer: torch.optim.Optimizer, state: TrainState,
                    train_config: TrainConfig, data_info: DatasetInfo, plan: TrainPlan, data_fingerprint: str) -> None:
    """Writes everything needed to resume or to use the model, atomically. ``data_fingerprint``:
    :func:`piga.data.schema.fingerprint` of the training file (read once per run, not per checkpoint)."""
    payload = {
        "model_config": model.config.to_dict(),
        "train_config": asdict(train_config),
        "plan": asdict(plan),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "state": asdict(state),
        "rng": _rng_state(),
        # the path as given, and the folder it is relative to (where the command ran)
        "data": {"path": str(data_info.path), "folder": os.getcwd(), "system": data_info.system,
                 "image_shape": list(data_info.image_shape),
                 "dt": data_info.dt, "sequences": data_info.n_sequences, "steps": data_info.steps,
                 "fingerprint": data_fingerprint, "env_id": data_info.attrs.get("env_id"),  # (None: not collected)
                 "env_config": data_info.attrs.get("env_config")},  # the env's settings, kept where the file is gone
    }
    write_checkpoint(path.parent, payload)


def _background(data: str | Path, channels: int, seed: int, max_frames: int = 2000) -> torch.Tensor:
    """Label-free background of the training frames: a per-pixel median over up to ``max_frames``, drawn
    at random from all of them. Only the sequences drawn from are read, one at a time, so a file
    larger than memory is not loaded."""
    sequences = split_indices(data, "train")
    steps = inspect_dataset(data).steps
    pick = np.sort(np.random.default_rng(seed).choice(len(sequences) * steps, size=min(max_frames, len(sequences) * steps),
                                                      replace=False))  # flat indices into the split's (n·T) frames
    with open_data_file(data) as f, read_rows(f["frames"], "the training sequences sampled for the background"):
        chosen = [f["frames"][int(sequences[row])][pick[pick // steps == row] % steps] for row in np.unique(pick // steps)]
    sample = frames_to_float(torch.from_numpy(np.concatenate(chosen))[:, None], channels)[:, 0]  # (F, C, H, W)
    return estimate_background(sample)


def resolve_loading(config: TrainConfig, info: DatasetInfo) -> TrainConfig:
    """``config`` with its data reading made concrete for the file (:attr:`TrainConfig.data_loading`
    "auto" decided, the cache capped at a quarter of the available memory), as the run records it."""
    from piga.io.resources import available_memory

    available = available_memory()
    loading = config.data_loading
    if loading == "auto":
        loading = "memory" if loads_whole(info.split_counts["train"] * info.sequence_bytes,
                                          available) else "stream"
    cache = config.stream_cache_mb if available is None else max(1, min(config.stream_cache_mb, available // 4 // 2**20))
    return replace(config, data_loading=loading, stream_cache_mb=cache)


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


def _lr_factor(step: int, epoch: int, plan: TrainPlan, config: TrainConfig) -> float:
    """Multiplier of the learning rates at a step (see ``TrainConfig.schedule``)."""
    if config.schedule == "step":
        return 1.0 / config.lr_decay_factor if config.lr_decay_epoch and epoch >= config.lr_decay_epoch else 1.0
    span = max(plan.total_steps - plan.warmup_steps, 1)
    progress = min(max(step - plan.warmup_steps, 0) / span, 1.0)
    low = config.lr_final_fraction
    return low + (1 - low) * 0.5 * (1 + math.cos(math.pi * progress))


def physics_lr(step: int, plan: dict[str, int], config: TrainConfig) -> float:
    """The physical parameters' learning rate at ``step`` of a run planned as ``plan`` (its :class:`TrainPlan` as a
    dict): the convergence check measures a parameter's last movements against it."""
    schedule = TrainPlan(**plan)
    return config.lr_physics * _lr_factor(step, step // max(schedule.steps_per_epoch, 1), schedule, config)


def _horizon(step: int, plan: TrainPlan, t_pred: int) -> int:
    """Prediction frames at a given step: 0 during warm-up, then growing to T_pred."""
    if step < plan.warmup_steps:
        return 0
    if plan.curriculum_steps <= 0:
        return t_pred
    frac = (step - plan.warmup_steps) / plan.curriculum_steps
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

    def close(self, quiet: bool = False) -> None:
        """Closes the writer (once); ``quiet``: whatever it raises is dropped (another error is being raised)."""
        writer, self.writer = self.writer, None
        if writer is not None:
            try:
                writer.close()
            except Exception:
                if not quiet:
                    raise


def _last_good(ckpt_path: Path) -> str:
    return f"last good checkpoint: {ckpt_path}" if ckpt_path.exists() else "no checkpoint was written yet"


def _shown(params: dict[str, float]) -> str:
    return ", ".join(f"{k}={v:.4g}" for k, v in params.items())


@torch.no_grad()
def _accumulate_average(state: TrainState, params: list[torch.Tensor], restart: bool) -> None:
    """Adds the current physical parameters to the running Polyak average kept in ``state`` (so a
    resumed run continues it exactly); ``restart`` begins a new one."""
    if restart or not state.average:
        state.average = [[0.0] * p.numel() for p in params]
        state.average_count = 0
    state.average_count += 1
    for i, p in enumerate(params):
        avg = torch.tensor(state.average[i], dtype=p.dtype, device=p.device)
        avg += (p.detach().flatten() - avg) / state.average_count
        state.average[i] = avg.tolist()


def check_trainable(info: DatasetInfo, model_config: ModelConfig, train_config: TrainConfig) -> TrainPlan:
    """Refuses, before anything is written, data that training cannot use; returns the run's plan.

    Raises:
        ValueError (a :class:`piga.data.schema.DataFormatError` for the file's contents): sequences shorter
        than a window, an empty train split, non-finite or absurd actions, or fewer windows than
        one batch (no step would run).
    """
    needed = model_config.window
    if info.steps < needed:
        from envs.fields import counted  # here: training runs without gymnasium's import

        raise ValueError(f"{info.path}: sequences have {counted(info.steps, 'frame')}; training needs at least "
                         f"L + T_pred = {model_config.input_frames} + {model_config.pred_frames} = {needed}")
    n_train = info.split_counts["train"]
    if not n_train:
        raise ValueError(f"{info.path}: the train split is empty")
    actions = check_actions_file(info.path)  # (N, T, A), small
    if info.system == "pendulum" and model_config.architecture != "video-lstm" and info.action_dim:
        # a multiplies the actions: with every one of the train split 0 it never leaves its start
        if not np.any(actions[split_indices(info.path, "train")]):
            raise DataFormatError(f"{info.path}: every action of its train split is 0, so the actuation gain a, which "
                                  "multiplies them, cannot be identified; train on data whose actions vary "
                                  "(piga-collect's random actions, or a recording with the motor driven)")
    windows = n_train * len(range(0, info.steps - needed + 1, train_config.window_stride))
    try:
        return plan_training(train_config, windows, (n_train, info.steps - needed + 1))
    except ValueError as exc:
        from envs.fields import counted  # here: training runs without gymnasium's import

        raise ValueError(f"{info.path}: {exc} ({counted(n_train, 'train sequence')})") from None


def train(
    data: str | Path,
    run_dir: str | Path,
    train_config: TrainConfig,
    model_config: ModelConfig | None = None,
    resume: bool = False,
    progress: bool = True,
    on_epoch: Callable[[TrainState, FrameModel], None] | None = None,
    n_objects: int | None = None,
    data_fingerprint: str | None = None,
) -> tuple[FrameModel, TrainState]:
    """Trains on the train split of ``data``; writes checkpoints and TensorBoard scalars to ``run_dir``.

    Nothing is written (not even ``run_dir``) before the first checkpoint, at the end of the first
    epoch (or of the first ``plan.checkpoint_every`` epochs of a small file); the data are checked
    first (:func:`check_trainable`). ``on_epoch`` is called after each checkpoint.

    With ``resume``, the model, optimiser, step and RNGs come from ``run_dir``'s checkpoint and
    ``train_config`` should be the run's saved one (``TrainConfig.from_dict(ckpt["train_config"])``),
    possibly with more ``epochs``; ``model_config`` is ignored. Otherwise the model is ``model_config``
    (None: the fast recipe's) fitted to the file (:func:`model_config_for`), with ``n_objects`` object slots
    (None: the file's count); ``data_fingerprint``: :func:`~piga.data.schema.fingerprint` of ``data`` where the caller
    took it already (it decodes every frame), else taken here. Resuming with the same
    ``epochs`` continues exactly. With more ``epochs``, the cosine schedule is replanned over the
    new total: from the resumed step on, the learning rates are those a straight run of the new
    length has at that step (they rise again if the old run had finished its cosine), while the
    steps already taken keep the old schedule (and, if the old run finished, its final
    average of the physical parameters); so the result is close to, not identical with, the
    straight run.

    The model trains on ``train_config.device`` (:func:`piga.io.device.resolve_device`; ``on_epoch`` sees it
    there) and is returned on the CPU, where evaluation, control and diagnosis run. Its initialisation,
    the background estimate and every random draw happen on the CPU whatever the device.

    Returns:
        The trained model (eval mode, on the CPU) and the final :class:`TrainState`.

    Raises:
        ValueError: ``train_config.device`` is "cuda" and torch sees no CUDA device (before anything is read).
    """
    if not isinstance(train_config, TrainConfig):
        raise TypeError(f"train_config must be a TrainConfig, got {type(train_config).__name__}")
    if model_config is not None and not isinstance(model_config, ModelConfig):
        raise TypeError(f"model_config must be a ModelConfig or None, got {type(model_config).__name__}")
    device = resolve_device(train_config.device)
    run_dir = Path(run_dir)
    folder = OutputFolder(run_dir)  # moved or removed while the run trains: said, not made again
    info = inspect_dataset(data)
    data_fingerprint = data_fingerprint or fingerprint(data)
    ckpt_path = run_dir / CHECKPOINT
    set_threads(train_config.threads, "TrainConfig")
    state = TrainState()
    if resume:
        model, ckpt = load_model(run_dir, any_model=True)  # on the CPU, wherever it was saved
        model.to(device).train()
        optimizer = _optimizer(model, train_config)
        with resuming_from(ckpt_path, RunKind.PIGA):
            optimizer.load_state_dict(ckpt["optimizer"])  # its moments follow the parameters to the device
            state = TrainState(**ckpt["state"])
            _set_rng_state(ckpt["rng"])
        check_counts(ckpt_path, RunKind.PIGA, step=state.step, epoch=state.epoch)
    else:
        fitted = model_config_for(info, model_config, n_objects)
        check_trainable(info, fitted, train_config)
        torch.manual_seed(train_config.seed)
        np.random.seed(legacy_seed(train_config.seed))
        random.seed(train_config.seed)
        model = build_model(fitted)  # piga's, or a baseline of ModelConfig.architecture
        model.set_background(_background(data, model.config.channels, train_config.seed))
        model.to(device)
        optimizer = _optimizer(model, train_config)
        learned = model.learned_parameter_names()
        state.start = {k: v for k, v in model.physical_parameters().items() if k in learned}
    cfg = model.config
    plan = check_trainable(info, cfg, train_config)
    state.plan = asdict(plan)
    state.device = str(device)
    cuda = device.type == "cuda"  # batches go through pinned memory, copied while the GPU works
    if not resume or train_config.data_loading == "auto":  # a resumed run reads as it did (a run saved before the choice: auto)
        train_config = resolve_loading(train_config, info)
    windows = SequenceWindows(data, "train", window=cfg.window, stride=train_config.window_stride,
                              in_memory=train_config.data_loading == "memory", cache_bytes=train_config.stream_cache_mb * 2**20)
    writer = _Scalars()
    physics_params = [p for p in model.physics_parameters() if p.requires_grad]
    physics_ids = {id(p) for p in physics_params}
    net_params = [p for p in model.parameters() if id(p) not in physics_ids]
    average_from = plan.total_steps - plan.average_steps  # the first step of the final average
    trace_every = max(1, plan.total_steps // 1000)
    model.train()
    started = time.monotonic() - state.elapsed
    try:
        while state.epoch < plan.epochs:
            if train_config.max_minutes and state.elapsed > train_config.max_minutes * 60:
                break
            # The sampler's generator depends on (seed, epoch) only, so a resumed run sees the same order.
            gen = torch.Generator().manual_seed((train_config.seed * 100_003 + state.epoch) % 2**63)  # torch: int64
            sampler = (RandomSampler(windows, generator=gen) if windows.in_memory
                       else BlockShuffleSampler(windows, windows.sequences_cached, generator=gen))
            loader = DataLoader(windows, batch_size=train_config.batch_size, sampler=sampler, drop_last=True, pin_memory=cuda)
            sums = {"loss": 0.0, "loss_pred": 0.0, "loss_rec": 0.0}
            count = 0
            bar = tqdm(loader, desc=f"epoch {state.epoch + 1}/{plan.epochs}", leave=False, disable=not progress)
            for batch in bar:
                factor = _lr_factor(state.step, state.epoch, plan, train_config)
                for group in optimizer.param_groups:
                    group["lr"] = factor * (train_config.lr if group["name"] == "nets" else train_config.lr_physics)
                horizon = _horizon(state.step, plan, cfg.pred_frames)
                frames = batch.frames.to(device, non_blocking=cuda)  # uint8 (B, L+T, H, W[, C]); the model scales it
                actions = batch.actions.to(device, non_blocking=cuda)  # (B, L+T, A)
                out = model(frames, actions, pred_frames=max(horizon, 1))
                # warm-up trains the autoencoder alone on α·L_rec; "pred-only" never trains on L_rec, so its
                # warm-up steps predict one frame (the horizon's floor) instead
                loss = out.loss if horizon > 0 or cfg.loss == "pred-only" else cfg.alpha * out.loss_rec
                if not torch.isfinite(loss):
                    raise TrainingDiverged(f"loss became {loss.item()} at step {state.step + 1} (epoch {state.epoch + 1}); "
                                           + _last_good(ckpt_path))
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                if train_config.physics_grad_clip and train_config.optimizer == "adam":
                    _clip_to_running_rms(optimizer, physics_params, train_config.physics_grad_clip)
                if train_config.grad_clip:
                    torch.nn.utils.clip_grad_norm_(net_params, train_config.grad_clip)
                optimizer.step()
                if plan.average_steps and state.step >= average_from:
                    _accumulate_average(state, physics_params, restart=state.step == average_from)
                state.step += 1
                count += 1
                params = model.physical_parameters()
                if not all(math.isfinite(v) for v in params.values()):
                    raise TrainingDiverged(f"the physical parameters became non-finite at step {state.step} "
                                           f"({_shown(params)}); lower --lr-physics; " + _last_good(ckpt_path))
                if state.step % trace_every == 0 and state.start:
                    state.trace.append([float(state.step), *(params[k] for k in state.start)])
                for key in sums:
                    sums[key] += float(getattr(out, key).detach()) if key != "loss" else float(loss.detach())
                if state.step % 10 == 0:
                    bar.set_postfix({k: f"{v:.4g}" for k, v in params.items() if k != "offset"} | {"loss": f"{loss.item():.4f}", "T": horizon})
                    for name, value in params.items():
                        writer.add(f"physics/{name}", value, state.step)
                    writer.add("loss/total", loss.item(), state.step)
                    writer.add("loss/pred", out.loss_pred.item(), state.step)
                    writer.add("loss/rec", out.loss_rec.item(), state.step)
                    writer.add("train/horizon", horizon, state.step)
                    writer.add("train/lr_factor", factor, state.step)
            bar.close()
            if plan.average_steps and state.step == plan.total_steps and state.average_count:
                with torch.no_grad():
                    for avg, p in zip(state.average, physics_params):
                        p.copy_(torch.tensor(avg, dtype=p.dtype, device=p.device).view_as(p))
            state.epoch += 1
            state.elapsed = time.monotonic() - started
            record = {k: v / max(count, 1) for k, v in sums.items()}
            record.update(model.physical_parameters())
            record.update({"epoch": state.epoch, "step": state.step, "seconds": state.elapsed})
            state.history.append(record)
            last = state.epoch == plan.epochs or bool(train_config.max_minutes and state.elapsed > train_config.max_minutes * 60)
            if state.epoch % plan.checkpoint_every == 0 or last:
                folder.make()
                save_checkpoint(ckpt_path, model, optimizer, state, train_config, info, plan, data_fingerprint)
                folder.check()  # before TensorBoard's writer makes its folder, and so the run's, again
                writer.open(run_dir / "tensorboard")
                (tqdm.write if progress else print)(
                    f"epoch {state.epoch}: loss {record['loss']:.5f} (pred {record['loss_pred']:.5f}, rec "
                    f"{record['loss_rec']:.5f}), " + "".join(f"{_shown(p)}, " for p in [model.physical_parameters()] if p)
                    + f"{state.elapsed / 60:.1f} min")
                if on_epoch is not None:
                    on_epoch(state, model)
    except BaseException as exc:
        writer.close(quiet=True)  # what it raises as it closes (its thread's failure, again) would hide this error
        if isinstance(exc, FileNotFoundError) and not isinstance(exc, FolderMovedError):
            folder.check()  # TensorBoard's writer raises its thread's failure to write in a folder moved away
        raise
    finally:
        writer.close()
        windows.close()
    model.eval()
    return model.cpu(), state
