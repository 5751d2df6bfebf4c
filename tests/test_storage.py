"""Storage: frame codecs, streaming a file larger than memory through a bounded cache, and the memory it sees."""

from __future__ import annotations

import json
import typing
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from piga.cli import train as cli
from piga.data.schema import DatasetWriter, FrameCodec, codec_options, inspect_dataset, read_sequences
from piga.data.windows import BlockShuffleSampler, SequenceReader, SequenceWindows, loads_whole
from piga.io import resources
from piga.training import train as training
from piga.training.train import TrainConfig, train
from tests.helpers import assert_one_line, run_in_process

# on the CPU, where a resumed run continues bit for bit (on a GPU, CUDA's atomic accumulations differ run to run)
TINY = TrainConfig(epochs=2, batch_size=4, warmup_fraction=1 / 6, curriculum_fraction=1 / 3, threads=1, device="cpu")


def _write(path: Path, codec: FrameCodec = "gzip-4", n: int = 6, t: int = 7) -> np.ndarray:
    frames = np.random.default_rng(0).integers(0, 256, (n, t, 8, 8), dtype=np.uint8)  # (N, T, H, W)
    with DatasetWriter(path, n, t, (8, 8), 1, None, {"system": "toy", "dt": 0.1}, compression=codec) as writer:
        writer.write(0, frames, np.zeros((n, t, 1), np.float32))
        writer.set_split(np.array([0, 0, 0, 0, 1, 2][:n], np.int8))
    return frames


@pytest.mark.parametrize("codec", typing.get_args(FrameCodec))
def test_every_codec_round_trips_one_sequence_per_chunk(tmp_path: Path, codec: FrameCodec) -> None:
    frames = _write(tmp_path / "d.h5", codec)
    with h5py.File(tmp_path / "d.h5") as f:
        assert f["frames"].chunks == (1, 7, 8, 8)
        assert f["frames"].compression == codec_options(codec).get("compression")
    np.testing.assert_array_equal(read_sequences(tmp_path / "d.h5", "train")[0], frames[:4])


def test_an_unknown_codec_is_refused_before_writing(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown frame codec 'gzip'"):
        DatasetWriter(tmp_path / "d.h5", 1, 2, (8, 8), 1, None, {"system": "toy", "dt": 0.1}, compression="gzip")  # type: ignore[arg-type]
    assert not list(tmp_path.iterdir())


def test_an_old_unchunked_file_reads_and_streams(tmp_path: Path) -> None:
    frames = _write(tmp_path / "new.h5")
    with h5py.File(tmp_path / "new.h5") as new, h5py.File(tmp_path / "old.h5", "w") as old:
        for key in new:
            old.create_dataset(key, data=new[key][()])  # contiguous, no filter
        old.attrs.update(new.attrs)
    with h5py.File(tmp_path / "old.h5") as f:
        assert f["frames"].chunks is None
    streamed = SequenceWindows(tmp_path / "old.h5", "train", window=3, in_memory=False)
    np.testing.assert_array_equal(streamed[streamed.locate(0)[0]].frames.numpy(), frames[0, :3])
    np.testing.assert_array_equal(read_sequences(tmp_path / "old.h5", "test")[0], frames[5:])


def test_the_reader_holds_at_most_its_capacity_least_recent_out(tmp_path: Path) -> None:
    frames = _write(tmp_path / "d.h5")
    reader = SequenceReader(tmp_path / "d.h5", np.arange(6), cache_bytes=2 * 7 * 64 + 10)  # two sequences
    assert reader.capacity == 2
    for position in (0, 1, 2, 0):
        np.testing.assert_array_equal(reader(position), frames[position])
    info = reader._cached.cache_info()  # type: ignore[union-attr]
    assert info.currsize == 2 and info.misses == 4 and info.hits == 0  # 0 was evicted by 2
    reader(0)
    assert reader._cached.cache_info().hits == 1  # type: ignore[union-attr]
    assert SequenceReader(tmp_path / "d.h5", np.arange(6), cache_bytes=1).capacity == 1


def test_block_order_visits_every_window_once_a_block_of_sequences_at_a_time(tmp_path: Path) -> None:
    _write(tmp_path / "d.h5", n=6)
    with h5py.File(tmp_path / "d.h5", "a") as f:
        f["split"][:] = 0
    windows = SequenceWindows(tmp_path / "d.h5", "train", window=3, in_memory=False, cache_bytes=2 * 7 * 64)
    assert windows.sequences_cached == 2
    order = list(BlockShuffleSampler(windows, 2, torch.Generator().manual_seed(1)))
    assert sorted(order) == list(range(len(windows))) == list(range(6 * 5))
    blocks = [{windows.locate(i)[0] for i in order[k : k + 10]} for k in range(0, 30, 10)]  # 2 sequences x 5 windows
    assert all(len(b) == 2 for b in blocks) and set().union(*blocks) == set(range(6))
    again = list(BlockShuffleSampler(windows, 2, torch.Generator().manual_seed(1)))
    assert again == order and list(BlockShuffleSampler(windows, 2, torch.Generator().manual_seed(2))) != order
    with pytest.raises(ValueError, match="block"):
        BlockShuffleSampler(windows, 0)


def test_loads_whole_below_two_gib_and_a_quarter_of_memory() -> None:
    assert loads_whole(100, None) and loads_whole(100, 401) and not loads_whole(100, 400)
    assert not loads_whole(3 * 2**30, None)


@pytest.mark.parametrize("version", [1, 2])
def test_available_memory_counts_a_cgroup_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, version: int) -> None:
    child, parent = tmp_path / "parent" / "child", tmp_path / "parent"
    child.mkdir(parents=True)
    names = (("memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file") if version == 1
             else ("memory.max", "memory.current", "inactive_file"))
    (child / names[0]).write_text(str(1000 * 2**20) if version == 1 else "max\n")  # the child has no limit of its own
    (child / names[1]).write_text("0")
    (parent / names[0]).write_text(str(1000 * 2**20))
    (parent / names[1]).write_text(str(700 * 2**20))
    (parent / "memory.stat").write_text(f"cache 1\n{names[2]} {200 * 2**20}\n")
    monkeypatch.setattr(resources, "_cgroup_folders", lambda: [child, parent])
    assert resources._cgroup_available() == 500 * 2**20  # 1000 - 700 + 200 reclaimable
    assert resources.available_memory() == min(500 * 2**20, resources._machine_available())
    monkeypatch.setattr(resources, "_cgroup_folders", lambda: [])
    assert resources._cgroup_available() is None


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from piga.data.collect import CollectConfig, collect

    path = tmp_path_factory.mktemp("storage") / "small.h5"
    collect(CollectConfig(sequences=10, steps=15, seed=7, workers=1, split=(8, 1, 1)), path, progress=False, command="t")
    return path


def test_auto_streams_when_memory_is_short_and_caps_the_cache(data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    info = inspect_dataset(data)
    monkeypatch.setattr(resources, "available_memory", lambda: 400 * 2**20)
    assert training.resolve_loading(TrainConfig(), info) == replace(TrainConfig(), data_loading="memory", stream_cache_mb=100)
    monkeypatch.setattr(resources, "available_memory", lambda: 2 * 8 * 15 * 64 * 64)  # twice the train split's frames
    assert training.resolve_loading(TrainConfig(), info).data_loading == "stream"
    assert training.resolve_loading(TrainConfig(data_loading="memory"), info).data_loading == "memory"  # asked for


def test_a_streamed_run_resumes_exactly(data: Path, tmp_path: Path) -> None:
    cfg = replace(TINY, data_loading="stream", stream_cache_mb=1)
    straight, _ = train(data, tmp_path / "a", cfg, progress=False)

    def stop_after_first(state, model) -> None:  # noqa: ANN001
        if state.epoch == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(data, tmp_path / "b", cfg, progress=False, on_epoch=stop_after_first)
    saved = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=False)["train_config"]
    assert saved["data_loading"] == "stream" and saved["stream_cache_mb"] == 1
    resumed, state = train(data, tmp_path / "b", TrainConfig.from_dict(saved), resume=True, progress=False)
    assert state.epoch == 2
    for (name, a), (_, b) in zip(straight.state_dict().items(), resumed.state_dict().items()):
        assert torch.equal(a, b), name


def test_the_command_records_its_reading_and_resume_keeps_it(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "run")
    code, stdout, err = run_in_process("piga-train-model", cli.main, str(data), "--out", out, "--epochs", "1", "--batch-size", "8",
                                       "--quiet", "--threads", "1", "--data-loading", "stream", "--stream-cache-mb", "3", capsys=capsys)
    assert code in (0, 3), err
    assert "streamed from" in stdout and "3 MiB cache" in stdout
    train_record = json.loads((tmp_path / "run" / "config.json").read_text())["train"]
    assert (train_record["data_loading"], train_record["stream_cache_mb"]) == ("stream", 3)
    code, _, err = run_in_process("piga-train-model", cli.main, str(data), "--out", out, "--resume", "--epochs", "2",
                                  "--data-loading", "memory", capsys=capsys)
    assert_one_line(code, err, "drop --data-loading")


def test_planet_batches_are_the_same_streamed(tiny_data: Path) -> None:
    from agents.planet.train import _Sequences

    loaded, streamed = _Sequences(tiny_data, "train"), _Sequences(tiny_data, "train", stream=True)
    assert streamed.frames is None and len(streamed) == len(loaded)
    for a, b in zip(loaded.batch(np.random.default_rng(0), 5, 3, repeat=2), streamed.batch(np.random.default_rng(0), 5, 3, repeat=2)):
        assert torch.equal(a, b)


def test_evaluation_in_batches_matches_one_batch(tiny_data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from piga.evaluation import evaluate as evaluation
    from piga.training.train import model_config_for
    from piga.world.model import PhysicsModel

    torch.manual_seed(0)
    model = PhysicsModel(model_config_for(inspect_dataset(tiny_data), None))
    config = evaluation.EvalConfig(split="train")
    batched = evaluation.evaluate(model, tiny_data, config)
    monkeypatch.setattr(evaluation, "EVAL_BATCH", 1000)
    whole = evaluation.evaluate(model, tiny_data, config)
    np.testing.assert_allclose(batched["frame_mse_per_step"], whole["frame_mse_per_step"], rtol=1e-6)
    np.testing.assert_allclose(batched["frame_ssim_per_step"], whole["frame_ssim_per_step"], rtol=1e-9)
    numbers = {k: v for k, v in whole["angle"].items() if isinstance(v, float)}
    assert {k: batched["angle"][k] for k in numbers} == pytest.approx(numbers, rel=1e-6, abs=1e-9)
