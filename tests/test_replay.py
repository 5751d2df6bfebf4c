"""agents/sb3/replay.py: the device-resident n-step buffer samples SB3's batches, index for index, and survives a
pickle (a checkpoint) as host arrays."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import NStepReplayBuffer

from agents.sb3.replay import DeviceNStepReplayBuffer, fits_on_device, observation_bytes

OBS = spaces.Box(0, 255, (3, 5, 5), np.uint8)
ACTION = spaces.Box(-1, 1, (1,), np.float32)


def _filled(cls: type, size: int = 40, steps: int = 60) -> NStepReplayBuffer:
    """A buffer of ``size`` slots after ``steps`` transitions (so it wrapped), with episode ends and time-outs."""
    buffer = cls(size, OBS, ACTION, device="cpu", n_steps=3, gamma=0.9)
    rng = np.random.default_rng(0)
    for t in range(steps):
        obs, next_obs = (rng.integers(0, 256, (1, *OBS.shape), dtype=np.uint8) for _ in range(2))
        buffer.add(obs, next_obs, rng.uniform(-1, 1, (1, 1)).astype(np.float32), rng.normal(size=1).astype(np.float32),
                   np.array([t % 7 == 6], np.float32), [{"TimeLimit.truncated": t % 11 == 10}])
    return buffer


def test_the_device_buffer_samples_sb3s_batches_index_for_index() -> None:
    reference, device = _filled(NStepReplayBuffer), _filled(DeviceNStepReplayBuffer)
    np.random.seed(3)
    expected = reference.sample(16)
    np.random.seed(3)
    got = device.sample(16)
    for name in expected._fields:
        want, have = getattr(expected, name), getattr(got, name)
        assert torch.equal(have, want), name
    assert got.observations.dtype == torch.uint8 and got.observations.shape == (16, *OBS.shape)


def test_a_pickled_device_buffer_holds_host_arrays_and_samples_the_same() -> None:
    buffer = _filled(DeviceNStepReplayBuffer)
    state = pickle.dumps(buffer)
    loaded = pickle.loads(state)
    assert all(isinstance(store, np.ndarray) for store in loaded._stores)
    np.random.seed(5)
    want = buffer.sample(8)
    np.random.seed(5)
    have = loaded.sample(8)
    assert torch.equal(want.observations, have.observations) and torch.equal(want.next_observations, have.next_observations)
    assert all(isinstance(store, torch.Tensor) for store in loaded._stores)  # moved back on first use


def test_only_a_gpu_with_room_holds_the_observations() -> None:
    assert not fits_on_device(torch.device("cpu"), 100, OBS.shape, OBS.dtype)
    assert observation_bytes(100_000, (9, 84, 84), np.uint8) == 2 * 100_000 * 9 * 84 * 84


def test_the_device_buffer_refuses_observation_normalisation() -> None:
    buffer = _filled(DeviceNStepReplayBuffer)
    with pytest.raises(ValueError, match="VecNormalize"):
        buffer.sample(4, env=object())  # type: ignore[arg-type]
