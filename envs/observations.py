"""Observation wrappers for model-free baselines (SB3 DDPG) on the pixel pendulum.

| wrapper | observation | dtype | range |
|---|---|---|---|
| the pixel pendulum itself (``frame_stack=1``) | (1, H, W), channel-first; SB3's ``VecFrameStack`` stacks K | uint8 | 0..255 |
| :class:`LatentObservation` | (Z,): an encoder's code of the newest frame; ``VecFrameStack`` stacks K | float32 | [low, high] of the encoder |
| :class:`StateObservation` | (3,): (cos θ, sin θ, θ̇), Pendulum-v1's own proprioception | float32 | [-1, 1], [-1, 1], [-8, 8] |

:class:`EpisodeSeeds` makes each reset's start depend only on (seed, episode index), so that a
resumed training run meets the same starts as an uninterrupted one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from envs.constants import PENDULUM_MAX_SPEED

__all__ = ["EpisodeSeeds", "FiniteActions", "LatentObservation", "NonFiniteAction", "StateObservation"]


class StateObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Replaces the observation by Pendulum-v1's own (cos θ, sin θ, θ̇), read from the simulator.

    The reference point of the baselines ("DDPG from proprioception"); it sees the true state, so
    it is never a from-pixels result.
    """

    def __init__(self, env: gym.Env):
        from gymnasium.envs.classic_control.pendulum import PendulumEnv

        if not isinstance(env.unwrapped, PendulumEnv):
            raise TypeError(f"StateObservation wraps Gymnasium's Pendulum-v1, got {env.unwrapped!r}")
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        high = np.array([1.0, 1.0, PENDULUM_MAX_SPEED], np.float32)
        self.observation_space = gym.spaces.Box(-high, high, dtype=np.float32)

    def observation(self, observation: Any) -> np.ndarray:
        theta, theta_dot = np.asarray(self.env.unwrapped.state, dtype=np.float64)
        return np.array([np.cos(theta), np.sin(theta), theta_dot], np.float32)


class LatentObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Replaces a frame observation (K, H, W) uint8 by an encoder's code of its newest frame.

    Args:
        env: an env with uint8 frame observations (K, H, W) (the pixel pendulum).
        encode: newest frame uint8 (H, W) -> code float32 (Z,), within [low, high].
        size: Z.
        low, high: bounds of the code (for example -1, 1 for a tanh bottleneck).
    """

    def __init__(self, env: gym.Env, encode: Callable[[np.ndarray], np.ndarray], size: int,
                 low: float = -1.0, high: float = 1.0):
        space = env.observation_space
        if not isinstance(space, gym.spaces.Box) or space.dtype != np.uint8 or len(space.shape) != 3:
            raise TypeError(f"LatentObservation needs uint8 frame observations (K, H, W), got {space}")
        if size < 1 or not low < high:
            raise ValueError(f"LatentObservation needs size >= 1 and low < high, got size={size}, low={low}, high={high}")
        gym.utils.RecordConstructorArgs.__init__(self, encode=encode, size=size, low=low, high=high)
        gym.ObservationWrapper.__init__(self, env)
        self.encode = encode
        self.observation_space = gym.spaces.Box(low, high, (size,), dtype=np.float32)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        code = np.asarray(self.encode(observation[-1]), dtype=np.float32)
        if code.shape != self.observation_space.shape:
            raise ValueError(f"the encoder returned shape {code.shape}, expected {self.observation_space.shape}")
        return np.clip(code, self.observation_space.low, self.observation_space.high)


class NonFiniteAction(ValueError):
    """An agent sent a NaN or infinite action (:class:`FiniteActions`); its training has diverged."""


class FiniteActions(gym.ActionWrapper):
    """Refuses NaN or infinite actions with :class:`NonFiniteAction`, before the env steps on them.

    A learner whose weights became NaN sends NaN actions; Gymnasium would step on them and return
    NaN observations and rewards (with a warning each), and the run would go on, scoring NaN.
    """

    def action(self, action: Any) -> Any:
        if not np.all(np.isfinite(action)):
            raise NonFiniteAction(f"the agent's action became {np.asarray(action).ravel().tolist()}")
        return action


class EpisodeSeeds(gym.Wrapper):
    """Resets without a seed use ``seed * 1_000_003 + k`` for the k-th reset (k from ``episodes``).

    SB3's vector envs reset without a seed after the first episode, drawing the start from the
    env's running RNG; with this wrapper the k-th start depends on (seed, k) only, so a run resumed
    at an episode boundary (with ``episodes`` restored) meets the same starts.
    """

    def __init__(self, env: gym.Env, seed: int):
        if seed < 0:
            raise ValueError(f"EpisodeSeeds: seed must be >= 0, got {seed}")
        super().__init__(env)
        self.seed = int(seed)
        self.episodes = 0
        """Resets so far."""

    def seed_of(self, k: int) -> int:
        """The seed of the k-th reset."""
        return self.seed * 1_000_003 + k

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if seed is None:
            seed = self.seed_of(self.episodes)
        self.episodes += 1
        return self.env.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        return self.env.step(action)
