"""DDPG baselines: the observation wrappers pass Gymnasium's and SB3's checkers, training resumes
exactly, and a trained policy runs in piga's episodes."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.sb3.config import SB3Config
from agents.sb3.train import make_env, make_observation_env

#: Tiny settings: a few seconds of training.
TINY = SB3Config(steps=400, learning_starts=100, eval_every=200, eval_episodes=1, batch_size=16, net_arch=(16, 16),
                  buffer_size=1000)


def _code(frame: np.ndarray) -> np.ndarray:
    """A stand-in encoder: the frame's mean brightness by quadrant, in [-1, 1] (4,)."""
    quads = frame.reshape(2, 32, 2, 32).mean((1, 3)).ravel() / 255.0
    return (2 * quads - 1).astype(np.float32)


@pytest.mark.parametrize("obs", ["pixels", "latent", "state"])
def test_observation_wrappers_pass_gymnasium_and_sb3_checks(obs: str) -> None:
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    config = replace(TINY, obs=obs)
    env = make_observation_env(config, _code, 4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any complaint of either checker fails the test, except
        warnings.filterwarnings("ignore", message=".*different from the unwrapped")  # "it is wrapped": the point
        # Pendulum-v1's own torque range [-2, 2]; SB3's DDPG rescales actions to [-1, 1] itself
        warnings.filterwarnings("ignore", message=".*symmetric and normalized")
        gym_check_env(env, skip_render_check=True)
        sb3_check_env(make_env(config, _code, 4, episode_seed=0), warn=True)  # as training sees it, with Monitor
    first, _ = env.reset(seed=5)
    assert env.observation_space.contains(first)
    expected = {"pixels": ((1, 64, 64), np.uint8), "latent": ((4,), np.float32), "state": ((3,), np.float32)}[obs]
    assert (first.shape, first.dtype) == expected
    if obs == "state":
        theta, theta_dot = env.unwrapped.state
        assert np.allclose(first, [np.cos(theta), np.sin(theta), theta_dot], atol=1e-6)
    env.close()


def test_wrappers_refuse_wrong_spaces() -> None:
    import gymnasium as gym

    from envs.observations import LatentObservation, StateObservation

    with pytest.raises(TypeError, match="uint8 frame"):
        LatentObservation(gym.make("Pendulum-v1"), _code, 4)
    with pytest.raises(TypeError, match="Pendulum"):
        StateObservation(gym.make("CartPole-v1"))


def test_training_resumes_exactly(tmp_path: Path) -> None:
    from agents.sb3.run import load_sb3
    from agents.sb3.train import train_sb3

    straight = train_sb3(TINY, tmp_path / "a", progress=False)
    train_sb3(replace(TINY, steps=200), tmp_path / "moved", progress=False)
    (tmp_path / "moved").rename(tmp_path / "b")  # a run folder moved between the two invocations
    resumed = train_sb3(TINY, tmp_path / "b", resume=True, progress=False)
    assert not (tmp_path / "moved").exists(), "the resumed run logged to the folder it was moved from"
    assert [r["step"] for r in straight["learning_curve"]] == [200, 400]
    assert [r["eval_mean_return"] for r in resumed["learning_curve"]] == [r["eval_mean_return"] for r in straight["learning_curve"]]
    a, b = load_sb3(tmp_path / "a")[0], load_sb3(tmp_path / "b")[0]
    for (name, p), q in zip(a.policy.state_dict().items(), b.policy.state_dict().values()):
        assert torch.equal(p, q), name
    assert (tmp_path / "a" / "model.zip").exists() and (tmp_path / "a" / "tensorboard").is_dir()
    # the replay buffer is a file of its own, named by the checkpoint; only the latest step's is kept
    assert [p.name for p in (tmp_path / "a" / "replay_buffers").iterdir()] == ["400.pkl"]


@pytest.mark.slow
def test_a_checkpoint_with_its_replay_buffer_inside_resumes_exactly(tmp_path: Path) -> None:
    """Runs checkpointed before the buffer had a file of its own held its bytes in checkpoint.pt: they continue; a
    checkpoint whose buffer file is gone is named, not an internal error."""
    from agents.sb3.train import train_sb3
    from piga.io.checkpoint import write_checkpoint

    straight = train_sb3(TINY, tmp_path / "a", progress=False)
    train_sb3(replace(TINY, steps=200), tmp_path / "b", progress=False)
    ckpt = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=False)
    buffer = tmp_path / "b" / ckpt.pop("replay_buffer_file")
    write_checkpoint(tmp_path / "b", {**ckpt, "replay_buffer": buffer.read_bytes()})
    buffer.unlink()
    resumed = train_sb3(TINY, tmp_path / "b", resume=True, progress=False)
    assert resumed["learning_curve"] == [{**r, "seconds": q["seconds"]} for r, q in
                                         zip(straight["learning_curve"], resumed["learning_curve"])]
    (tmp_path / "b" / "replay_buffers" / "400.pkl").unlink()
    with pytest.raises(ValueError, match=r"400.pkl, the replay buffer that .*checkpoint.pt names, is missing"):
        train_sb3(replace(TINY, steps=600), tmp_path / "b", resume=True, progress=False)
    (tmp_path / "b" / "replay_buffers" / "400.pkl").mkdir()  # a folder in its place was called missing
    with pytest.raises(ValueError, match=r"400.pkl, the replay buffer that .*checkpoint.pt names, is not a file"):
        train_sb3(replace(TINY, steps=600), tmp_path / "b", resume=True, progress=False)


@pytest.mark.slow
def test_a_pixel_policy_runs_in_piga_episodes_with_sb3s_stacking(tmp_path: Path) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

    from agents.sb3.run import SB3Agent
    from agents.sb3.train import train_sb3
    from piga.control.episodes import EpisodeConfig, run_episodes

    config = replace(TINY, obs="pixels", steps=200, learning_starts=150, batch_size=4)
    train_sb3(config, tmp_path / "run", progress=False)
    agent = SB3Agent.from_run(tmp_path / "run")
    result = run_episodes(agent, EpisodeConfig(episodes=1, steps=20, hold_steps=5, frame_stack=agent.input_frames))
    assert np.isfinite(result.summary.mean_return)
    # the agent's own stack is SB3's VecFrameStack: zeros at reset, newest frame last
    venv = VecFrameStack(DummyVecEnv([lambda: make_env(config)]), config.frame_stack, channels_order="first")
    venv.seed(3)
    stacked = venv.reset()
    agent.reset()
    agent.act(stacked[0][-1:], np.zeros(2))
    assert agent._stack is not None and np.array_equal(agent._stack, stacked[0])
    for _ in range(5):
        stacked, *_ = venv.step(np.zeros((1, 1), np.float32))
        agent.act(stacked[0][-1:], np.zeros(2))
        assert np.array_equal(agent._stack, stacked[0])
    venv.close()


@pytest.mark.slow
def test_a_latent_run_trains_on_its_autoencoders_codes_and_records_its_cost(tiny_data: Path, tmp_path: Path) -> None:
    from agents.sb3.autoencoder import AutoencoderConfig, train_autoencoder
    from agents.sb3.run import SB3Agent
    from agents.sb3.train import train_sb3
    from piga.control.episodes import EpisodeConfig, run_episodes

    run = tmp_path / "run"
    run.mkdir()
    train_autoencoder(tiny_data, AutoencoderConfig(steps=2, depth=4, batch_size=2), run / "autoencoder.pt", progress=False)
    metrics = train_sb3(replace(TINY, obs="latent", steps=200, learning_starts=150, batch_size=4), run, run / "autoencoder.pt",
                         progress=False)
    assert metrics["autoencoder_train_seconds"] > 0  # the compute table adds it to DDPG's own seconds
    agent = SB3Agent.from_run(run)
    assert agent.model.observation_space.shape == (TINY.frame_stack * 8,)  # K stacked 8-number codes
    assert np.isfinite(run_episodes(agent, EpisodeConfig(episodes=1, steps=10, hold_steps=5)).summary.mean_return)


def test_each_algorithm_has_its_own_zoo_values() -> None:
    """The values config_for gave each (observation, algorithm) before SB3Config resolved them itself."""
    ddpg = {"gamma": 0.98, "buffer_size": 200_000, "learning_starts": 10_000, "noise_std": 0.1, "net_arch": (400, 300)}
    sac = {"gamma": 0.99, "buffer_size": 1_000_000, "learning_starts": 100, "noise_std": 0.0, "net_arch": (256, 256)}
    for algo, values in (("ddpg", ddpg), ("sac", sac)):
        for obs in ("state", "latent", "pixels"):
            config = SB3Config(obs=obs, algo=algo)  # type: ignore[arg-type]
            expected = {**values, "buffer_size": 50_000} if obs == "pixels" else values
            assert {name: getattr(config, name) for name in values} == expected, (algo, obs)
    assert SB3Config(algo="sac", gamma=0.95, buffer_size=1000).gamma == 0.95  # a value given wins
    assert SB3Config(**SB3Config(algo="sac").to_dict()) == SB3Config(algo="sac")  # a run's record reads back
    with pytest.raises(ValueError, match="unknown algorithm 'td3'"):
        SB3Config(algo="td3")  # type: ignore[arg-type]
