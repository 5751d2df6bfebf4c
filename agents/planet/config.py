"""Settings of the PlaNet-style baseline: plain dataclasses, no torch, so that command lines read their defaults quickly.

PlaNet (Hafner et al., 2019) is sized for a GPU. Each field below that departs from it says so, and
why: the model must train in tens of minutes on a 2-core CPU. docs/commands/baseline.md lists
the departures in one table.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from agents.config import CEMConfig
from piga.data.schema import MAX_SEED
from piga.io.choices import check_choices, check_ranges, check_types
from piga.io.device import Device

#: Largest KL free nats per frame accepted (PlaNet uses 3; far larger values switch the KL term off
#: entirely and, near float32's range, overflow the loss).
MAX_FREE_NATS = 1000.0
#: Most optimiser steps a run may take, in its training and over all its iterative rounds together: weeks on a CPU
#: (PlaNet's own runs take a few million); --steps 1e20 was taken, and trained for ever.
MAX_STEPS = 10_000_000
#: Smallest reward weight. The reward head learns only from the reward term, whose gradients the weight scales;
#: Adam divides them by their running size plus ``adam_eps`` (1e-4), so once they shrink toward that epsilon the
#: head's steps shrink with them (a weight of 1e-300 made the term exactly 0 in float32: the head never learnt).
#: PlaNet's code uses 10; 1e-3 leaves room for any tuning.
MIN_REWARD_SCALE = 1e-3
#: Largest reward weight: six orders above PlaNet's 10, where the reward term's gradient already drowns the frames'
#: (--reward-scale 1e308 overflowed the loss to inf at the first step, refused only as a divergence).
MAX_REWARD_SCALE = 1e6
#: Most hidden layers of the reward head (PlaNet's has 3): --reward-layers 100000 built a head of a billion weights
#: that passed the memory check and then trained for hours without a word.
MAX_REWARD_LAYERS = 100
#: Largest exploration noise accepted, as a fraction of the action bound (the noisy action is then clipped).
MAX_EXPLORATION_NOISE = 10.0


RewardAlignment = Literal["frame", "transition"]
"""Which latent state the reward head reads for the summed reward of a model step's R actions (the
actions after frame t·R): ``frame``, the state of frame t·R, before the actions; ``transition``,
PlaNet's, the state they lead to, whose transition input holds them (:mod:`agents.planet.rssm`)."""


@dataclass(frozen=True)
class RSSMConfig:
    """The recurrent state-space model: sizes of its parts."""

    image_size: int = 64
    """Side of the square gray frames."""
    channels: int = 1
    """Colour channels of a frame (1: gray)."""
    action_dim: int = 1
    """A."""
    deter_size: int = 100
    """Size of the deterministic GRU state h (PlaNet: 200; halved for CPU time, the GRU and every head scale with it)."""
    stoch_size: int = 16
    """Size of the stochastic Gaussian state s (PlaNet: 30; the pendulum has two degrees of freedom)."""
    hidden_size: int = 100
    """Width of the MLPs around the GRU and, with ``reward_units`` 0, of the reward head (PlaNet: 200, halved with
    ``deter_size``)."""
    reward_layers: int = 2
    """Hidden layers of the reward head (PlaNet: 3, its ``configs.py``'s ``head_network``)."""
    reward_units: int = 0
    """Width of the reward head's hidden layers (0: ``hidden_size``; PlaNet: 300). Run at PlaNet's sizes in
    benchmarks/planet_faithful.py (``planet-sizes``)."""
    depth: int = 16
    """Channels of the first conv layer, doubled at each of the four (PlaNet: 32; the convs are ~80% of
    a training step's time on a CPU, and a gray 64x64 pendulum needs less capacity than RGB scenes)."""
    min_std: float = 0.1
    """Floor on the standard deviation of the stochastic state (PlaNet's 0.1)."""
    action_repeat: int = 2
    """R, env steps per model step (PlaNet: 2 to 8 on its DMC tasks). The model sees every R-th frame,
    takes the R actions in between as one input of R·A numbers (random-action data change the action
    at every env step), and predicts their summed reward; the planner holds each action for R steps.
    With 2, PlaNet's 12 planning steps look 1.2 s ahead, and the model swings up and holds at 6000
    steps, where the same training with R = 1 did not (results/planet_tuning.md)."""

    reward_alignment: RewardAlignment = "frame"
    """Which state the reward head reads (:data:`RewardAlignment`). ``frame`` (the default, that of the
    committed results) reads the state before the actions, which cannot see them: the pendulum's
    action cost, and at an action repeat of 2 the second step's reward, which depends on where the
    first action took the pendulum. ``transition`` is PlaNet's, a function of what the head sees; the
    planner reads the head the same way under both (the state after each imagined action)."""

    def __post_init__(self) -> None:
        check_choices(self)
        if self.image_size != 64:
            raise ValueError(f"the PlaNet encoder and decoder are built for 64x64 frames, got image_size={self.image_size}")
        for name in ("channels", "action_dim", "deter_size", "stoch_size", "hidden_size", "reward_layers", "depth",
                     "action_repeat"):
            if getattr(self, name) < 1:
                raise ValueError(f"RSSMConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.reward_layers > MAX_REWARD_LAYERS:
            raise ValueError(f"RSSMConfig.reward_layers (--reward-layers) must be at most {MAX_REWARD_LAYERS} (PlaNet uses 3), "
                             f"got {self.reward_layers}")
        if self.reward_units < 0:
            raise ValueError(f"RSSMConfig.reward_units must be >= 0 (0: hidden_size), got {self.reward_units}")
        check_ranges(self, {"min_std": (0, math.inf)}, above=("min_std",))

    @property
    def input_action_size(self) -> int:
        """Size of the transition's action input: the R actions of a model step, R·A."""
        return self.action_repeat * self.action_dim

    @property
    def embed_size(self) -> int:
        """Size of the encoder's output: 8·depth channels on a 2x2 grid."""
        return 8 * self.depth * 4

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy."""
        return asdict(self)


@dataclass(frozen=True)
class PlanetTrainConfig:
    """How the RSSM is trained on a data file's random-action sequences."""

    steps: int = 12000
    """Optimiser steps (PlaNet: 100 per collected episode, ~5e5 in all; here the data are fixed). At
    6000 steps the loss still fell and success on 2000 sequences depended on the seed (10% and 30% of
    20 episodes); the same runs continued to 12000 reached 100% for both (results/planet_tuning.md)."""
    batch_size: int = 16
    """Sequences per batch (PlaNet: 50; CPU time per step is linear in it)."""
    chunk_length: int = 20
    """Model steps per training sequence (PlaNet: 50). With an action repeat R a chunk spans
    chunk_length·R frames: 20 x 2 = piga-collect's default 40-frame sequences."""
    lr: float = 1e-3
    """Adam's learning rate (PlaNet's)."""
    adam_eps: float = 1e-4
    """Adam's epsilon (PlaNet's)."""
    grad_clip: float = 1000.0
    """Global gradient-norm clip (PlaNet's)."""
    free_nats: float = 0.25
    """The KL term is max(KL, free_nats) (PlaNet: 3). The pendulum's posterior needs fewer nats per
    frame than PlaNet's scenes: with 3 the KL settled at 2.4, under the floor, so the prior got no
    gradient and its open-loop frames were worse than the mean frame after ~8 steps; with 1 they
    track the real ones over 35 frames, and with 0.25 the open-loop reward error halves again
    (results/planet_tuning.md)."""
    kl_scale: float = 1.0
    """Weight of the KL term (PlaNet's 1; PlaNet's latent overshooting is not used, as in its later releases)."""
    reward_scale: float = 1.0
    """Weight of the reward term."""
    checkpoint_every: int = 250
    """Steps between atomic checkpoints (and one line of the learning curve)."""
    seed: int = 0
    """Seed of initialisation, batch sampling and the stochastic states."""
    threads: int = 0
    """torch CPU threads (0: leave torch's default)."""
    device: Device = "auto"
    """Where to train (:mod:`piga.io.device`): "auto" (a CUDA GPU when torch sees one, else the CPU), "cpu" or
    "cuda". Not part of the recipe: a run resumes on any device. The batches and the latent samples are
    drawn on the CPU whatever the device; the trained model is returned, and planned with, on the CPU."""
    max_minutes: float = 0.0
    """Stop at the first checkpoint past this budget (0: no limit)."""
    max_sequences: int = 0
    """Use only the first N training sequences of the file (0: all), for sample-efficiency sweeps."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        for name, least in (("steps", 1), ("batch_size", 1), ("chunk_length", 2), ("checkpoint_every", 1)):
            if getattr(self, name) < least:
                why = " (a sequence: the first step is only observed)" if name == "chunk_length" else ""
                raise ValueError(f"PlanetTrainConfig.{name} must be >= {least}{why}, got {getattr(self, name)}")
        infinite = [f"{n}={getattr(self, n)}" for n in ("lr", "adam_eps", "grad_clip", "free_nats", "kl_scale",
                                                         "reward_scale", "max_minutes") if not math.isfinite(getattr(self, n))]
        if infinite:  # (the whole config was printed: 600 characters to find the one)
            raise ValueError(f"PlanetTrainConfig: {', '.join(infinite)}; each must be a finite number")
        if not (self.lr > 0 and self.adam_eps > 0 and self.grad_clip > 0 and self.free_nats >= 0):
            raise ValueError("need lr, adam_eps, grad_clip > 0 and free_nats >= 0")
        if not self.reward_scale >= MIN_REWARD_SCALE:
            from envs.fields import number_text  # here: the config is read without gymnasium's import

            raise ValueError(f"PlanetTrainConfig.reward_scale (--reward-scale) must be at least {MIN_REWARD_SCALE:g}, got "
                             f"{number_text(self.reward_scale)}: below it the reward head barely learns (at 0, never), and the planner "
                             "ranks its plans by that head")
        if self.reward_scale > MAX_REWARD_SCALE:
            from envs.fields import number_text  # here: the config is read without gymnasium's import

            raise ValueError(f"PlanetTrainConfig.reward_scale (--reward-scale) must be at most {MAX_REWARD_SCALE:g}, got "
                             f"{number_text(self.reward_scale)}: above it the reward term drowns the frames' (PlaNet's code uses 10)")
        if self.steps > MAX_STEPS:
            raise ValueError(f"PlanetTrainConfig.steps (--steps) must be at most {MAX_STEPS:,} (weeks on a CPU), got {self.steps:,}")
        if self.free_nats > MAX_FREE_NATS:
            from envs.fields import number_text  # here: the config is read without gymnasium's import

            raise ValueError(f"PlanetTrainConfig.free_nats (--free-nats) must be at most {MAX_FREE_NATS:g} nats per frame (PlaNet uses 3), got {number_text(self.free_nats)}")
        if self.seed < 0 or self.max_sequences < 0 or self.max_minutes < 0 or self.threads < 0 or self.kl_scale < 0:
            raise ValueError(f"PlanetTrainConfig: seed, max_sequences, max_minutes, threads and kl_scale must be >= 0, got "
                             f"seed={self.seed}, max_sequences={self.max_sequences}, max_minutes={self.max_minutes}, "
                             f"threads={self.threads}, kl_scale={self.kl_scale}")
        if self.seed > MAX_SEED:
            raise ValueError(f"PlanetTrainConfig.seed must be <= {MAX_SEED} (2^63 - 1), got {self.seed}")
        check_choices(self)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy."""
        return asdict(self)


@dataclass(frozen=True)
class IterativeConfig:
    """PlaNet's own data loop, after training on the data file: each round collects ``episodes``
    episodes with the latent planner plus Gaussian exploration noise, adds them to the training
    data, and trains ``steps_per_round`` more optimiser steps on the file and everything collected."""

    rounds: int = 10
    """Collect-then-train rounds after the first training."""
    episodes: int = 1
    """Episodes collected per round (PlaNet: 1 per collection interval)."""
    steps_per_round: int = 100
    """Optimiser steps after each round's collection (PlaNet: 100 per collected episode)."""
    episode_steps: int = 200
    """Env steps per collected episode (Pendulum-v1's episode length); cut into sequences of the data file's length."""
    noise: float = 0.3
    """Std of the Gaussian exploration noise added to the planner's action, as a fraction of the action
    bound (PlaNet's 0.3 for actions in [-1, 1]; here 0.6 for the pendulum's [-2, 2]); then clipped."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        if self.rounds < 1 or self.episodes < 1 or self.steps_per_round < 1 or self.episode_steps < 1:
            raise ValueError(f"need rounds, episodes, steps_per_round and episode_steps >= 1, got {self.rounds}, "
                             f"{self.episodes}, {self.steps_per_round}, {self.episode_steps}")
        if self.rounds * self.steps_per_round > MAX_STEPS:
            raise ValueError(f"IterativeConfig: rounds x steps_per_round (--rounds x --round-steps) = {self.rounds:,} x "
                             f"{self.steps_per_round:,} must be at most {MAX_STEPS:,} optimiser steps (weeks on a CPU)")
        if not 0 <= self.noise <= MAX_EXPLORATION_NOISE:
            raise ValueError(f"IterativeConfig.noise: the exploration noise must be >= 0 and at most "
                             f"{MAX_EXPLORATION_NOISE:g} (a fraction of the action bound), got {self.noise}")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy."""
        return asdict(self)


@dataclass(frozen=True)
class LatentPlannerConfig:
    """CEM in the RSSM's latent space. The defaults are PlaNet's: horizon 12, 10 iterations, 1000
    candidates, the best 100 refit, re-planned from scratch at every step, and the first action of
    the final mean executed."""

    cem: CEMConfig = field(default_factory=CEMConfig)
    """CEM settings (:class:`agents.config.CEMConfig`'s defaults are PlaNet's)."""
    seed: int = 0
    """Seed of the planner's RNG (candidate actions and imagined stochastic states)."""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy."""
        return asdict(self)
