"""PlaNet's own data loop, as an option of the PlaNet-style baseline: train on the data file, then
repeat "collect episodes with the planner plus exploration noise, train more on everything".

The loop (:class:`agents.planet.config.IterativeConfig`):

1. train ``PlanetTrainConfig.steps`` steps on the file's random-action sequences (as without the option);
2. round r = 1 .. ``rounds``: run ``episodes`` episodes of ``episode_steps`` steps with the latent
   planner (PlaNet's settings), each action plus N(0, (noise·2)²) and clipped; cut each episode into
   sequences of the file's length T (frames x_t, actions u_t after x_t, Gymnasium's rewards for
   u_t; no states, which training never reads) and append them to ``RUN_DIR/collected.h5``; then train
   until step ``steps + r·steps_per_round`` on the file's train split and all collected sequences.

The user's data file is only read. ``collected.h5`` is rewritten atomically after each round's
collection, in piga's schema (its attrs ``rounds`` and ``episode_returns`` say how many rounds it
holds and what each episode returned), so an interrupted run resumes exactly: a round whose
collection was cut short is collected again from the same checkpoint with the same seeds (episode e
of round r draws its start, noise and planner seed from ``SeedSequence(seed, spawn_key=(r, e))``),
and training resumes from its last checkpoint with its saved generators.

Frames are rendered as the data file's were (its ``env_config``: the torque arrow, gravity, effects).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from agents.planet.config import IterativeConfig, LatentPlannerConfig, PlanetTrainConfig, RSSMConfig
from agents.planet.planner import PlanetAgent
from agents.planet.rssm import WorldModel
from agents.planet.run import load_planet
from agents.planet.train import PlanetState, check_planet_data, train_planet
from envs import PIXEL_PENDULUM
from envs.fields import counted
from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum
from piga.data.schema import (DataFormatError, DatasetInfo, DatasetWriter, check_pixel_pendulum_file, inspect_dataset,
                              load_rewards, read_sequences)
from piga.io.atomic import write_json
from piga.io.checkpoint import CHECKPOINT
from piga.io.progress import close_bar

#: The collected episodes' file in a run folder.
COLLECTED = "collected.h5"

__all__ = ["COLLECTED", "check_iterative_data", "collect_round", "rounds_collected", "train_planet_iterative"]


def check_iterative_data(info: DatasetInfo, config: IterativeConfig) -> PixelPendulumConfig:
    """The env that renders frames like the data file's; refuses files it cannot extend.

    Raises:
        DataFormatError: not the pixel pendulum's file.
        ValueError: ``config``'s episodes shorter than one of its sequences.
    """
    check_pixel_pendulum_file(info, f"the iterative mode collects on {PIXEL_PENDULUM} and renders like the file")
    if config.episode_steps < info.steps:  # the config's to change, not the file: a ValueError, which names the field
        raise ValueError(f"IterativeConfig.episode_steps must be at least the sequence length of {info.path} "
                         f"({info.steps} frames): collected episodes of {config.episode_steps} steps would be shorter "
                         f"than the file's sequences; raise IterativeConfig.episode_steps to {info.steps} or more")
    fields = info.attrs["env_config"]  # a JSON object (inspect_dataset checked it)
    known = {f.name for f in dataclasses.fields(PixelPendulumConfig)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise DataFormatError(f"{info.path}: attribute 'env_config' has unknown field(s) {', '.join(unknown)}; "
                              f"PixelPendulumConfig knows {', '.join(sorted(known))}")
    try:
        effects = tuple(tuple(effect) for effect in fields.get("effects", ()))
        env = PixelPendulumConfig(**{**fields, "effects": effects})
    except (TypeError, ValueError) as exc:
        raise DataFormatError(f"{info.path}: attribute 'env_config' is not a valid PixelPendulumConfig ({exc})") from None
    return replace(env, frame_stack=1, episode_length=config.episode_steps)


def rounds_collected(run_dir: str | Path, per_round: int | None = None) -> int:
    """Rounds whose episodes ``run_dir/collected.h5`` holds (0 without one).

    ``per_round``: the sequences that each round appends; where given, the file's ``rounds`` must account for its
    sequences (a DataFormatError otherwise: an edited attribute would skip rounds or collect them twice).
    """
    path = Path(run_dir) / COLLECTED
    if not path.exists():
        return 0
    try:
        info = inspect_dataset(path)
        rounds = int(info.attrs["rounds"])
    except (DataFormatError, KeyError, TypeError, ValueError) as exc:  # truncated or edited
        raise DataFormatError(f"{path}, the run's collected episodes, cannot be read ({' '.join(str(exc).split())}): "
                              "restore it, or train the run again with --overwrite") from None
    if per_round is not None and (rounds < 0 or info.n_sequences != rounds * per_round):
        raise DataFormatError(f"{path}, the run's collected episodes, says it holds {counted(rounds, 'round')} of "
                              f"{counted(per_round, 'sequence')}, but it holds {counted(info.n_sequences, 'sequence')}; "
                              "the run cannot continue exactly: restore it, or train the run again with --overwrite")
    return rounds


def collect_round(model: WorldModel, env_config: PixelPendulumConfig, config: IterativeConfig, planner: LatentPlannerConfig,
                  seed: int, round_index: int, length: int, progress: bool = False) -> dict[str, Any]:
    """One round's episodes with the planner plus exploration noise, cut into sequences of ``length`` frames.

    Returns:
        frames uint8 (n, T, H, W), actions (n, T, 1), rewards (n, T) with
        n = episodes · (episode_steps // T), and each episode's return (over all its steps).
    """
    env = make_pixel_pendulum(env_config)
    per_episode = config.episode_steps // length
    keep = per_episode * length
    frames, actions, rewards, returns = [], [], [], []
    bar = tqdm(total=config.episodes * config.episode_steps, desc=f"collect round {round_index}", unit="step", disable=not progress)
    try:
        for episode in range(config.episodes):
            child = np.random.SeedSequence(seed, spawn_key=(round_index, episode))
            reset_seed, planner_seed = (int(x) for x in child.generate_state(2, dtype=np.uint32))
            noise_rng = np.random.default_rng(child.spawn(1)[0])
            agent = PlanetAgent(model, replace(planner, seed=planner_seed))
            agent.reset()
            obs, _ = env.reset(seed=reset_seed)
            ep: dict[str, list[Any]] = {"frames": [], "actions": [], "rewards": []}
            for _ in range(config.episode_steps):
                ep["frames"].append(obs[-1])
                action = agent.explore(obs, noise_rng, config.noise)
                obs, reward, _, _, _ = env.step(action)
                ep["actions"].append(action)
                ep["rewards"].append(reward)
                bar.update(1)
            returns.append(float(np.sum(ep["rewards"])))
            shape = lambda x, dtype: np.asarray(x[:keep], dtype).reshape(per_episode, length, *np.shape(x[0]))  # noqa: E731
            frames.append(shape(ep["frames"], np.uint8))
            actions.append(shape(ep["actions"], np.float32))
            rewards.append(shape(ep["rewards"], np.float32))
    finally:
        close_bar(bar)  # cleared on an error: its line is the last
        env.close()
    return {"frames": np.concatenate(frames), "actions": np.concatenate(actions), "rewards": np.concatenate(rewards), "returns": returns}


def _append(path: Path, info: DatasetInfo, env: PixelPendulumConfig, new: dict[str, Any], round_index: int,
            command: str, seed: int) -> None:
    """Rewrites ``path`` atomically with its sequences and ``new``'s (all in the train split); its ``env_config`` is
    ``env``, the env that collected them (the source file's episode length is not theirs), with its ``effects`` (which
    training scores the gain against), and its ``seed`` the run's, from which each round's episodes draw theirs."""
    old: dict[str, Any] = {"returns": []}
    if path.exists():
        frames, actions = read_sequences(path, "train")
        old = {"frames": frames, "actions": actions, "rewards": load_rewards(path, "train"),
               "returns": list(inspect_dataset(path).attrs["episode_returns"])}
    joined = {key: np.concatenate([old[key], new[key]]) if key in old else new[key] for key in ("frames", "actions", "rewards")}
    n, t = joined["rewards"].shape
    attrs = {key: info.attrs[key] for key in ("system", "dt", "params", "env_id") if key in info.attrs}
    attrs.update({"env_config": env.to_dict(), "effects": dict(env.effects), "seed": seed, "rounds": round_index,
                  "episode_returns": old["returns"] + new["returns"], "command": command, "source": str(info.path),
                  "split_counts": {"train": n, "valid": 0, "test": 0}})
    with DatasetWriter(path, n, t, joined["frames"].shape[2:], joined["actions"].shape[2], None, attrs,
                       overwrite=True, rewards=True) as writer:
        writer.write(0, joined["frames"], joined["actions"], rewards=joined["rewards"])
        writer.set_split(np.zeros(n, np.int8))


def _step_of(run_dir: Path) -> int:
    """The optimiser step of ``run_dir``'s checkpoint (0 without one)."""
    return int(load_planet(run_dir)[1]["state"]["step"]) if (run_dir / CHECKPOINT).exists() else 0


def train_planet_iterative(
    data: str | Path,
    run_dir: str | Path,
    config: PlanetTrainConfig,
    iterative: IterativeConfig,
    rssm: RSSMConfig | None = None,
    resume: bool = False,
    progress: bool = True,
    on_checkpoint: Callable[[PlanetState], None] | None = None,
    planner: LatentPlannerConfig | None = None,
    command: str = "",
) -> tuple[WorldModel, PlanetState]:
    """Trains on ``data``, then runs ``iterative.rounds`` collect-then-train rounds (module docstring).

    ``planner``: the latent planner's settings while collecting (None: PlaNet's). With ``resume``,
    continues ``run_dir`` exactly where it stopped (``config`` and ``iterative`` should be its saved
    ones, possibly with more rounds). ``metrics.json`` gains an ``iterative``
    record: rounds done, collected sequences and each collected episode's return.

    Returns:
        The final model (eval mode) and state.
    """
    run_dir = Path(run_dir)
    info = inspect_dataset(data)
    check_planet_data(info, config)  # train_planet checks again with the model's action repeat
    env_config = check_iterative_data(info, iterative)
    collected = run_dir / COLLECTED
    has_checkpoint = (run_dir / CHECKPOINT).exists()
    model, state = None, None
    if not resume or _step_of(run_dir) < config.steps:  # the first training, on the file alone
        model, state = train_planet(data, run_dir, config, rssm, resume=resume and has_checkpoint, progress=progress,
                                    on_checkpoint=on_checkpoint)
    done = rounds_collected(run_dir, iterative.episodes * (iterative.episode_steps // info.steps))
    for r in range(1, iterative.rounds + 1):
        target = config.steps + r * iterative.steps_per_round
        if done < r:
            if _step_of(run_dir) > target - iterative.steps_per_round:
                raise ValueError(f"{collected} holds {done} rounds, but {run_dir / CHECKPOINT} was trained past round {r - 1}; "
                                 "the run cannot continue exactly (was collected.h5 removed?): restore it, or train the "
                                 "run again with --overwrite")
            new = collect_round(load_planet(run_dir)[0], env_config, iterative, planner or LatentPlannerConfig(), config.seed, r,
                                info.steps, progress)
            _append(collected, info, env_config, new, r, command, config.seed)
            done = r
        if _step_of(run_dir) < target:
            model, state = train_planet(data, run_dir, replace(config, steps=target), resume=True, progress=progress,
                                        on_checkpoint=on_checkpoint, extra_data=collected)
        _record(run_dir, collected)
    if model is None or state is None:  # nothing left to do: the run as it is
        model, ckpt = load_planet(run_dir)
        state = PlanetState(**ckpt["state"])
    return model, state


def _record(run_dir: Path, collected: Path) -> None:
    """Adds the iterative record to ``metrics.json``."""
    metrics_path = run_dir / "metrics.json"
    metrics = json.loads(metrics_path.read_text())
    attrs = inspect_dataset(collected).attrs
    metrics["iterative"] = {"rounds": int(attrs["rounds"]), "collected_sequences": inspect_dataset(collected).n_sequences,
                            "episode_returns": list(attrs["episode_returns"])}
    write_json(metrics_path, metrics, overwrite=True)
