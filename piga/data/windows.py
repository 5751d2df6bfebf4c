"""Training items from a data file: runs of consecutive frames with their actions (a torch Dataset)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, NamedTuple

import h5py
import numpy as np
import torch
from torch.utils.data import Dataset

from piga.data.schema import (IN_MEMORY_LIMIT_BYTES, DataFormatError, check_frames_have_signal, inspect_dataset, read_sequences,
                       split_indices)


class Window(NamedTuple):
    """One training item: a run of consecutive frames and the actions after each."""

    frames: torch.Tensor
    """uint8 (W, H, W_img) or (W, H, W_img, C)."""
    actions: torch.Tensor
    """float32 (W, A)."""


class SequenceWindows(Dataset[Window]):
    """Every run of ``window`` consecutive frames in one split, as a torch Dataset.

    Only frames and actions are served, never states. The file is read lazily, one sequence at a
    time. ``in_memory=True`` loads the split once, which is faster for training when it fits. By
    default it does so when the split's frames need less than :data:`IN_MEMORY_LIMIT_BYTES`. The
    object pickles without its file handle, so it works with DataLoader worker processes.

    Args:
        path: an HDF5 file of piga's schema.
        split: "train", "valid" or "test".
        window: frames per item (for example L + T_pred); at most the file's T.
        stride: step between the start frames of consecutive windows of one sequence.
        in_memory: load the split whole (None: decide by size).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        split: str,
        window: int,
        stride: int = 1,
        in_memory: bool | None = None,
    ):
        self.path = Path(path)
        self.info = inspect_dataset(self.path)
        check_frames_have_signal(self.path)  # a blank video has nothing to train on
        if window < 1 or window > self.info.steps:
            raise DataFormatError(
                f"{self.path}: sequences have {self.info.steps} frames, fewer than the {window} needed per item"
            )
        if stride < 1:
            raise ValueError(f"stride must be >= 1, got {stride}")
        self.split, self.window, self.stride = split, window, stride
        self.sequences = split_indices(self.path, split)
        if len(self.sequences) == 0:
            raise DataFormatError(f"{self.path}: split '{split}' has no sequences")
        self.starts = np.arange(0, self.info.steps - window + 1, stride)
        frame_bytes = len(self.sequences) * self.info.steps * int(np.prod(self.info.image_shape))
        if in_memory is None:
            in_memory = frame_bytes < IN_MEMORY_LIMIT_BYTES
        self._frames: np.ndarray | None = None
        self._actions: np.ndarray | None = None
        if in_memory:
            self._frames, self._actions = read_sequences(self.path, split)
        self._file: h5py.File | None = None

    def __len__(self) -> int:
        return len(self.sequences) * len(self.starts)

    def locate(self, item: int) -> tuple[int, int]:
        """(sequence index in the file, start frame) of an item."""
        seq, start = divmod(item, len(self.starts))
        return int(self.sequences[seq]), int(self.starts[start])

    def __getitem__(self, item: int) -> Window:
        if not 0 <= item < len(self):
            raise IndexError(item)
        seq_pos, start_pos = divmod(item, len(self.starts))
        start = int(self.starts[start_pos])
        stop = start + self.window
        if self._frames is not None and self._actions is not None:
            frames, actions = self._frames[seq_pos, start:stop], self._actions[seq_pos, start:stop]
        else:
            if self._file is None:
                self._file = h5py.File(self.path, "r")
            seq = int(self.sequences[seq_pos])
            frames = self._file["frames"][seq, start:stop]
            actions = self._file["actions"][seq, start:stop].astype(np.float32)
        return Window(torch.from_numpy(np.ascontiguousarray(frames)), torch.from_numpy(np.ascontiguousarray(actions)))

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_file"] = None
        return state

    def close(self) -> None:
        """Closes the lazily opened file, if any."""
        if self._file is not None:
            self._file.close()
            self._file = None
