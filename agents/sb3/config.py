"""The settings of an SB3 baseline run: DDPG, SAC or DrQ-v2, as variants of one config.

Each algorithm's defaults are the SB3 zoo's tuned ones for Pendulum-v1 (rl-baselines3-zoo,
``hyperparams/ddpg.yml`` and ``hyperparams/sac.yml``) or, for DrQ-v2, its paper's for DMC's easy tasks
(:data:`ALGORITHM_PRESETS`); each observation
may change some of them (:data:`PRESETS`). A field left unset takes, in order, the observation's
preset, then the algorithm's value: so ``SB3Config(algo="sac")`` has SAC's values, never DDPG's.
Build a new config to change ``algo`` or ``obs`` (``dataclasses.replace`` keeps the values already set).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Literal, get_args

from envs import DMC_PENDULUM, PIXEL_PENDULUM, EnvId
from envs.dmc import DMCPendulumConfig
from envs.fields import number_text
from envs.pendulum import PixelPendulumConfig
from piga.data.schema import MAX_SEED
from piga.io.choices import check_choices
from piga.io.device import Device

__all__ = ["ALGORITHMS", "ALGORITHM_PRESETS", "PRECISIONS", "Precision", "resolve_precision", "bfloat16_in_hardware", "ENV_EPISODE_STEPS", "EPISODE_STEPS", "LEARNED_RETURN", "MAX_LEARNING_RATE", "OBSERVATIONS", "PRESETS", "Algorithm", "Observation", "SB3Config", "DMC_VIEWS", "VIEWS", "View"]

Observation = Literal["pixels", "latent", "state"]
"""What the policy sees."""
Precision = Literal["auto", "float32", "bfloat16"]
"""DrQ-v2's encoder arithmetic: float32, bfloat16 (torch's autocast over the convolutions; the actor, the critic and
their losses stay float32), or auto (:func:`resolve_precision`)."""
View = Literal["face", "fixed", "drqv2"]
"""How the DMC pendulum is seen: piga's face-on camera in 64x64 gray; dm_control's camera 0 in 64x64 gray (the camera
alone changed); or DrQ-v2's own view, dm_control's camera 0 in 84x84 RGB (:data:`DMC_VIEWS`)."""
Algorithm = Literal["ddpg", "sac", "drqv2"]
"""The algorithm: SB3's DDPG (the paper's) or SAC (its stronger sibling), or DrQ-v2 in SB3's loop
(:mod:`agents.sb3.drqv2`; pixels only)."""
#: The DMC pendulum's config fields of each view.
DMC_VIEWS: dict[View, dict[str, Any]] = {"face": {}, "fixed": {"camera": "fixed"},
                                         "drqv2": {"camera": "fixed", "color": "rgb", "image_size": 84}}
#: The views.
VIEWS: tuple[View, ...] = get_args(View)
#: Most env steps a run may take: 300 times the paper's 30k, weeks on a CPU; --steps 1e20 was taken and ran for ever.
MAX_STEPS = 10_000_000
#: Most episodes per evaluation, as piga-control's most episodes; --eval-episodes 1e11 was taken and evaluated for ever.
MAX_EVAL_EPISODES = 10_000
#: What the policy can observe.
OBSERVATIONS: tuple[Observation, ...] = get_args(Observation)
#: The SB3 algorithms.
ALGORITHMS: tuple[Algorithm, ...] = get_args(Algorithm)
#: The encoder precisions.
PRECISIONS: tuple[Precision, ...] = get_args(Precision)
#: Pendulum-v1's episode length (its TimeLimit).
EPISODE_STEPS = 200
#: DrQ-v2's random warm-up, in its frames (physics steps; its ``num_seed_frames``). Its exploration schedule, by
#: contrast, counts env steps (its ``global_step``), as ``SB3Config.noise_decay_steps`` does.
DRQV2_SEED_FRAMES = 4000
#: Each env's episode length in env steps (DMC's: 1000 physics steps at its default action repeat of 2).
ENV_EPISODE_STEPS: dict[EnvId, int] = {PIXEL_PENDULUM: EPISODE_STEPS, DMC_PENDULUM: DMCPendulumConfig().frames_per_episode}
#: Physics steps per env step (the action held over them): DrQ-v2's paper counts each as a frame.
ENV_ACTION_REPEAT: dict[EnvId, int] = {PIXEL_PENDULUM: 1, DMC_PENDULUM: DMCPendulumConfig().action_repeat}
#: The evaluation return that counts as learning to swing up: Pendulum-v1's -200 (the SB3 zoo's mark) and, on
#: DMC's 0-1000 scale, 200 (random actions score near 0 there: they rarely bring the pole within 8 degrees of upright).
LEARNED_RETURN: dict[EnvId, float] = {PIXEL_PENDULUM: -200.0, DMC_PENDULUM: 200.0}

#: Each algorithm's zoo values for Pendulum-v1. DDPG (``ddpg.yml``): gamma 0.98, buffer 200000, learning
#: starts 10000, Gaussian action noise of std 0.1 (in SB3's [-1, 1] action scale), net_arch [400, 300].
#: SAC: the zoo's Pendulum-v1 entry sets only the learning rate (1e-3, as DDPG's); the rest are SB3's SAC
#: defaults (gamma 0.99, buffer 1e6, learning starts 100, net_arch [256, 256], entropy coefficient "auto",
#: no added action noise: SAC explores with its own stochastic policy).
#: DrQ-v2 (Yarats et al. 2021, its DMC "easy" settings): gamma 0.99, 3-step returns, a warm-up of 4000
#: frames (physics steps: :data:`DRQV2_SEED_FRAMES`, so 2000 env steps at the DMC pendulum's action repeat 2), exploration std 1.0 falling linearly to 0.1 over 100000 steps, Adam 1e-4, batch 256, tau 0.01,
#: an update every 2 env steps, MLPs of 1024 x 2, 3 stacked frames; a buffer of 100000 transitions (its
#: 1e6 of 84x84 RGB frames does not fit a laptop; 100000 stacks of three 64x64 frames take 2.5 GB).
#: The fields that only some algorithms read: ``n_step``, ``noise_final_std``, ``noise_decay_steps`` and
#: ``feature_dim`` (DrQ-v2's), ``n_step`` too for DDPG and SAC (1: one-step returns).
_SB3_COMMON = {"learning_rate": 1e-3, "batch_size": 256, "tau": 0.005, "train_freq": 1, "frame_stack": 4, "n_step": 1}
ALGORITHM_PRESETS: dict[Algorithm, dict[str, Any]] = {
    "ddpg": {"gamma": 0.98, "buffer_size": 200_000, "learning_starts": 10_000, "noise_std": 0.1, "net_arch": (400, 300),
             **_SB3_COMMON},
    "sac": {"gamma": 0.99, "buffer_size": 1_000_000, "learning_starts": 100, "noise_std": 0.0, "net_arch": (256, 256),
            **_SB3_COMMON},
    "drqv2": {"gamma": 0.99, "buffer_size": 100_000, "learning_starts": None, "noise_std": 1.0, "net_arch": (1024, 1024),
              "learning_rate": 1e-4, "batch_size": 256, "tau": 0.01, "train_freq": 2, "frame_stack": 3, "n_step": 3},
}
#: Per-observation values, over the algorithm's. Pixels: a replay buffer of 200000 stacks of four 64x64
#: frames takes 6.6 GB (observations and next observations); 50000 take 1.6 GB.
PRESETS: dict[Observation, dict[str, Any]] = {"state": {}, "latent": {}, "pixels": {"buffer_size": 50_000}}


#: Largest learning rate, as piga-train-model's (:data:`piga.training.train.MAX_LR`): no recipe comes within a factor
#: 100 of it, and SB3 turns the rate into a float32 for its logs, which overflows above ~3.4e38.
MAX_LEARNING_RATE = 10.0
#: Largest std of the exploration noise, in SB3's [-1, 1] action scale (as PlaNet's exploration noise is bounded).
MAX_NOISE_STD = 10.0


@dataclass(frozen=True)
class SB3Config:
    """An SB3 run's settings. Unset (None) fields take the observation's preset, then the algorithm's zoo
    value (module docstring); the rest are the zoo's for both (one gradient step per env step, learning
    rate 1e-3) or SB3's defaults (batch 256, tau 0.005). The zoo trains 20000 steps."""

    env: EnvId = PIXEL_PENDULUM
    """The env: Gymnasium's pixel pendulum, or dm_control's pendulum-swingup through its face-on camera
    (:mod:`envs.dmc`, its defaults: action repeat 2, 500 frames an episode, DMC's reward; needs ``piga[dmc]``;
    "pixels" only). The pixel pendulum's rewards, or DMC's, are what the agent learns from."""
    view: View = "face"
    """DMC's pendulum only: "face" (piga's face-on camera, 64x64 gray), "fixed" (dm_control's camera 0, looking down
    at 45°, 64x64 gray) or "drqv2" (DrQ-v2's view: camera 0 in 84x84 RGB; a 100000-step buffer of its stacks takes
    12.7 GB)."""
    obs: Observation = "state"
    """What the policy sees: "pixels" (K stacked frames, CnnPolicy), "latent" (K stacked autoencoder
    codes) or "state" ((cos θ, sin θ, θ̇), the reference point)."""
    algo: Algorithm = "ddpg"
    """The SB3 algorithm: "ddpg" or "sac"."""
    steps: int = 30000
    """Env steps to train (the paper reports its proprioception result after 30k steps)."""
    gamma: float = None  # type: ignore[assignment]  (None: the algorithm's)
    """Discount (zoo: DDPG 0.98, SAC 0.99)."""
    buffer_size: int = None  # type: ignore[assignment]
    """Replay buffer capacity (zoo: DDPG 200000, SAC 1e6; pixels 50000)."""
    learning_starts: int = None  # type: ignore[assignment]
    """Random-action steps before learning (zoo: DDPG 10000, SAC 100)."""
    noise_std: float = None  # type: ignore[assignment]
    """Std of the Gaussian action noise, in SB3's [-1, 1] action scale (zoo: DDPG 0.1, SAC none; DrQ-v2 1.0 at
    the start of its schedule)."""
    noise_final_std: float = 0.1
    """DrQ-v2: the exploration std at the end of its linear schedule (DrQ-v2's 0.1)."""
    noise_decay_steps: int = 100_000
    """DrQ-v2: env steps over which the exploration std falls from ``noise_std`` to ``noise_final_std``."""
    train_freq: int = None  # type: ignore[assignment]
    """Env steps between updates (zoo: 1; DrQ-v2: 2)."""
    gradient_steps: int = 1
    """Gradient steps per update (zoo)."""
    learning_rate: float = None  # type: ignore[assignment]
    """Adam's learning rate for actor and critic (zoo: 1e-3; DrQ-v2: 1e-4, the encoder's too)."""
    batch_size: int = None  # type: ignore[assignment]
    """Minibatch (SB3's default 256; DrQ-v2's 256)."""
    tau: float = None  # type: ignore[assignment]
    """Target networks' soft-update rate (SB3's default 0.005; DrQ-v2: 0.01)."""
    n_step: int = None  # type: ignore[assignment]
    """Returns over n steps (SB3's ``NStepReplayBuffer``): 1 for DDPG and SAC, 3 for DrQ-v2."""
    net_arch: tuple[int, ...] = None  # type: ignore[assignment]
    """Hidden layers of actor and critic (zoo: DDPG (400, 300), SAC (256, 256); DrQ-v2 (1024, 1024))."""
    feature_dim: int = 50
    """DrQ-v2: the width of the actor's and the critic's trunk (LayerNorm, tanh) over the encoder's features."""
    frame_stack: int = None  # type: ignore[assignment]
    """K, frames (or codes) per observation for "pixels" and "latent" (4; DrQ-v2: 3)."""
    torque_arrow: bool = False
    """Whether the frames show Gymnasium's torque arrow (``piga-control``'s default is off)."""
    eval_every: int = 1000
    """Env steps between evaluations and checkpoints (whole episodes: a multiple of 200)."""
    eval_episodes: int = 5
    """Episodes per evaluation (EvalCallback), from the same seeded starts each time."""
    seed: int = 0
    """SB3's ``seed=``, the episode starts and the evaluation starts."""
    encoder_precision: Precision = "auto"
    """DrQ-v2: the encoder's convolutions in "float32" or "bfloat16" (autocast; the rest stays float32), or "auto":
    bfloat16 on a CPU that multiplies it in hardware, float32 elsewhere (:func:`resolve_precision`). Part of the
    recipe: a run keeps the precision it was started with."""
    threads: int = 1
    """torch CPU threads (0: torch's choice)."""
    device: Device = "auto"
    """Where SB3 trains its networks (:mod:`piga.io.device`; passed to SB3's ``device``), and the latent
    autoencoder trains: "auto" (a CUDA GPU when torch sees one, else the CPU), "cpu" or "cuda". Not part of
    the recipe: a run resumes on any device. The trained policy acts on the CPU. On a GPU, an n-step replay
    buffer (DrQ-v2's) keeps its observations in GPU memory where they take at most half of what is free
    (:mod:`agents.sb3.replay`): the same batches, sampled there."""

    def __post_init__(self) -> None:
        if self.obs not in OBSERVATIONS:
            raise ValueError(f"unknown observation {self.obs!r}; expected one of {', '.join(OBSERVATIONS)}")
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {self.algo!r}; expected one of {', '.join(ALGORITHMS)}")
        check_choices(self)
        if self.algo != "drqv2" and self.encoder_precision == "bfloat16":
            raise ValueError(f"encoder_precision bfloat16 is for DrQ-v2; SB3's {self.algo} trains its "
                             "own networks in float32")
        if self.algo == "drqv2" and self.obs != "pixels":
            raise ValueError(f"DrQ-v2 learns from pixels; --obs {self.obs} is for ddpg or sac")
        if self.env == DMC_PENDULUM and self.obs != "pixels":
            raise ValueError(f"--obs {self.obs} is not available for {DMC_PENDULUM}, which is learnt from its frames "
                             f"(--obs pixels) only; --obs {self.obs} is for {PIXEL_PENDULUM}")
        if self.env == DMC_PENDULUM and self.torque_arrow:
            raise ValueError(f"--torque-arrow: the frames of {DMC_PENDULUM} show no torque arrow; drop --torque-arrow")
        if self.view != "face" and self.env != DMC_PENDULUM:
            raise ValueError(f"view {self.view!r} is a view of {DMC_PENDULUM}; {self.env} is seen as it renders")
        # DrQ-v2's buffer is its own (its stacks are of 3 frames, and it keeps a 100k-step run's every transition)
        observation_preset = {} if self.algo == "drqv2" else PRESETS[self.obs]
        for name, value in {**ALGORITHM_PRESETS[self.algo], **observation_preset}.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        if self.learning_starts is None:  # DrQ-v2's warm-up is counted in frames, of which an env step may hold several
            object.__setattr__(self, "learning_starts", DRQV2_SEED_FRAMES // ENV_ACTION_REPEAT[self.env])
        object.__setattr__(self, "net_arch", tuple(self.net_arch))  # a JSON record's list
        if not 1 <= self.steps <= MAX_STEPS:
            raise ValueError(f"steps must be in [1, {MAX_STEPS:,}] (more takes weeks on a CPU), got {self.steps:,}")
        if self.eval_episodes > MAX_EVAL_EPISODES:
            raise ValueError(f"eval_episodes must be at most {MAX_EVAL_EPISODES:,} (episodes per evaluation), got {self.eval_episodes:,}")
        if self.eval_every < self.episode_steps or self.eval_every % self.episode_steps:
            raise ValueError(f"eval_every must be a multiple of the episode length {self.episode_steps} ({self.env}), "
                             f"got {self.eval_every}")
        for name in ("buffer_size", "batch_size", "train_freq", "gradient_steps", "frame_stack", "eval_episodes",
                     "n_step", "feature_dim"):
            if getattr(self, name) < 1:
                raise ValueError(f"SB3Config.{name} must be >= 1, got {getattr(self, name)}")
        if not self.net_arch or not all(isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 65536
                                        for w in self.net_arch):
            raise ValueError(f"SB3Config.net_arch must be hidden layer widths from 1 to 65536, got {self.net_arch}")
        for name in ("learning_starts", "seed", "noise_decay_steps", "threads"):
            if getattr(self, name) < 0:
                raise ValueError(f"SB3Config.{name} must be >= 0, got {getattr(self, name)}")
        if self.seed > MAX_SEED:
            raise ValueError(f"SB3Config.seed must be <= {MAX_SEED} (2^63 - 1), got {self.seed}")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE:  # NaN too
            raise ValueError(f"SB3Config.learning_rate must be in (0, {MAX_LEARNING_RATE:g}], got {number_text(self.learning_rate)}")
        if not (0 < self.gamma <= 1 and 0 < self.tau <= 1 and self.noise_std >= 0 and self.noise_final_std >= 0):
            raise ValueError(f"SB3Config: need 0 < gamma <= 1, 0 < tau <= 1, noise_std >= 0, noise_final_std >= 0; got "
                             f"gamma={self.gamma}, tau={self.tau}, noise_std={self.noise_std}, "
                             f"noise_final_std={self.noise_final_std}")
        for name in ("noise_std", "noise_final_std"):
            if getattr(self, name) > MAX_NOISE_STD:
                raise ValueError(f"SB3Config.{name} must be at most {MAX_NOISE_STD:g} (a std in SB3's [-1, 1] action "
                                 f"scale; far beyond 1 every noisy action is clipped to a bound), got {number_text(getattr(self, name))}")
        if self.algo == "drqv2" and self.noise_std < self.noise_final_std:
            raise ValueError(f"SB3Config.noise_std ({number_text(self.noise_std)}) is below the std that DrQ-v2's exploration "
                             f"schedule falls to ({number_text(self.noise_final_std)}): it would rise instead; give at least "
                             f"{number_text(self.noise_final_std)}")
        if self.eval_every > self.steps and self.steps < self.episode_steps:  # eval_every can go no lower
            raise ValueError(f"SB3Config.steps ({self.steps}) is less than one episode of {self.episode_steps} steps "
                             f"({self.env}), the least between two evaluations: the run would never be evaluated; "
                             f"give SB3Config.steps {self.episode_steps} or more")
        if self.eval_every > self.steps:
            raise ValueError(f"eval_every ({self.eval_every}) is more than SB3Config.steps ({self.steps}): the run would "
                             "never be evaluated; lower eval_every or raise SB3Config.steps")
        if self.steps % self.eval_every:  # the steps after the last evaluation went unscored, its return called final
            raise ValueError(f"SB3Config.steps must be a multiple of eval_every, got {self.steps} and {self.eval_every}: a run "
                             "ends on an evaluation, whose return it reports as its final one")
        if self.learning_starts >= self.steps:
            raise ValueError(f"learning_starts ({self.learning_starts}) is not below SB3Config.steps ({self.steps}): the "
                             "run would only collect random actions and never learn; lower learning_starts or raise "
                             "SB3Config.steps")
        if self.batch_size > self.buffer_size:
            raise ValueError(f"batch_size ({self.batch_size}) is more than buffer_size ({self.buffer_size}): a batch "
                             "cannot be drawn from the replay buffer; lower batch_size or raise buffer_size")

    @property
    def episode_steps(self) -> int:
        """Env steps per episode (:data:`ENV_EPISODE_STEPS`)."""
        return ENV_EPISODE_STEPS[self.env]

    @property
    def learned_return(self) -> float:
        """The evaluation return that counts as learning (:data:`LEARNED_RETURN`)."""
        return LEARNED_RETURN[self.env]

    @property
    def frame_pixels(self) -> int:
        """Bytes of one frame as the policy sees it ("pixels"): channels x height x width."""
        if self.env == DMC_PENDULUM:
            env = DMCPendulumConfig(**DMC_VIEWS[self.view])
            return env.channels * env.image_size**2
        return PixelPendulumConfig().image_size**2

    @property
    def stacked(self) -> int:
        """Frames or codes per observation: ``frame_stack``, or 1 for "state"."""
        return 1 if self.obs == "state" else self.frame_stack

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy, every value set."""
        return asdict(self)


def bfloat16_in_hardware() -> bool:
    """Whether this CPU multiplies bfloat16 in hardware (Intel AMX or AVX-512 BF16), where oneDNN's bfloat16
    convolutions run several times faster than float32 ones; elsewhere torch emulates them, more slowly.

    torch answers only through private helpers (``torch.cpu._is_amx_tile_supported``, 2.13); a torch without them
    is taken to have no such CPU.
    """
    import torch

    return any(bool(getattr(torch.cpu, name, lambda: False)()) for name in ("_is_amx_tile_supported", "_is_avx512_bf16_supported"))


def resolve_precision(config: SB3Config, device: Any) -> Literal["float32", "bfloat16"]:
    """The encoder precision ``config`` stands for on torch ``device``: "auto" is bfloat16 for DrQ-v2 on a CPU with
    bfloat16 hardware (:func:`bfloat16_in_hardware`; its encoder's update about 2.3x faster than float32 on a
    Xeon with AMX, results/ddpg_tuning.md), float32 otherwise (on a GPU torch already runs convolutions in TF32)."""
    if config.encoder_precision != "auto":
        return config.encoder_precision
    cpu = getattr(device, "type", str(device)) == "cpu"
    return "bfloat16" if config.algo == "drqv2" and cpu and bfloat16_in_hardware() else "float32"
