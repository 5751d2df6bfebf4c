"""Training items from a data file: runs of consecutive frames with their actions (a torch Dataset),
served from memory or streamed from the file through a bounded cache, and the order a streamed file
is read in (:class:`BlockShuffleSampler`)."""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import h5py
import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from piga.data.schema import (IN_MEMORY_LIMIT_BYTES, DataFormatError, check_frames_have_signal, inspect_dataset, load_actions,
                              open_data_file, read_rows, read_sequences, split_indices)

#: The streaming reader's cache of whole sequences of frames, in bytes.
STREAM_CACHE_BYTES = 256 * 1024**2


def loads_whole(frame_bytes: int, available: int | None) -> bool:
    """Whether a split whose frames need ``frame_bytes`` is loaded whole rather than streamed: when it
    needs less than :data:`IN_MEMORY_LIMIT_BYTES` and less than a quarter of the ``available`` memory
    (None: unknown, the first test alone)."""
    return frame_bytes < IN_MEMORY_LIMIT_BYTES and (available is None or 4 * frame_bytes < available)


class Window(NamedTuple):
    """One training item: a run of consecutive frames and the actions after each."""

    frames: torch.Tensor
    """uint8 (W, H, W_img) or (W, H, W_img, C)."""
    actions: torch.Tensor
    """float32 (W, A)."""


class SequenceReader:
    """Whole sequences of a file's frames, read on demand through a cache of at most ``cache_bytes``
    (at least one sequence), the least recently used out first: memory stays bounded whatever the
    file's size. It pickles without its file handle and cache.

    The cache is ours, not HDF5's chunk cache, because each h5py read costs about 50-100 us of Python
    before any decompression (measured), twice a 64x64 window's slicing; whole sequences are read, and
    all have one size, so a count (``functools.lru_cache``'s) bounds the bytes.

    Args:
        path: an HDF5 file of piga's schema.
        sequences: the file's sequence indices that position 0, 1, ... stand for.
        cache_bytes: the cache's size.
    """

    def __init__(self, path: str | os.PathLike[str], sequences: np.ndarray, cache_bytes: int = STREAM_CACHE_BYTES):
        self.path, self.sequences = Path(path), np.asarray(sequences)
        with open_data_file(self.path) as f:
            self.sequence_bytes = int(np.prod(f["frames"].shape[1:]))
        self.capacity = max(1, cache_bytes // max(1, self.sequence_bytes))
        """Sequences the cache holds."""
        self._file: h5py.File | None = None
        self._cached: Callable[[int], np.ndarray] | None = None

    def __call__(self, position: int) -> np.ndarray:
        """The frames of sequence ``sequences[position]``: uint8 (T, H, W[, C]); a cached array, not to be written."""
        if self._cached is None:
            self._cached = functools.lru_cache(maxsize=self.capacity)(self._read)
        return self._cached(int(position))

    def _read(self, position: int) -> np.ndarray:
        if self._file is None:  # opened directly: __init__ read the file's header through open_data_file's check
            self._file = h5py.File(self.path, "r")
        index = int(self.sequences[position])
        with read_rows(self._file["frames"], f"sequence {index}"):
            return self._file["frames"][index]

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_file"] = state["_cached"] = None
        return state

    def close(self) -> None:
        """Closes the file, if open, and empties the cache."""
        self._cached = None
        if self._file is not None:
            self._file.close()
            self._file = None


class SequenceWindows(Dataset[Window]):
    """Every run of ``window`` consecutive frames in one split, as a torch Dataset.

    Only frames and actions are served, never states. ``in_memory=True`` loads the split's frames
    once, which is fastest when they fit. Otherwise (streaming) each item is read from the file through
    a cache of whole sequences of ``cache_bytes``: a sequence is read (and decompressed) once while it
    stays in the cache, so reading in :class:`BlockShuffleSampler`'s order reads each once per epoch, and
    memory stays bounded whatever the file's size. By default (None) the split is loaded when
    :func:`loads_whole` says so. The actions are always loaded (12 bytes a frame). The object pickles
    without its file handle, so it works with DataLoader worker processes.

    Args:
        path: an HDF5 file of piga's schema.
        split: "train", "valid" or "test".
        window: frames per item (for example L + T_pred); at most the file's T.
        stride: step between the start frames of consecutive windows of one sequence.
        in_memory: load the split whole (None: decide by size and available memory).
        cache_bytes: the streaming reader's cache (:class:`SequenceReader`).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        split: str,
        window: int,
        stride: int = 1,
        in_memory: bool | None = None,
        cache_bytes: int = STREAM_CACHE_BYTES,
    ):
        self.path = Path(path)
        self.info = inspect_dataset(self.path)
        check_frames_have_signal(self.path)  # a blank video has nothing to train on
        for name, value in (("window", window), ("stride", stride)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name} must be an integer, got {value!r}")
        if window < 1:
            raise ValueError(f"window must be >= 1 (frames per item), got {window}")
        if cache_bytes < 0:
            raise ValueError(f"cache_bytes must be >= 0, got {cache_bytes}")
        if window > self.info.steps:
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
        if in_memory is None:
            from piga.io.resources import available_memory

            in_memory = loads_whole(len(self.sequences) * self.info.sequence_bytes, available_memory())
        self.in_memory = in_memory
        self._frames: np.ndarray | None = None
        self.reader: SequenceReader | None = None
        if in_memory:
            self._frames, self._actions = read_sequences(self.path, split)
        else:
            self.reader = SequenceReader(self.path, self.sequences, cache_bytes)
            self._actions = load_actions(self.path, split)  # (n, T, A)

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
        actions = self._actions[seq_pos, start:stop]
        if self._frames is not None:
            frames = self._frames[seq_pos, start:stop]
        else:
            assert self.reader is not None
            frames = self.reader(seq_pos)[start:stop]
        return Window(torch.from_numpy(np.ascontiguousarray(frames)), torch.from_numpy(np.ascontiguousarray(actions)))

    @property
    def sequences_cached(self) -> int:
        """Whole sequences that the streaming reader's cache holds (all, when loaded whole): the block of
        :class:`BlockShuffleSampler`, whose sequences stay in the cache while their windows are read."""
        return self.reader.capacity if self.reader is not None else len(self.sequences)

    def close(self) -> None:
        """Closes the streaming reader's file, if open, and empties its cache."""
        if self.reader is not None:
            self.reader.close()


class BlockShuffleSampler(Sampler[int]):
    """Every item of a :class:`SequenceWindows` once per pass, in an order that a streamed file reads
    fast: the sequences in a random order, cut into blocks of ``block`` sequences, and each block's
    windows shuffled together. With a block that the reader's cache holds, each sequence is read (and
    decompressed) once per pass instead of once per window. Random sampling's order, over the whole
    split, is what a file loaded whole gets (torch's ``RandomSampler``); this one is the shuffle buffer
    of streaming data loaders. ``generator`` (a torch.Generator) fixes the order, so a resumed run
    sees the same.
    """

    def __init__(self, windows: SequenceWindows, block: int, generator: torch.Generator | None = None):
        if block < 1:
            raise ValueError(f"block must be >= 1 sequence, got {block}")
        self.sequences, self.per_sequence = len(windows.sequences), len(windows.starts)
        self.block, self.generator = block, generator

    def __len__(self) -> int:
        return self.sequences * self.per_sequence

    def __iter__(self) -> Iterator[int]:
        order = torch.randperm(self.sequences, generator=self.generator)  # (n,)
        offsets = torch.arange(self.per_sequence)  # (W,)
        for first in range(0, self.sequences, self.block):
            items = (order[first : first + self.block, None] * self.per_sequence + offsets).flatten()  # (b·W,)
            yield from items[torch.randperm(len(items), generator=self.generator)].tolist()
