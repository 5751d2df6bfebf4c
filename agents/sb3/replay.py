"""SB3's n-step replay buffer with its observations kept on the training device (a GPU).

On a GPU, DrQ-v2's update spent 57% of its time sampling its batch (``benchmarks/drqv2_step_time.py``: 15 of 27 ms
on an H200): SB3's buffer gathers 256 stacks of 3 84x84 RGB frames from host memory, twice (the observations and
the n-th next ones), copies them into tensors, and moves those to the GPU. :class:`DeviceNStepReplayBuffer` keeps
the observations in GPU memory instead, so that a batch is two gathers there.

Everything else is SB3's :class:`~stable_baselines3.common.buffers.NStepReplayBuffer`, unchanged: its arrays
``observations`` and ``next_observations`` hold, instead of the stacks, each slot's row number in the device's
stores, so SB3's own n-step sampling (indices, episode ends, discounts) picks the rows, and the stacks are then
read from the device with those rows. The batches are the same as SB3's, index for index.

Pickled (a checkpoint), the stores travel as host arrays; :meth:`DeviceNStepReplayBuffer.stores` moves them to
the buffer's device when next used, so a run resumes on any device.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples

__all__ = ["DeviceNStepReplayBuffer", "fits_on_device"]

#: The share of a GPU's free memory that a buffer's observations may take there (the rest is the networks' and
#: the batches').
DEVICE_MEMORY_SHARE = 0.5


def observation_bytes(buffer_size: int, shape: tuple[int, ...], dtype: np.dtype) -> int:
    """Bytes of a buffer's observations and next observations."""
    return 2 * buffer_size * int(np.prod(shape)) * np.dtype(dtype).itemsize


def fits_on_device(device: torch.device, buffer_size: int, shape: tuple[int, ...], dtype: np.dtype) -> bool:
    """Whether ``device`` is a CUDA GPU with room for a buffer's observations (:data:`DEVICE_MEMORY_SHARE` of its
    free memory)."""
    if device.type != "cuda":
        return False
    free, _ = torch.cuda.mem_get_info(device)
    return observation_bytes(buffer_size, shape, dtype) <= DEVICE_MEMORY_SHARE * free


class DeviceNStepReplayBuffer(NStepReplayBuffer):
    """:class:`~stable_baselines3.common.buffers.NStepReplayBuffer` whose observations live on ``device`` (module
    docstring). Takes SB3's arguments."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        rows = self.buffer_size * self.n_envs
        dtype = torch.from_numpy(np.zeros(0, self.observation_space.dtype)).dtype
        # empty, not zeros: a buffer built only to be replaced by a checkpoint's (SB3's load) touches no memory
        self._stores: tuple[Any, Any] = (torch.empty((rows, *self.obs_shape), dtype=dtype, device=self.device),  # (N·E, *obs)
                                         torch.empty((rows, *self.obs_shape), dtype=dtype, device=self.device))  # next ones
        # SB3's observation arrays, replaced (their pages were never touched) by each slot's row: (N, E)
        self.observations = np.arange(rows, dtype=np.int64).reshape(self.buffer_size, self.n_envs)
        self.next_observations = self.observations

    def stores(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The observations and next observations (N·E, *obs), on the buffer's device (moved there once after a load)."""
        device = torch.device(self.device)
        if isinstance(self._stores[0], np.ndarray) or self._stores[0].device != device:
            self._stores = tuple(torch.as_tensor(store).to(device) for store in self._stores)
        return self._stores

    def add(self, obs: np.ndarray, next_obs: np.ndarray, action: np.ndarray, reward: np.ndarray, done: np.ndarray,
            infos: list[dict[str, Any]]) -> None:
        rows = self.observations[self.pos]  # (E,) this slot's rows
        store, next_store = self.stores()
        index = torch.from_numpy(rows).to(store.device)
        store[index] = torch.from_numpy(np.asarray(obs).reshape(self.n_envs, *self.obs_shape)).to(store.device)
        next_store[index] = torch.from_numpy(np.asarray(next_obs).reshape(self.n_envs, *self.obs_shape)).to(store.device)
        super().add(rows, rows, action, reward, done, infos)  # SB3's bookkeeping; the rows stay the rows

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> ReplayBufferSamples:
        if env is not None:  # SB3's VecNormalize would normalise the row numbers
            raise ValueError("DeviceNStepReplayBuffer does not normalise observations (VecNormalize)")
        samples = super()._get_samples(batch_inds, env)  # SB3's n-step sample, with rows for observations
        store, next_store = self.stores()
        return samples._replace(observations=store[samples.observations.to(store.device, torch.long)],
                                next_observations=next_store[samples.next_observations.to(store.device, torch.long)])

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        # as host arrays, which pickle streams to the file without a copy (a tensor's storage pickles through bytes),
        # and which load where there is no GPU
        state["_stores"] = tuple(store.cpu().numpy() if isinstance(store, torch.Tensor) else store for store in self._stores)
        return state
