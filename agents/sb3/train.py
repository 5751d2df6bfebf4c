"""Training stable-baselines3 DDPG (or SAC, or DrQ-v2 in SB3's loop) on the pixel pendulum, from pixels, from an autoencoder's latent, or from the true state (or, from pixels, on dm_control's pendulum: ``SB3Config.env``).

Everything is SB3's own: ``DDPG`` with ``CnnPolicy`` (pixels) or ``MlpPolicy``, ``VecFrameStack``
(channel-first uint8 stacks of K frames, or K stacked codes), ``Monitor``, ``EvalCallback`` for the
learning curve, TensorBoard logging and ``seed=``. The hyperparameters are the SB3 zoo's tuned ones
for Pendulum-v1 (:class:`agents.sb3.config.SB3Config`).

``algo="sac"`` trains SB3's SAC instead, with the zoo's Pendulum-v1 settings. It is the stronger
sibling for pixels, where DDPG's deterministic actor saturates (``results/ddpg_tuning.md``); the run
folder, the agent (:class:`agents.sb3.run.SB3Agent`) and the evaluation are the same.
``algo="drqv2"`` trains DrQ-v2 (:mod:`agents.sb3.drqv2`), the pixel actor-critic whose encoder the
critic trains, with augmentation, 3-step returns and scheduled exploration, in the same loop.

Training runs in chunks of ``eval_every`` steps (whole episodes). After each chunk, ``EvalCallback``
has scored the policy, and one atomic ``checkpoint.pt`` holds the SB3 model, the name of its replay
buffer's file (``replay_buffers/STEP.pkl``, written before it), the global numpy and torch RNG states
(SB3 samples batches and noise from them; the GPU's too when it trains on one) and the number of
episodes started; every training episode's start depends on
(seed, episode index) only (:class:`envs.observations.EpisodeSeeds`) and every evaluation uses the
same seeded starts. So ``resume`` continues exactly as the uninterrupted run would (on the same
device). ``model.zip`` (SB3's format) is the latest policy, for ``DDPG.load``.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import gymnasium as gym
import numpy as np
import torch
from tqdm.auto import tqdm

from agents.sb3.config import DMC_VIEWS, EPISODE_STEPS, SB3Config, resolve_precision
from agents.sb3.run import MODEL, REPLAY_BUFFERS, sb3_class
from envs.observations import EpisodeSeeds, FiniteActions, LatentObservation, NonFiniteAction, StateObservation
from envs.pendulum import PixelPendulumConfig
from piga.data.schema import legacy_seed
from piga.io.atomic import OutputFolder, atomic_output, write_json
from piga.io.checkpoint import (CHECKPOINT, RunKind, check_counts, check_record_matches, read_checkpoint,
                                resuming_from, unreadable, write_checkpoint)
from piga.io.device import resolve_device, set_threads
from piga.io.progress import close_bar

__all__ = ["first_step_reaching", "make_env", "make_observation_env", "train_sb3"]


def make_observation_env(config: SB3Config, encoder: Callable[[np.ndarray], np.ndarray] | None = None,
                         latent_size: int = 0, gravity_mult: float = 1.0) -> gym.Env:
    """The registered pixel pendulum (one frame per observation) with the observation wrapper of ``config.obs``,
    or, for ``config.env`` DMC's, the registered DMC pendulum at its defaults but for ``config.view`` (one frame per
    observation).

    For "state", Gymnasium's Pendulum-v1 itself (the same dynamics and starts, gravity times
    ``gravity_mult``) without rendering: rendering a frame costs more than the rest of a step, and
    the state policy never looks at it.
    """
    from envs import DMC_PENDULUM  # importing envs registers the env ids

    if config.env == DMC_PENDULUM:  # pixels only (SB3Config); its own reward and episode, at dm_control's defaults
        if gravity_mult != 1.0:
            raise ValueError(f"{DMC_PENDULUM} has no gravity multiplier (got {gravity_mult:g})")
        return gym.make(DMC_PENDULUM, frame_stack=1, **DMC_VIEWS[config.view])
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


def make_env(config: SB3Config, encoder: Callable[[np.ndarray], np.ndarray] | None = None, latent_size: int = 0,
             episode_seed: int | None = None, gravity_mult: float = 1.0) -> gym.Env:
    """One env as DDPG sees it, before stacking: :func:`make_observation_env`, then
    :class:`~envs.observations.FiniteActions` (a diverged policy's NaN action stops the run), then
    (with ``episode_seed``) :class:`EpisodeSeeds`, then SB3's ``Monitor``."""
    from stable_baselines3.common.monitor import Monitor

    env = FiniteActions(make_observation_env(config, encoder, latent_size, gravity_mult))
    if episode_seed is not None:
        env = EpisodeSeeds(env, episode_seed)
    return Monitor(env)


def _vec_env(config: SB3Config, encoder: Callable[[np.ndarray], np.ndarray] | None, latent_size: int,
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


def _eval_callback(config: SB3Config, eval_env: Any) -> Any:
    from stable_baselines3.common.callbacks import EvalCallback

    class SeededEvalCallback(EvalCallback):
        """EvalCallback whose every evaluation starts from the same seeded episodes."""

        def _on_step(self) -> bool:
            if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0:
                self.eval_env.seed(config.seed + 10_000)
            return super()._on_step()

    return SeededEvalCallback(eval_env, n_eval_episodes=config.eval_episodes, eval_freq=config.eval_every,
                              deterministic=True, verbose=0)


def _bar_callback(bar: Any) -> Any:
    """A callback that moves the run's progress bar at each env step: a chunk between checkpoints can last an hour
    on a CPU (SB3's own ProgressBarCallback would draw a new bar for each chunk)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class BarCallback(BaseCallback):
        def _on_step(self) -> bool:
            bar.update(self.training_env.num_envs)
            return True

    return BarCallback()


def _n_step_buffer(config: SB3Config, venv: Any, device: torch.device) -> dict[str, Any]:
    """SB3's arguments for ``config.n_step``-step returns: its ``NStepReplayBuffer`` named explicitly (the saved
    model then loads without SB3's warning that its ``n_steps`` shortcut is ignored), or nothing for 1. On a GPU
    with room for the observations, :class:`agents.sb3.replay.DeviceNStepReplayBuffer` (the same batches, sampled
    there)."""
    if config.n_step == 1:
        return {}
    from stable_baselines3.common.buffers import NStepReplayBuffer

    from agents.sb3.replay import DeviceNStepReplayBuffer, fits_on_device

    space = venv.observation_space
    on_device = fits_on_device(device, config.buffer_size, space.shape, space.dtype)
    return {"replay_buffer_class": DeviceNStepReplayBuffer if on_device else NStepReplayBuffer,
            "replay_buffer_kwargs": {"n_steps": config.n_step, "gamma": config.gamma}}


def new_model(config: SB3Config, venv: Any, device: torch.device, tensorboard_log: str | None = None) -> Any:
    """A new SB3 model of ``config.algo`` on ``venv`` (:func:`train_sb3`'s, before any step), its networks on
    ``device``, seeded with ``config.seed``."""
    from stable_baselines3.common.noise import NormalActionNoise

    n_actions = venv.action_space.shape[0]
    policy_kwargs: dict[str, Any] = {"net_arch": list(config.net_arch)}
    if config.algo == "drqv2":
        from agents.sb3.drqv2 import ScheduledNoise

        noise: Any = ScheduledNoise(n_actions, config.noise_std, config.noise_final_std, config.noise_decay_steps)
        policy_kwargs.update(feature_dim=config.feature_dim, encoder_precision=resolve_precision(config, device))
    else:
        noise = NormalActionNoise(np.zeros(n_actions), config.noise_std * np.ones(n_actions)) if config.noise_std else None
    return sb3_class(config.algo)("CnnPolicy" if config.obs == "pixels" else "MlpPolicy", venv, learning_rate=config.learning_rate,
                                  buffer_size=config.buffer_size, learning_starts=config.learning_starts, batch_size=config.batch_size,
                                  tau=config.tau, gamma=config.gamma, train_freq=config.train_freq,
                                  gradient_steps=config.gradient_steps, action_noise=noise, policy_kwargs=policy_kwargs,
                                  **_n_step_buffer(config, venv, device), tensorboard_log=tensorboard_log, seed=legacy_seed(config.seed), device=device,
                                  verbose=0)


def _save(run_dir: Path, model: Any, config: SB3Config, episodes: int, history: list[dict[str, float]], elapsed: float) -> None:
    """The checkpoint: the replay buffer first, into a file of its own named by the step, which SB3's pickle streams to
    disk (through bytes inside the checkpoint, a buffer of 2.5 GB took 17 GB of memory to save: the pickle, its copy,
    torch's pickle of it and that one's copy); then ``checkpoint.pt``, atomically, naming it; then the buffers of
    earlier checkpoints go. Killed at any point, the folder holds a checkpoint and the buffer it names."""
    step = int(model.num_timesteps)
    buffer = Path(REPLAY_BUFFERS) / f"{step}.pkl"
    (run_dir / REPLAY_BUFFERS).mkdir(exist_ok=True)
    with atomic_output(run_dir / buffer, overwrite=True) as tmp, open(tmp, "wb") as file:
        model.save_replay_buffer(file)
    policy = io.BytesIO()
    model.save(policy)
    payload = {
        "kind": RunKind.DDPG.value,
        "config": config.to_dict(),
        "model_zip": policy.getvalue(),
        "replay_buffer_file": buffer.as_posix(),
        "rng": {"numpy": np.random.get_state(), "torch": torch.get_rng_state(),
                "action_space": model.action_space.np_random.bit_generator.state,
                **({"cuda": torch.cuda.get_rng_state(model.device)} if model.device.type == "cuda" else {})},
        "episodes": episodes,
        "history": history,
        "elapsed": elapsed,
    }
    try:
        write_checkpoint(run_dir, payload)
    except BaseException:  # (a full disk) the checkpoint still names the earlier buffer: this one would be left astray
        (run_dir / buffer).unlink(missing_ok=True)
        raise
    for earlier in (run_dir / REPLAY_BUFFERS).glob("*.pkl"):
        if earlier.name != buffer.name:
            earlier.unlink(missing_ok=True)
    with atomic_output(run_dir / MODEL, overwrite=True) as tmp:
        tmp.write_bytes(policy.getvalue())


def _load_replay_buffer(model: Any, run_dir: Path, ckpt: dict[str, Any]) -> None:
    """Fills ``model``'s replay buffer from the file the checkpoint names (or, in a checkpoint written before buffers
    had files of their own, from its bytes)."""
    if "replay_buffer" in ckpt:
        model.load_replay_buffer(io.BytesIO(ckpt["replay_buffer"]))
        return
    if "replay_buffer_file" not in ckpt:
        raise unreadable(run_dir / CHECKPOINT, RunKind.DDPG, KeyError("replay_buffer_file"))
    name = ckpt["replay_buffer_file"]
    if not isinstance(name, str) or Path(name).is_absolute() or ".." in Path(name).parts:
        raise unreadable(run_dir / CHECKPOINT, RunKind.DDPG, f"its replay buffer is {name!r}, not a file in the run "
                                                             "folder")
    path = run_dir / name
    if not path.is_file():
        state = "is not a file" if path.exists() else "is missing"  # (a folder in its place was called missing)
        raise ValueError(f"{path}, the replay buffer that {run_dir / CHECKPOINT} names, {state}: put it back, or "
                         "train the run again with --overwrite")
    try:
        model.load_replay_buffer(path)
    except Exception as exc:  # a truncated or foreign file
        raise unreadable(path, RunKind.DDPG, exc, what=f"replay buffer of a {RunKind.DDPG.label} run") from None
    shape = tuple(getattr(model.replay_buffer, "obs_shape", model.observation_space.shape))
    if shape != tuple(model.observation_space.shape):  # another run's: the first step would fail to store into it
        raise ValueError(f"{path} is the replay buffer of another run (observations {shape}, this run's "
                         f"{tuple(model.observation_space.shape)}): put back the run's own, or train it again with "
                         "--overwrite")


def _check_finite(model: Any, callback: Any, evaluated: bool, checkpoint: Path) -> None:
    """Stops a run whose weights or evaluation return became NaN or infinite, before it is checkpointed.

    Raises:
        piga.training.train.TrainingDiverged: naming the step, the cause and the last good checkpoint.
    """
    bad = _non_finite(model)
    ret = float(callback.last_mean_reward) if evaluated else 0.0
    if bad is None and np.isfinite(ret):
        return
    _diverged(f"the weights of {bad} became non-finite" if bad else f"the evaluation's mean return became {ret}",
              model.num_timesteps, checkpoint)


def _non_finite(model: Any) -> str | None:
    """The name of the first of ``model``'s learned tensors (its policy's weights, SAC's entropy coefficient) that holds
    a NaN or an infinity, or None."""
    tensors = [*model.policy.named_parameters()]
    if isinstance(getattr(model, "log_ent_coef", None), torch.Tensor):  # SAC's learned temperature, outside the policy
        tensors.append(("log_ent_coef", model.log_ent_coef))
    return next((name for name, p in tensors if not torch.isfinite(p).all()), None)


def _diverged(cause: str, step: int, checkpoint: Path) -> NoReturn:
    """Raises :class:`piga.training.train.TrainingDiverged` naming ``cause``, the step and the last good checkpoint."""
    from piga.training.train import TrainingDiverged

    good = checkpoint if checkpoint.exists() else None
    raise TrainingDiverged(f"{cause} by step {step} (lower the learning rate); "
                           + (f"last good checkpoint: {good}" if good else "no checkpoint was written yet"))


def first_step_reaching(history: list[dict[str, float]], threshold: float = -200.0) -> int | None:
    """The first evaluated step at which the mean return is at least ``threshold`` (None if never)."""
    return next((int(r["step"]) for r in history if r["eval_mean_return"] >= threshold), None)


def _reaching_key(threshold: float) -> str:
    """metrics.json's key for the first step at ``threshold``: "first_step_reaching_minus_200" on the pixel pendulum,
    "first_step_reaching_200" on DMC's scale."""
    return f"first_step_reaching_{'minus_' if threshold < 0 else ''}{abs(threshold):g}"


def train_sb3(config: SB3Config, run_dir: str | Path, autoencoder: str | Path | None = None, resume: bool = False,
               progress: bool = True, on_checkpoint: Callable[[int], None] | None = None,
               check_disk: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Trains ``config.algo`` for ``config.steps`` env steps; writes ``checkpoint.pt``, ``model.zip``, TensorBoard
    (``tensorboard/``) and ``metrics.json`` (the EvalCallback learning curve) to ``run_dir``.

    Args:
        config: the settings (with ``resume``: the run's own, possibly with more ``steps``, on any ``device``;
            SB3 trains on ``config.device``, :func:`piga.io.device.resolve_device`).
        run_dir: the run folder.
        autoencoder: for ``obs="latent"``, the trained autoencoder (:mod:`agents.sb3.autoencoder`).
        resume: continue the run in ``run_dir`` exactly.
        on_checkpoint: called with the step count after each checkpoint.
        check_disk: called, before the first step, with the bytes of the model's saved networks (its policy zip, held
            by the checkpoint and by model.zip), which only the built model tells: the caller checks its disk again.

    Returns:
        The metrics written to ``metrics.json``.

    Raises:
        ValueError: ``config.device`` is "cuda" and torch sees no CUDA device.
    """
    algorithm = sb3_class(config.algo)
    device = resolve_device(config.device)
    run_dir = Path(run_dir)
    folder = OutputFolder(run_dir)  # moved or removed while the run trains: said, not made again
    set_threads(config.threads, "SB3Config")
    encoder, latent_size = None, 0
    if config.obs == "latent":
        from agents.sb3.autoencoder import load_autoencoder

        if autoencoder is None:
            raise ValueError("obs='latent' needs a trained autoencoder")
        ae = load_autoencoder(autoencoder)
        encoder, latent_size = ae.encode_frame, ae.config.latent_size
    venv = _vec_env(config, encoder, latent_size, episode_seed=config.seed)
    eval_env = _vec_env(config, encoder, latent_size, episode_seed=None)
    history: list[dict[str, float]] = []
    elapsed = 0.0
    if resume:
        ckpt = read_checkpoint(run_dir, RunKind.DDPG)
        check_record_matches(run_dir, [(config.to_dict(), ckpt.get("config"))])
        try:
            # the zip holds the TensorBoard folder of the run's first invocation: log where the run is now
            model = algorithm.load(io.BytesIO(ckpt["model_zip"]), env=venv, device=device,
                                   tensorboard_log=str(run_dir / "tensorboard"), **_n_step_buffer(config, venv, device))
        except Exception as exc:  # a truncated or foreign file
            raise unreadable(run_dir / CHECKPOINT, RunKind.DDPG, exc) from None
        _load_replay_buffer(model, run_dir, ckpt)
        # load() reseeded everything with the run's seed (SB3's _setup_model): put back the states
        # of the moment of the checkpoint
        with resuming_from(run_dir / CHECKPOINT, RunKind.DDPG):
            np.random.set_state(ckpt["rng"]["numpy"])
            torch.set_rng_state(ckpt["rng"]["torch"])
            if device.type == "cuda" and "cuda" in ckpt["rng"]:  # saved on a GPU, resumed on one
                torch.cuda.set_rng_state(ckpt["rng"]["cuda"], device)
            model.action_space.np_random.bit_generator.state = ckpt["rng"]["action_space"]
            episodes = ckpt["episodes"]
            history, elapsed = list(ckpt["history"]), float(ckpt["elapsed"])
        check_counts(run_dir / CHECKPOINT, RunKind.DDPG, episodes=episodes)
        # the last chunk ended an episode, and its automatic reset drew episode k's start; draw it
        # again (SB3's env.seed() in load left a seed for the next reset: make it episode k's)
        k = episodes - 1
        _episode_seeds(venv).episodes = k
        venv.seed(_episode_seeds(venv).seed_of(k))
    else:
        model = new_model(config, venv, device, tensorboard_log=str(run_dir / "tensorboard"))
    if check_disk is not None:
        policy = io.BytesIO()
        model.save(policy)
        check_disk(len(policy.getvalue()))
    callback = _eval_callback(config, eval_env)
    started = time.monotonic() - elapsed
    bar = tqdm(total=config.steps, initial=model.num_timesteps, desc=f"{config.algo} ({config.obs})", unit="step", disable=not progress)
    try:
        while model.num_timesteps < config.steps:
            chunk = min(config.eval_every, config.steps - model.num_timesteps)
            try:
                model.learn(chunk, callback=[callback, _bar_callback(bar)], reset_num_timesteps=False,
                            tb_log_name=config.algo)
            except NonFiniteAction as exc:
                _diverged(str(exc), model.num_timesteps, run_dir / CHECKPOINT)
            except ValueError as exc:  # torch.distributions refuses a NaN mean or scale (SAC's policy) as it samples
                if (bad := _non_finite(model)) is None and "found invalid values" not in str(exc):
                    raise
                _diverged(f"the weights of {bad} became non-finite" if bad else "the policy's action distribution "
                          "became NaN", model.num_timesteps, run_dir / CHECKPOINT)
            bar.update(model.num_timesteps - bar.n)  # none, unless a step went uncounted
            _check_finite(model, callback, chunk == config.eval_every, run_dir / CHECKPOINT)
            elapsed = time.monotonic() - started
            if chunk == config.eval_every:  # the callback evaluated at the chunk's last step
                history.append({"step": model.num_timesteps, "eval_mean_return": float(callback.last_mean_reward),
                                "seconds": elapsed})
                bar.set_postfix(eval_return=f"{callback.last_mean_reward:.1f}")
            folder.make()
            _save(run_dir, model, config, _episode_seeds(venv).episodes, history, elapsed)
            if on_checkpoint is not None:
                on_checkpoint(model.num_timesteps)
    finally:
        close_bar(bar)  # cleared on an error: its line is the last
        venv.close()
        eval_env.close()
    metrics = {
        "kind": "ddpg",
        "algo": config.algo,
        "obs": config.obs,
        "steps": int(model.num_timesteps),
        "train_seconds": elapsed,
        "device": str(device),
        "encoder_precision": getattr(model.policy, "encoder_precision", "float32"),
        "learning_curve": history,
        "env": config.env,
        "learned_return": config.learned_return,
        _reaching_key(config.learned_return): first_step_reaching(history, config.learned_return),
        "final_eval_mean_return": history[-1]["eval_mean_return"] if history else None,
    }
    if autoencoder is not None:  # its training came before DDPG's and is not in train_seconds
        from agents.sb3.autoencoder import autoencoder_seconds

        metrics["autoencoder_train_seconds"] = autoencoder_seconds(autoencoder)
    with folder.kept():
        write_json(run_dir / "metrics.json", metrics)
    return metrics
