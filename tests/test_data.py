"""The HDF5 schema: round trip, validation messages, and the training Dataset."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from piga.data.schema import DataFormatError, DatasetWriter, inspect_dataset, load_states, read_sequences, split_indices
from piga.data.windows import SequenceWindows, Window


def _write(path: Path, n: int = 6, t: int = 5, colour: bool = False, states: bool = True) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    shape = (8, 8, 3) if colour else (8, 8)
    arrays = {
        "frames": rng.integers(0, 256, (n, t, *shape), dtype=np.uint8),
        "actions": rng.normal(size=(n, t, 2)).astype(np.float32),
        "states": rng.normal(size=(n, t, 3)).astype(np.float32),
        "split": np.array([0, 1, 0, 2, 0, 1][:n], np.int8),
    }
    with DatasetWriter(path, n, t, shape, 2, 3 if states else None, {"system": "toy", "dt": 0.1, "params": {"k": 2.0}}) as w:
        w.write(0, arrays["frames"][:4], arrays["actions"][:4], arrays["states"][:4] if states else None)
        w.write(4, arrays["frames"][4:], arrays["actions"][4:], arrays["states"][4:] if states else None)
        w.set_split(arrays["split"])
    return arrays


@pytest.mark.parametrize("colour", [False, True])
def test_round_trip(tmp_path: Path, colour: bool) -> None:
    path = tmp_path / "d.h5"
    arrays = _write(path, colour=colour)
    info = inspect_dataset(path)
    assert info.image_shape == ((8, 8, 3) if colour else (8, 8))
    assert info.split_counts == {"train": 3, "valid": 2, "test": 1}
    assert info.params == {"k": 2.0} and info.attrs["piga_version"]
    frames, actions = read_sequences(path, "train")
    np.testing.assert_array_equal(frames, arrays["frames"][[0, 2, 4]])
    np.testing.assert_array_equal(actions, arrays["actions"][[0, 2, 4]])
    np.testing.assert_array_equal(load_states(path, "valid"), arrays["states"][[1, 5]])
    np.testing.assert_array_equal(split_indices(path, "test"), [3])


def test_windows_lazy_equals_in_memory_and_never_serve_states(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    arrays = _write(path)
    lazy = SequenceWindows(path, "train", window=3, in_memory=False)
    eager = SequenceWindows(path, "train", window=3, in_memory=True)
    assert len(lazy) == len(eager) == 3 * 3
    for i in range(len(lazy)):
        a, b = lazy[i], eager[i]
        assert isinstance(a, Window) and set(a._fields) == {"frames", "actions"}
        assert torch.equal(a.frames, b.frames) and torch.equal(a.actions, b.actions)
    seq, start = lazy.locate(4)
    np.testing.assert_array_equal(lazy[4].frames.numpy(), arrays["frames"][seq, start : start + 3])
    # pickles without its h5py handle, so DataLoader workers can use it
    clone = pickle.loads(pickle.dumps(lazy))
    assert torch.equal(clone[0].frames, lazy[0].frames)
    batch = next(iter(DataLoader(lazy, batch_size=4, num_workers=1)))
    assert batch.frames.shape == (4, 3, 8, 8) and batch.actions.shape == (4, 3, 2)


def test_windows_too_long_or_empty_split(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    _write(path)
    with pytest.raises(DataFormatError, match="fewer than the 6"):
        SequenceWindows(path, "train", window=6)
    with pytest.raises(ValueError, match="unknown split"):
        SequenceWindows(path, "training", window=2)


def test_load_states_needs_states(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    _write(path, states=False)
    assert not inspect_dataset(path).has_states
    with pytest.raises(DataFormatError, match="/states"):
        load_states(path, "train")


def test_rewards_are_optional_and_checked(tmp_path: Path) -> None:
    from piga.data.schema import load_rewards

    path = tmp_path / "d.h5"
    _write(path)
    assert not inspect_dataset(path).has_rewards
    with pytest.raises(DataFormatError, match="/rewards"):
        load_rewards(path, "train")
    with h5py.File(path, "a") as f:
        f["rewards"] = np.zeros((1, 2), np.float32)  # wrong shape
    with pytest.raises(DataFormatError, match="/rewards"):
        inspect_dataset(path)


def _corrupt(path: Path, how: str) -> None:
    with h5py.File(path, "a") as f:
        if how == "no-frames":
            del f["frames"]
        elif how == "float-frames":
            data = f["frames"][()]
            del f["frames"]
            f["frames"] = data.astype(np.float32)
        elif how == "short-actions":
            data = f["actions"][:, :-1]
            del f["actions"]
            f["actions"] = data
        elif how == "bad-split":
            f["split"][0] = 7
        elif how == "no-split":
            del f["split"]
        elif how == "no-dt":
            del f.attrs["dt"]
        elif how == "bad-states":
            del f["states"]
            f["states"] = np.zeros((2, 2, 2), np.float32)


@pytest.mark.parametrize(
    "how, message",
    [("no-frames", "/frames"), ("float-frames", "/frames"), ("short-actions", "/actions"), ("bad-split", "/split"),
     ("no-split", "/split"), ("no-dt", "'dt'"), ("bad-states", "/states")],
)
def test_validation_names_the_culprit(tmp_path: Path, how: str, message: str) -> None:
    path = tmp_path / "d.h5"
    _write(path)
    _corrupt(path, how)
    with pytest.raises(DataFormatError, match=message):
        inspect_dataset(path)


@pytest.mark.parametrize("cut", ["sequences", "frames"])
def test_states_left_whole_in_a_cut_file_is_named_as_a_shape(tmp_path: Path, cut: str) -> None:
    """A file with /frames, /actions and /split cut to fewer sequences (or /frames and /actions to fewer frames), and
    /states left whole, was refused as "/states must be real numbers [N=19, T=30, S], got float32 (60, 30, 2)"."""
    path = tmp_path / "d.h5"
    _write(path)
    with h5py.File(path, "a") as f:
        names = ("frames", "actions", "split") if cut == "sequences" else ("frames", "actions")
        for name in names:
            data = f[name][:4] if cut == "sequences" else f[name][:, :3]
            del f[name]
            f[name] = data
    with pytest.raises(DataFormatError) as refused:
        inspect_dataset(path)
    message = str(refused.value)
    shape = "(4, 5)" if cut == "sequences" else "(6, 3)"
    assert "/states has shape (6, 5, 3)" in message and shape in message and "real numbers" not in message, message
    assert "cut it the same way or drop it" in message and "\n" not in message


def test_not_hdf5_and_missing(tmp_path: Path) -> None:
    junk = tmp_path / "junk.h5"
    junk.write_text("not hdf5")
    with pytest.raises(DataFormatError, match="not a readable HDF5"):
        inspect_dataset(junk)
    with pytest.raises(FileNotFoundError):
        inspect_dataset(tmp_path / "absent.h5")


def test_writer_is_atomic_and_refuses_to_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    with pytest.raises(RuntimeError, match="boom"):
        with DatasetWriter(path, 2, 2, (4, 4), 1, None, {"system": "x", "dt": 1.0}) as w:
            w.write(0, np.zeros((1, 2, 4, 4), np.uint8), np.zeros((1, 2, 1), np.float32))
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []  # neither target nor partial file
    with pytest.raises(RuntimeError, match="unwritten"):
        with DatasetWriter(path, 2, 2, (4, 4), 1, None, {"system": "x", "dt": 1.0}) as w:
            w.set_split(np.zeros(2))
    assert list(tmp_path.iterdir()) == []
    _write(path)
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="--overwrite"):
        DatasetWriter(path, 2, 2, (4, 4), 1, None, {"system": "x", "dt": 1.0}).__enter__()
    assert path.read_bytes() == before


def test_user_recording_without_optional_attrs_is_readable(tmp_path: Path) -> None:
    """A file made by hand with plain h5py, the way a user would, reads the same."""
    path = tmp_path / "mine.h5"
    with h5py.File(path, "w") as f:
        f["frames"] = np.zeros((3, 4, 16, 16), np.uint8)
        for t in range(4):  # a square moving on black (all-blank frames, and frames in which nothing moves, are refused)
            f["frames"][:, t, 4:8, 4 + t : 8 + t] = 200
        f["actions"] = np.zeros((3, 4, 1), np.float32)
        f["split"] = np.array([0, 0, 2], np.int8)
        f.attrs["system"] = "pendulum"
        f.attrs["dt"] = 0.05
        f.attrs["params"] = json.dumps({})
    info = inspect_dataset(path)
    assert info.split_counts["train"] == 2 and not info.has_states
    assert len(SequenceWindows(path, "train", window=4)) == 2
    shutil.rmtree(tmp_path)
