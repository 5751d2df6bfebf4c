"""Training: a tiny real run moves g toward the truth without states; resume; NaN; the CLI."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from piga.collect import CollectConfig, collect
from piga.runs import load_model
from piga.train import TrainConfig, TrainingDiverged, train
from tests.test_cli import assert_one_line_error, run

TINY = TrainConfig(epochs=8, batch_size=16, warmup_steps=40, curriculum_steps=60, lr_physics=5e-2, threads=2)


@pytest.fixture(scope="module")
def stateless_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """40 sequences x 24 frames whose /states were deleted: training cannot read them."""
    path = tmp_path_factory.mktemp("train") / "nostates.h5"
    collect(CollectConfig(sequences=40, steps=24, seed=5, workers=1, split=(36, 2, 2)), path, progress=False, command="t")
    with h5py.File(path, "a") as f:
        del f["states"]
    return path


def test_tiny_training_moves_g_and_a_toward_truth(stateless_data: Path, tmp_path: Path) -> None:
    model, state = train(stateless_data, tmp_path / "run", TINY, {"rec_frames": "input"}, progress=False)
    p = model.physical_parameters()
    assert state.history[0]["g"] < 10  # it really started from g = 1
    assert abs(p["g"] - 10) < 0.5 * abs(1 - 10), p  # moved more than half-way from 1 to 10
    assert abs(p["a"] - 1) < 0.5 * abs(0.3 - 1), p
    assert (tmp_path / "run" / "checkpoint.pt").exists()
    assert any((tmp_path / "run" / "tensorboard").iterdir())


def test_resume_continues_exactly(stateless_data: Path, tmp_path: Path) -> None:
    cfg = replace(TINY, epochs=3)
    straight, _ = train(stateless_data, tmp_path / "a", cfg, {"rec_frames": "input"}, progress=False)

    def stop_after_first(state, model) -> None:  # noqa: ANN001
        if state.epoch == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(stateless_data, tmp_path / "b", cfg, {"rec_frames": "input"}, progress=False, on_epoch=stop_after_first)
    resumed, state = train(stateless_data, tmp_path / "b", cfg, resume=True, progress=False)
    assert state.epoch == 3
    for (name, a), (_, b) in zip(straight.state_dict().items(), resumed.state_dict().items()):
        assert torch.equal(a, b), name


def test_nan_stops_and_names_last_checkpoint(stateless_data: Path, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    train(stateless_data, run_dir, replace(TINY, epochs=1), {"rec_frames": "input"}, progress=False)
    bad = tmp_path / "nan.h5"
    shutil.copy(stateless_data, bad)
    with h5py.File(bad, "a") as f:
        f["actions"][...] = np.nan
    before = (run_dir / "checkpoint.pt").read_bytes()
    with pytest.raises(TrainingDiverged, match=str(run_dir / "checkpoint.pt")):
        train(bad, run_dir, replace(TINY, epochs=3), resume=True, progress=False)
    assert (run_dir / "checkpoint.pt").read_bytes() == before  # the good checkpoint survives
    load_model(run_dir)


def test_cli_trains_and_reports(stateless_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = run("piga-train-model", str(stateless_data), "--out", str(out), "--epochs", "1", "--warmup-steps", "5",
                 "--quiet", "--threads", "2")
    assert result.returncode == 0, result.stderr
    assert "learned: g=" in result.stdout and "epoch 1:" in result.stdout
    for name in ("checkpoint.pt", "metrics.json", "config.json", "rollout.png", "templates.png", "curves.png"):
        assert (out / name).exists(), name
    import json

    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["parameter_errors"]) == {"g", "a"} and "angle" not in metrics  # no /states, no angle error
    assert len(metrics["frame_ssim_per_step"]) == 24 - 4
    # an existing run is not replaced without --overwrite or --resume
    assert_one_line_error(run("piga-train-model", str(stateless_data), "--out", str(out)), "--overwrite")
    resumed = run("piga-train-model", str(stateless_data), "--out", str(out), "--resume", "--epochs", "2", "--quiet")
    assert resumed.returncode == 0, resumed.stderr
    assert "epoch 2:" in resumed.stdout and "epoch 1:" not in resumed.stdout


def test_cli_bad_input(stateless_data: Path, tmp_path: Path) -> None:
    out = str(tmp_path / "run")
    assert_one_line_error(run("piga-train-model", str(tmp_path / "absent.h5"), "--out", out), "no such file")
    junk = tmp_path / "junk.h5"
    junk.write_text("junk")
    assert_one_line_error(run("piga-train-model", str(junk), "--out", out), "HDF5")
    wrong = tmp_path / "wrong.h5"
    with h5py.File(wrong, "w") as f:
        f["frames"] = np.zeros((2, 20, 64, 64), np.uint8)
    assert_one_line_error(run("piga-train-model", str(wrong), "--out", out), "/actions")
    short = tmp_path / "short.h5"
    collect(CollectConfig(sequences=3, steps=8, workers=1, split=(1, 1, 1)), short, progress=False, command="t")
    assert_one_line_error(run("piga-train-model", str(short), "--out", out), "14")
    assert_one_line_error(run("piga-train-model", str(stateless_data), "--out", out, "--preset", "slow"), "--preset")
    assert_one_line_error(run("piga-train-model", str(stateless_data), "--out", out, "--resume"), "does not exist")
    assert_one_line_error(run("piga-train-model", str(stateless_data), "--out", out, "--epochs", "0"), "--epochs")
    assert not (tmp_path / "run" / "checkpoint.pt").exists()
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "checkpoint.pt").write_bytes(b"not a checkpoint")
    assert_one_line_error(run("piga-train-model", str(stateless_data), "--out", str(broken), "--resume"), "checkpoint")


def test_cli_nan_names_checkpoint(stateless_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert run("piga-train-model", str(stateless_data), "--out", str(out), "--epochs", "1", "--warmup-steps", "0",
               "--quiet").returncode == 0
    bad = tmp_path / "nan.h5"
    shutil.copy(stateless_data, bad)
    with h5py.File(bad, "a") as f:
        f["actions"][...] = np.nan
    result = run("piga-train-model", str(bad), "--out", str(out), "--resume", "--epochs", "2", "--quiet")
    assert_one_line_error(result, "diverged", str(out / "checkpoint.pt"))
