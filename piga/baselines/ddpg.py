"""Stable-baselines3 DDPG on the pixel pendulum, from pixels, from an autoencoder's latent, or from the true state.

Everything is SB3's own: ``DDPG`` with ``CnnPolicy`` (pixels) or ``MlpPolicy``, ``VecFrameStack``
(channel-first uint8 stacks of K frames, or K stacked codes), ``Monitor``, ``EvalCallback`` for the
learning curve, TensorBoard logging and ``seed=``. The hyperparameters are the SB3 zoo's tuned ones
for Pendulum-v1 (rl-baselines3-zoo, ``hyperparams/ddpg.yml``), listed in :class:`DDPGConfig`.

``algo="sac"`` trains SB3's SAC instead, with the zoo's Pendulum-v1 settings (``hyperparams/sac.yml``:
learning rate 1e-3, SB3's SAC defaults for the rest; :data:`ALGORITHM_PRESETS`). It is the stronger
sibling for pixels, where DDPG's deterministic actor saturates (``results/ddpg_tuning.md``); the run
folder, the agent and the evaluation are the same.

Training runs in chunks of ``eval_every`` steps (whole episodes). After each chunk, ``EvalCallback``
has scored the policy, and one atomic ``checkpoint.pt`` holds the SB3 model, its replay buffer, the
global numpy and torch RNG states (SB3 samples batches and noise from them) and the number of
episodes started; every training episode's start depends on (seed, episode index) only
(:class:`envs.observations.EpisodeSeeds`) and every evaluation uses the same seeded starts. So
``resume`` continues exactly as the uninterrupted run would. ``model.zip`` (SB3's format) is the
latest policy, for ``DDPG.load``.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, NoReturn

import gymnasium as gym
import numpy as np
import torch
from tqdm.auto import tqdm

from envs.observations import EpisodeSeeds, FiniteActions, LatentObservation, NonFiniteAction, StateObservation
from envs.pendulum import PixelPendulumConfig
from piga.io.atomic import atomic_output, write_json

__all__ = [
    "ALGORITHMS",
    "ALGORITHM_PRESETS",
    "CHECKPOINT",
    "OBSERVATIONS",
    "PRESETS",
    "DDPGAgent",
    "DDPGConfig",
    "config_for",
    "load_ddpg",
    "make_env",
    "make_observation_env",
    "train_ddpg",
]

#: What DDPG can observe.
OBSERVATIONS = ("pixels", "latent", "state")
#: The SB3 algorithms: DDPG (the paper's), SAC (its stronger sibling).
ALGORITHMS = ("ddpg", "sac")
#: The checkpoint's file name in a run folder; ``model.zip`` is the latest policy in SB3's format.
CHECKPOINT = "checkpoint.pt"
MODEL = "model.zip"
AUTOENCODER = "autoencoder.pt"
#: Pendulum-v1's episode length (its TimeLimit).
EPISODE_STEPS = 200


@dataclass(frozen=True)
class DDPGConfig:
    """DDPG's settings. The defaults are the SB3 zoo's for Pendulum-v1 (``hyperparams/ddpg.yml``):
    gamma 0.98, buffer 200000, learning starts 10000, Gaussian action noise of std 0.1 (in SB3's
    [-1, 1] action scale), one gradient step per env step, learning rate 1e-3, net_arch [400, 300];
    SB3's own defaults for the rest (batch 256, tau 0.005). The zoo trains 20000 steps."""

    obs: str = "state"
    """What the policy sees: "pixels" (K stacked frames, CnnPolicy), "latent" (K stacked autoencoder
    codes) or "state" ((cos θ, sin θ, θ̇), the reference point)."""
    algo: str = "ddpg"
    """The SB3 algorithm: "ddpg", or "sac" (start from :func:`config_for`, which applies its zoo settings)."""
    steps: int = 30000
    """Env steps to train (the paper reports its proprioception result after 30k steps)."""
    gamma: float = 0.98
    """Discount (zoo)."""
    buffer_size: int = 200_000
    """Replay buffer capacity (zoo)."""
    learning_starts: int = 10_000
    """Random-action steps before learning (zoo)."""
    noise_std: float = 0.1
    """Std of the Gaussian action noise, in SB3's [-1, 1] action scale (zoo)."""
    train_freq: int = 1
    """Env steps between updates (zoo)."""
    gradient_steps: int = 1
    """Gradient steps per update (zoo)."""
    learning_rate: float = 1e-3
    """Adam's learning rate for actor and critic (zoo)."""
    batch_size: int = 256
    """Minibatch (SB3's default)."""
    tau: float = 0.005
    """Target networks' soft-update rate (SB3's default)."""
    net_arch: tuple[int, ...] = (400, 300)
    """Hidden layers of actor and critic (zoo)."""
    frame_stack: int = 4
    """K, frames (or codes) per observation for "pixels" and "latent"."""
    torque_arrow: bool = False
    """Whether the frames show Gymnasium's torque arrow (``piga-control``'s default is off)."""
    eval_every: int = 1000
    """Env steps between evaluations and checkpoints (whole episodes: a multiple of 200)."""
    eval_episodes: int = 5
    """Episodes per evaluation (EvalCallback), from the same seeded starts each time."""
    seed: int = 0
    """SB3's ``seed=``, the episode starts and the evaluation starts."""
    threads: int = 1
    """torch CPU threads."""

    def __post_init__(self) -> None:
        if self.obs not in OBSERVATIONS:
            raise ValueError(f"unknown observation {self.obs!r}; expected one of {', '.join(OBSERVATIONS)}")
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {self.algo!r}; expected one of {', '.join(ALGORITHMS)}")
        if self.steps < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")
        if self.eval_every < EPISODE_STEPS or self.eval_every % EPISODE_STEPS:
            raise ValueError(f"eval_every must be a multiple of the episode length {EPISODE_STEPS}, got {self.eval_every}")
        if min(self.buffer_size, self.batch_size, self.train_freq, self.gradient_steps, self.frame_stack,
               self.eval_episodes, self.threads) < 1 or self.learning_starts < 0 or self.seed < 0:
            raise ValueError(f"DDPGConfig: sizes, counts and threads must be >= 1, learning_starts and seed >= 0: {self}")
        if not (0 < self.gamma <= 1 and self.learning_rate > 0 and 0 < self.tau <= 1 and self.noise_std >= 0):
            raise ValueError(f"DDPGConfig: need 0 < gamma <= 1, learning_rate > 0, 0 < tau <= 1, noise_std >= 0: {self}")

    @property
    def stacked(self) -> int:
        """Frames or codes per observation: ``frame_stack``, or 1 for "state"."""
        return 1 if self.obs == "state" else self.frame_stack

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy."""
        return asdict(self)


#: Per-observation overrides of :class:`DDPGConfig`. Pixels: a replay buffer of 200000 stacks of
#: four 64x64 frames takes 6.6 GB (observations and next observations); 50000 take 1.6 GB.
PRESETS: dict[str, dict[str, Any]] = {"state": {}, "latent": {}, "pixels": {"buffer_size": 50_000}}
#: Per-algorithm overrides of :class:`DDPGConfig`, applied before :data:`PRESETS`. SAC: the zoo's
#: Pendulum-v1 entry sets only the learning rate (1e-3, as DDPG's); the rest are SB3's SAC defaults
#: (gamma 0.99, buffer 1e6, learning starts 100, net_arch [256, 256], entropy coefficient "auto", no
#: added action noise: SAC explores with its own stochastic policy).
ALGORITHM_PRESETS: dict[str, dict[str, Any]] = {
    "ddpg": {},
    "sac": {"gamma": 0.99, "buffer_size": 1_000_000, "learning_starts": 100, "noise_std": 0.0, "net_arch": (256, 256)},
}


def _algorithm(name: str) -> Any:
    """The SB3 class of ``name`` (one of :data:`ALGORITHMS`)."""
    from stable_baselines3 import DDPG, SAC

    return {"ddpg": DDPG, "sac": SAC}[name]


def make_observation_env(config: DDPGConfig, encoder: Callable[[np.ndarray], np.ndarray] | None = None,
                         latent_size: int = 0, gravity_mult: float = 1.0) -> gym.Env:
    """The registered pixel pendulum (one frame per observation) with the observation wrapper of ``config.obs``.

    For "state", Gymnasium's Pendulum-v1 itself (the same dynamics and starts, gravity times
    ``gravity_mult``) without rendering: rendering a frame costs more than the rest of a step, and
    the state policy never looks at it.
    """
    import envs  # noqa: F401  (registers piga/PixelPendulum-v0)

    if config.obs == "state":
        g = PixelPendulumConfig(gravity_mult=gravity_mult).effective_gravity
        return StateObservation(gym.make("Pendulum-v1", g=g, max_episode_steps=EPISODE_STEPS))
    env = gym.make("piga/PixelPendulum-v0", frame_stack=1, draw_torque_arrow=config.torque_arrow,
                   episode_length=EPISODE_STEPS, gravity_mult=gravity_mult)
    if config.obs == "latent":
        if encoder is None:
            raise ValueError("obs='latent' needs an encoder")
        return LatentObservation(env, encoder, latent_size)
    return env


def make_env(config: DDPGConfig, encoder: Callable[[np.ndarray], np.ndarray] | None = None, latent_size: int = 0,
             episode_seed: int | None = None, gravity_mult: float = 1.0) -> gym.Env:
    """One env as DDPG sees it, before stacking: :func:`make_observation_env`, then
    :class:`~envs.observations.FiniteActions` (a diverged policy's NaN action stops the run), then
    (with ``episode_seed``) :class:`EpisodeSeeds`, then SB3's ``Monitor``."""
    from stable_baselines3.common.monitor import Monitor

    env = FiniteActions(make_observation_env(config, encoder, latent_size, gravity_mult))
    if episode_seed is not None:
        env = EpisodeSeeds(env, episode_seed)
    return Monitor(env)


def _vec_env(config: DDPGConfig, encoder: Callable[[np.ndarray], np.ndarray] | None, latent_size: int,
             episode_seed: int | None) -> Any:
    from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

    venv = DummyVecEnv([lambda: make_env(config, encoder, latent_size, episode_seed)])
    if config.obs == "state":
        return venv
    return VecFrameStack(venv, config.frame_stack, channels_order="first" if config.obs == "pixels" else "last")


def _episode_seeds(venv: Any) -> EpisodeSeeds:
    env = venv.venv.envs[0] if hasattr(venv, "venv") else venv.envs[0]
    while not isinstance(env, EpisodeSeeds):
        env = env.env
    return env


def _eval_callback(config: DDPGConfig, eval_env: Any) -> Any:
    from stable_baselines3.common.callbacks import EvalCallback

    class SeededEvalCallback(EvalCallback):
        """EvalCallback whose every evaluation starts from the same seeded episodes."""

        def _on_step(self) -> bool:
            if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0:
                self.eval_env.seed(config.seed + 10_000)
            return super()._on_step()

    return SeededEvalCallback(eval_env, n_eval_episodes=config.eval_episodes, eval_freq=config.eval_every,
                              deterministic=True, verbose=0)


def _save(run_dir: Path, model: Any, config: DDPGConfig, episodes: int, history: list[dict[str, float]], elapsed: float) -> None:
    policy, buffer = io.BytesIO(), io.BytesIO()
    model.save(policy)
    model.save_replay_buffer(buffer)
    payload = {
        "kind": "ddpg",
        "config": config.to_dict(),
        "model_zip": policy.getvalue(),
        "replay_buffer": buffer.getvalue(),
        "rng": {"numpy": np.random.get_state(), "torch": torch.get_rng_state(),
                "action_space": model.action_space.np_random.bit_generator.state},
        "episodes": episodes,
        "history": history,
        "elapsed": elapsed,
    }
    with atomic_output(run_dir / CHECKPOINT, overwrite=True) as tmp:
        torch.save(payload, tmp)
    with atomic_output(run_dir / MODEL, overwrite=True) as tmp:
        tmp.write_bytes(policy.getvalue())


def _check_finite(model: Any, callback: Any, evaluated: bool, checkpoint: Path) -> None:
    """Stops a run whose weights or evaluation return became NaN or infinite, before it is checkpointed.

    Raises:
        piga.training.train.TrainingDiverged: naming the step, the cause and the last good checkpoint.
    """
    bad = [name for name, p in model.policy.named_parameters() if not torch.isfinite(p).all()]
    ret = float(callback.last_mean_reward) if evaluated else 0.0
    if not bad and np.isfinite(ret):
        return
    _diverged(f"the weights of {bad[0]} became non-finite" if bad else f"the evaluation's mean return became {ret}",
              model.num_timesteps, checkpoint)


def _diverged(cause: str, step: int, checkpoint: Path) -> NoReturn:
    """Raises :class:`piga.training.train.TrainingDiverged` naming ``cause``, the step and the last good checkpoint."""
    from piga.training.train import TrainingDiverged

    good = checkpoint if checkpoint.exists() else None
    raise TrainingDiverged(f"{cause} by step {step} (lower the learning rate); "
                           + (f"last good checkpoint: {good}" if good else "no checkpoint was written yet"))


def first_step_reaching(history: list[dict[str, float]], threshold: float = -200.0) -> int | None:
    """The first evaluated step at which the mean return is at least ``threshold`` (None if never)."""
    return next((int(r["step"]) for r in history if r["eval_mean_return"] >= threshold), None)


def train_ddpg(config: DDPGConfig, run_dir: str | Path, autoencoder: str | Path | None = None, resume: bool = False,
               progress: bool = True, on_checkpoint: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Trains DDPG for ``config.steps`` env steps; writes ``checkpoint.pt``, ``model.zip``, TensorBoard
    (``tensorboard/``) and ``metrics.json`` (the EvalCallback learning curve) to ``run_dir``.

    Args:
        config: the settings (with ``resume``: the run's own, possibly with more ``steps``).
        run_dir: the run folder.
        autoencoder: for ``obs="latent"``, the trained autoencoder (:mod:`piga.baselines.autoencoder`).
        resume: continue the run in ``run_dir`` exactly.
        on_checkpoint: called with the step count after each checkpoint.

    Returns:
        The metrics written to ``metrics.json``.
    """
    from stable_baselines3.common.noise import NormalActionNoise

    algorithm = _algorithm(config.algo)
    run_dir = Path(run_dir)
    torch.set_num_threads(config.threads)
    encoder, latent_size = None, 0
    if config.obs == "latent":
        from piga.baselines.autoencoder import load_autoencoder

        if autoencoder is None:
            raise ValueError("obs='latent' needs a trained autoencoder")
        ae = load_autoencoder(autoencoder)
        encoder, latent_size = ae.encode_frame, ae.config.latent_size
    venv = _vec_env(config, encoder, latent_size, episode_seed=config.seed)
    eval_env = _vec_env(config, encoder, latent_size, episode_seed=None)
    history: list[dict[str, float]] = []
    elapsed = 0.0
    if resume:
        path = run_dir / CHECKPOINT
        try:
            ckpt = torch.load(path, map_location="cpu", weights_only=False)
            # the zip holds the TensorBoard folder of the run's first invocation: log where the run is now
            model = algorithm.load(io.BytesIO(ckpt["model_zip"]), env=venv, device="cpu", tensorboard_log=str(run_dir / "tensorboard"))
            model.load_replay_buffer(io.BytesIO(ckpt["replay_buffer"]))
        except Exception as exc:  # a truncated or foreign file
            raise _unreadable(path, exc) from None
        # load() reseeded everything with the run's seed (SB3's _setup_model): put back the states
        # of the moment of the checkpoint
        np.random.set_state(ckpt["rng"]["numpy"])
        torch.set_rng_state(ckpt["rng"]["torch"])
        model.action_space.np_random.bit_generator.state = ckpt["rng"]["action_space"]
        # the last chunk ended an episode, and its automatic reset drew episode k's start; draw it
        # again (SB3's env.seed() in load left a seed for the next reset: make it episode k's)
        k = int(ckpt["episodes"]) - 1
        _episode_seeds(venv).episodes = k
        venv.seed(_episode_seeds(venv).seed_of(k))
        history, elapsed = list(ckpt["history"]), float(ckpt["elapsed"])
    else:
        n_actions = venv.action_space.shape[0]
        noise = NormalActionNoise(np.zeros(n_actions), config.noise_std * np.ones(n_actions)) if config.noise_std else None
        model = algorithm("CnnPolicy" if config.obs == "pixels" else "MlpPolicy", venv, learning_rate=config.learning_rate,
                          buffer_size=config.buffer_size, learning_starts=config.learning_starts, batch_size=config.batch_size,
                          tau=config.tau, gamma=config.gamma, train_freq=config.train_freq, gradient_steps=config.gradient_steps,
                          action_noise=noise, policy_kwargs={"net_arch": list(config.net_arch)},
                          tensorboard_log=str(run_dir / "tensorboard"), seed=config.seed, device="cpu", verbose=0)
    callback = _eval_callback(config, eval_env)
    started = time.monotonic() - elapsed
    bar = tqdm(total=config.steps, initial=model.num_timesteps, desc=f"{config.algo} ({config.obs})", unit="step", disable=not progress)
    try:
        while model.num_timesteps < config.steps:
            chunk = min(config.eval_every, config.steps - model.num_timesteps)
            before = model.num_timesteps
            try:
                model.learn(chunk, callback=callback, reset_num_timesteps=False, tb_log_name=config.algo)
            except NonFiniteAction as exc:
                _diverged(str(exc), model.num_timesteps, run_dir / CHECKPOINT)
            bar.update(model.num_timesteps - before)
            _check_finite(model, callback, chunk == config.eval_every, run_dir / CHECKPOINT)
            elapsed = time.monotonic() - started
            if chunk == config.eval_every:  # the callback evaluated at the chunk's last step
                history.append({"step": model.num_timesteps, "eval_mean_return": float(callback.last_mean_reward),
                                "seconds": elapsed})
                bar.set_postfix(eval_return=f"{callback.last_mean_reward:.1f}")
            run_dir.mkdir(parents=True, exist_ok=True)
            _save(run_dir, model, config, _episode_seeds(venv).episodes, history, elapsed)
            if on_checkpoint is not None:
                on_checkpoint(model.num_timesteps)
    finally:
        bar.close()
        venv.close()
        eval_env.close()
    metrics = {
        "kind": "ddpg",
        "algo": config.algo,
        "obs": config.obs,
        "steps": int(model.num_timesteps),
        "train_seconds": elapsed,
        "learning_curve": history,
        "first_step_reaching_minus_200": first_step_reaching(history),
        "final_eval_mean_return": history[-1]["eval_mean_return"] if history else None,
    }
    if autoencoder is not None:  # its training came before DDPG's and is not in train_seconds
        from piga.baselines.autoencoder import autoencoder_seconds

        metrics["autoencoder_train_seconds"] = autoencoder_seconds(autoencoder)
    write_json(run_dir / "metrics.json", metrics)
    return metrics


def _unreadable(path: Path, exc: Exception) -> ValueError:
    """The one-line error for a checkpoint that cannot be read: the file, and the first sentence of the cause."""
    cause = " ".join(str(exc).split()).split(". ")[0][:160]
    return ValueError(f"{path}: not a readable DDPG checkpoint ({exc.__class__.__name__}: {cause}); it may be truncated "
                      "(a full disk, an interrupted copy): restore it, or train the run again with --overwrite")


def load_ddpg(run_dir: str | Path) -> tuple[Any, DDPGConfig, Any]:
    """The policy (SB3 ``DDPG`` or ``SAC``), its config and, for "latent", its autoencoder (else None)."""
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT
    if not path.exists():
        raise FileNotFoundError(f"{path}: no checkpoint (is {run_dir} a piga-baseline ddpg run folder?)")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
        config = DDPGConfig(**{**ckpt["config"], "net_arch": tuple(ckpt["config"]["net_arch"])})
        model = _algorithm(config.algo).load(io.BytesIO(ckpt["model_zip"]), device="cpu")
    except Exception as exc:  # a truncated or foreign file
        raise _unreadable(path, exc) from None
    encoder = None
    if config.obs == "latent":
        from piga.baselines.autoencoder import load_autoencoder

        encoder = load_autoencoder(run_dir / AUTOENCODER)
    return model, config, encoder


@dataclass
class DDPGAgent:
    """A trained DDPG policy as an episode agent (:mod:`piga.control.episodes`).

    It keeps its own stack of the last K frames or codes, zeros at reset, exactly as SB3's
    ``VecFrameStack`` did in training, so it needs only the newest frame (``input_frames`` = 1).
    "state" reads (cos θ, sin θ, θ̇) from the true state that episodes pass to every agent.
    """

    model: Any
    """SB3 ``DDPG`` or ``SAC``."""
    config: DDPGConfig
    """The run's settings."""
    encoder: Any = None
    """For "latent": the :class:`~piga.baselines.autoencoder.FrameAutoencoder`."""
    input_frames: int = 1
    """Frames the agent needs per decision."""
    _stack: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def from_run(cls, run_dir: str | Path) -> DDPGAgent:
        """The agent of a ``piga-baseline ddpg`` run folder."""
        model, config, encoder = load_ddpg(run_dir)
        return cls(model, config, encoder)

    def reset(self) -> None:
        """Starts an episode: an empty (zero) stack."""
        self._stack = np.zeros(self.model.observation_space.shape, self.model.observation_space.dtype)

    def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
        """Action (1,) from the newest frame (uint8 (L, H, W)), or from ``state`` for obs="state"."""
        if self.config.obs == "state":
            obs = np.array([np.cos(state[0]), np.sin(state[0]), state[1]], np.float32)
        else:
            if self._stack is None:
                self.reset()
            assert self._stack is not None
            new = frames[-1:] if self.config.obs == "pixels" else self.encoder.encode_frame(frames[-1])
            size = len(new)
            self._stack = np.concatenate([self._stack[size:], np.asarray(new, self._stack.dtype)])
            obs = self._stack
        action, _ = self.model.predict(obs, deterministic=True)
        return np.asarray(action, np.float32).reshape(1)


def config_for(obs: str, algo: str = "ddpg", **overrides: Any) -> DDPGConfig:
    """The config of an observation kind and algorithm: DDPG's zoo defaults, the algorithm's preset
    (:data:`ALGORITHM_PRESETS`), the observation's (:data:`PRESETS`), then ``overrides``."""
    return replace(DDPGConfig(obs=obs, algo=algo), **{**ALGORITHM_PRESETS[algo], **PRESETS[obs], **overrides})
