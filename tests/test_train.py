"""Training: a tiny real run moves g toward the truth without states; resume; NaN; the CLI."""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import torch

from piga.cli.common import NOT_CONVERGED
from piga.cli import train as cli
from piga.data.collect import CollectConfig, collect
from piga.world.model import PhysicsModel
from piga.io.runs import load_model
from piga.training.train import TrainConfig, TrainingDiverged, train
from tests.helpers import assert_one_line, assert_one_line_error, run, run_in_process, stateless_pendulum

PROG = "piga-train-model"
# on the CPU: the resume tests assert bit-for-bit continuation, which CUDA's atomic accumulations do not give
TINY = TrainConfig(epochs=8, batch_size=16, warmup_fraction=0.2, curriculum_fraction=0.3, lr_physics=5e-2, threads=1,
                   device="cpu")
#: CLI options for a run of seconds on ``small_data`` (2 steps per epoch).
SMALL = ("--epochs", "1", "--batch-size", "8", "--warmup-fraction", "0.5", "--quiet", "--threads", "1")

#: Exit statuses of a run that trained and saved its model: a tiny run is too short to be judged converged (3).
FINISHED = (0, NOT_CONVERGED)


@pytest.fixture(scope="module")
def small_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 sequences x 15 frames, split 8/1/1: 16 training windows of L + T_pred = 14 frames.

    Its /states were deleted: training cannot read them.
    """
    return stateless_pendulum(tmp_path_factory.mktemp("small") / "small.h5", 10, 15, seed=7, split=(8, 1, 1))


@pytest.fixture(scope="module")
def stateless_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """40 sequences x 24 frames whose /states were deleted: training cannot read them."""
    return stateless_pendulum(tmp_path_factory.mktemp("train") / "nostates.h5", 40, 24, seed=5, split=(36, 2, 2))


@pytest.mark.slow  # the learning run: ~200 steps
def test_tiny_training_moves_g_and_a_toward_truth(stateless_data: Path, tmp_path: Path) -> None:
    model, state = train(stateless_data, tmp_path / "run", TINY, progress=False)
    p = model.physical_parameters()
    assert state.history[0]["g"] < 10  # it really started from g = 1
    assert abs(p["g"] - 10) < 0.5 * abs(1 - 10), p  # moved more than half-way from 1 to 10
    assert abs(p["a"] - 1) < 0.5 * abs(0.3 - 1), p
    assert (tmp_path / "run" / "checkpoint.pt").exists()
    assert any((tmp_path / "run" / "tensorboard").iterdir())


def test_resume_continues_exactly(small_data: Path, tmp_path: Path) -> None:
    cfg = replace(TINY, epochs=3, batch_size=4, warmup_fraction=1 / 6, curriculum_fraction=1 / 3)  # 4 steps per epoch
    straight, _ = train(small_data, tmp_path / "a", cfg, progress=False)

    def stop_after_first(state, model) -> None:  # noqa: ANN001
        if state.epoch == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(small_data, tmp_path / "b", cfg, progress=False, on_epoch=stop_after_first)
    resumed, state = train(small_data, tmp_path / "b", cfg, resume=True, progress=False)
    assert state.epoch == 3
    for (name, a), (_, b) in zip(straight.state_dict().items(), resumed.state_dict().items()):
        assert torch.equal(a, b), name


def _poison(monkeypatch: pytest.MonkeyPatch, after_calls: int, error: type[BaseException] | None = None) -> None:
    """From the ``after_calls``-th forward pass on, the loss is NaN (or ``error`` is raised)."""
    forward = PhysicsModel.forward
    calls = []

    def patched(self, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        calls.append(1)
        out = forward(self, *args, **kwargs)
        if len(calls) >= after_calls and self.training:
            if error is not None:
                raise error
            return out._replace(loss=out.loss * float("nan"), loss_rec=out.loss_rec * float("nan"))
        return out

    monkeypatch.setattr(PhysicsModel, "forward", patched)


def test_nan_stops_and_names_last_checkpoint(small_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run_dir = tmp_path / "run"
    cfg = replace(TINY, epochs=1, batch_size=8)
    train(small_data, run_dir, cfg, progress=False)
    before = (run_dir / "checkpoint.pt").read_bytes()
    _poison(monkeypatch, after_calls=2)
    with pytest.raises(TrainingDiverged, match=str(run_dir / "checkpoint.pt")):
        train(small_data, run_dir, replace(cfg, epochs=3), resume=True, progress=False)
    assert (run_dir / "checkpoint.pt").read_bytes() == before  # the good checkpoint survives
    load_model(run_dir)
    with pytest.raises(TrainingDiverged, match="no checkpoint was written yet"):
        train(small_data, tmp_path / "fresh", cfg, progress=False)
    assert not (tmp_path / "fresh").exists()


def test_cli_trains_and_reports(small_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from piga.io.device import resolve_device

    out = tmp_path / "run"
    result = run("piga-train-model", str(small_data), "--out", str(out), *SMALL, "--device", "auto")
    assert result.returncode in FINISHED, result.stderr
    # --device auto says nothing on stderr, with or without a GPU: at most the tiny run's convergence warning
    said = [line for line in result.stderr.splitlines() if "warning: not converged" not in line]
    assert not said and "cuda" not in result.stderr.lower(), result.stderr
    assert "learned: g=" in result.stdout and "epoch 1:" in result.stdout
    for name in ("checkpoint.pt", "metrics.json", "config.json", "rollout.png", "templates.png", "curves.png"):
        assert (out / name).exists(), name
    import json

    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["parameter_errors"]) == {"g", "a"} and "angle" not in metrics  # no /states, no angle error
    assert len(metrics["frame_ssim_per_step"]) == 15 - 4
    assert metrics["training"]["device"] == str(resolve_device("auto"))
    from piga.io.checkpoint import RunKind, read_checkpoint

    data = read_checkpoint(out, RunKind.PIGA)["data"]  # found from elsewhere through the folder it is relative to
    assert data["path"] == str(small_data) and data["folder"] == os.getcwd()
    # an existing run is not replaced without --overwrite or --resume
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), capsys=capsys)
    assert_one_line(code, err, "--overwrite")
    code, stdout, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "2",
                                       "--quiet", "--device", "cpu", "--threads", "2",
                                       capsys=capsys)  # the device and the threads are not the recipe's
    assert code in FINISHED, err
    assert "epoch 2:" in stdout and "epoch 1:" not in stdout
    assert json.loads((out / "metrics.json").read_text())["training"]["device"] == "cpu"
    record = json.loads((out / "config.json").read_text())
    assert record["train"]["threads"] == 2  # it was 1; --threads was ignored
    from piga.io.pool import git_commit  # the code's commit, where it started and where it continued

    assert record["commit"] == git_commit() and record["resumed_commits"] == [git_commit()]


def test_cli_bad_input(small_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "run")
    assert_one_line_error(run(PROG, str(tmp_path / "absent.h5"), "--out", out), "no such file")  # once as a script

    def refused(*argv: str) -> str:
        code, _, err = run_in_process(PROG, cli.main, *argv, capsys=capsys)
        return assert_one_line(code, err)

    junk = tmp_path / "junk.h5"
    junk.write_text("junk")
    assert "HDF5" in refused(str(junk), "--out", out)
    wrong = tmp_path / "wrong.h5"
    with h5py.File(wrong, "w") as f:
        f["frames"] = np.zeros((2, 20, 64, 64), np.uint8)
    assert "/actions" in refused(str(wrong), "--out", out)
    short = tmp_path / "short.h5"
    collect(CollectConfig(sequences=3, steps=7, workers=1, split=(1, 1, 1)), short, progress=False, command="t")
    assert "L + T_pred = 4 + 4 = 8" in refused(str(short), "--out", out)  # T_pred shortened to its floor, still too long
    assert "--preset" in refused(str(small_data), "--out", out, "--preset", "slow")
    assert "does not exist" in refused(str(small_data), "--out", out, "--resume")
    assert "--epochs" in refused(str(small_data), "--out", out, "--epochs", "0")
    assert "is a file" in refused(str(small_data), "--out", str(junk))
    assert not (tmp_path / "run").exists()
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "checkpoint.pt").write_bytes(b"not a checkpoint")
    assert "checkpoint" in refused(str(small_data), "--out", str(broken), "--resume")
    leftovers = tmp_path / "leftovers"  # an earlier run that wrote no checkpoint
    (leftovers / "tensorboard").mkdir(parents=True)
    (leftovers / "config.json").write_text("{}")
    line = refused(str(small_data), "--out", str(leftovers))
    assert "no checkpoint" in line and "--overwrite" in line and "--resume" not in line


def test_cli_nan_names_checkpoint(small_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), *SMALL, capsys=capsys)
    assert code in FINISHED, err
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--seed-retries", "3",
                                  capsys=capsys)
    assert_one_line(code, err, "drop --seed-retries")  # retries start new runs; a resumed run is the user's
    _poison(monkeypatch, after_calls=1)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "2",
                                  "--quiet", capsys=capsys)
    assert_one_line(code, err, "diverged", str(out / "checkpoint.pt"))


@pytest.mark.parametrize("value, needle", [(np.nan, "NaN or infinite"), (np.inf, "NaN or infinite"), (1e30, "beyond")])
def test_cli_refuses_unusable_actions_up_front(small_data: Path, tmp_path: Path, value: float, needle: str,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.h5"
    shutil.copy(small_data, bad)
    with h5py.File(bad, "a") as f:
        f["actions"][1, 3, 0] = value
    out = tmp_path / "r"
    code, _, err = run_in_process(PROG, cli.main, str(bad), "--out", str(out), "--warmup-fraction", "0", "--epochs", "1",
                                  capsys=capsys)
    assert_one_line(code, err, needle, "sequence 1, step 3")
    assert not out.exists()


@pytest.mark.slow
def test_cli_curriculum_fraction_plans_the_horizon_and_a_sum_of_one_is_refused(
        small_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"  # 16 windows of batch 8: 2 steps an epoch, 10 epochs
    code, stdout, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--batch-size", "8",
                                       "--epochs", "10", "--warmup-fraction", "0", "--curriculum-fraction", "0",
                                       "--quiet", "--threads", "1", capsys=capsys)
    assert code in FINISHED, err
    config = json.loads((out / "config.json").read_text())
    assert config["train"]["curriculum_fraction"] == 0 and config["plan"]["curriculum_steps"] == 0
    assert "no warm-up, no curriculum (T_pred 10 from the first step)" in stdout
    refused = tmp_path / "refused"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(refused), "--warmup-fraction", "0.5",
                                  "--curriculum-fraction", "0.5", "--quiet", capsys=capsys)
    assert_one_line(code, err, "--warmup-fraction + --curriculum-fraction")
    assert not refused.exists()


def test_cli_refuses_a_run_without_a_single_batch(small_data: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--batch-size", "17", capsys=capsys)
    assert_one_line(code, err, "16 training windows", "fewer than one batch of 17")
    assert not out.exists()


def test_cli_warns_when_there_is_no_test_split(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "notest.h5"
    collect(CollectConfig(sequences=3, steps=14, seed=1, workers=1, split=(3, 0, 0)), data, progress=False, command="t")
    code, out, err = run_in_process(PROG, cli.main, str(data), "--out", str(tmp_path / "r"), "--batch-size", "3",
                                    "--epochs", "1", "--warmup-fraction", "0", "--quiet", capsys=capsys)
    assert code in FINISHED, err
    # on stdout: a run that then fails its checks says so in one line on stderr
    assert "no test sequences, so metrics.json and the figures measure the train split" in out
    assert len(err.splitlines()) <= 1, err  # at most the verdict's warning (exit 3)
    assert "SSIM (train split)" in out
    # one epoch: the readout, which has no parameters, reads the angle all the same, and the line says so
    assert "encoder angle error" in out and "(the centroid readout's, as small before any training" in out, out
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["split"] == "train"


def test_short_sequences_shorten_the_rollout_to_what_they_hold(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A file of 10-frame sequences is shorter than the recipe's window L + T_pred = 4 + 10: the physics
    predicts 6 frames per window instead, the plan says so, and the saved model keeps it."""
    from piga.data.schema import inspect_dataset
    from piga.training.train import MIN_PRED_FRAMES, model_config_for

    data = tmp_path / "short.h5"
    collect(CollectConfig(sequences=6, steps=10, seed=1, workers=1, split=(4, 1, 1)), data, progress=False, command="t")
    fitted = model_config_for(inspect_dataset(data))
    assert (fitted.input_frames, fitted.pred_frames) == (4, 6) and MIN_PRED_FRAMES <= 6
    code, out, err = run_in_process(PROG, cli.main, str(data), "--out", str(tmp_path / "r"), "--batch-size", "4",
                                    "--epochs", "1", "--warmup-fraction", "0", "--quiet", capsys=capsys)
    assert code in FINISHED, err
    assert "T_pred 6 from the first step" in out and "predicts 6 frames per window, not the recipe's 10" in out
    assert "predicts" not in err  # a note, not a warning: stderr keeps at most the one line of what went wrong
    assert load_model(tmp_path / "r")[0].config.pred_frames == 6


def test_cli_paper_preset_runs(small_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "paper"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--preset", "paper", "--epochs", "1",
                                  "--batch-size", "8", "--quiet", capsys=capsys)
    assert code in FINISHED, err
    config = json.loads((out / "config.json").read_text())
    assert config["train"]["optimizer"] == "rmsprop" and config["train"]["epochs"] == 1
    assert config["model"]["substeps"] == 5 and config["model"]["readout"] == "regress"
    _, ckpt = load_model(out)
    assert ckpt["state"]["step"] == 1  # one step of 8 windows: the paper's epoch takes one window per sequence
    assert load_model(out)[0].system.offset.requires_grad  # the paper preset learns the angle offset


@pytest.mark.slow
def test_cli_interrupted_first_epoch_writes_nothing_and_rerun_works(
        small_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"
    with monkeypatch.context() as m:
        _poison(m, after_calls=2, error=KeyboardInterrupt)
        code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), *SMALL, capsys=capsys)
    assert code == 130 and err.strip() == f"{PROG}: interrupted; nothing was written"
    assert not out.exists()
    with monkeypatch.context() as m:  # interrupted in epoch 2: epoch 1's checkpoint and the record stay
        _poison(m, after_calls=3, error=KeyboardInterrupt)
        code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), *SMALL[2:], "--epochs", "3",
                                      capsys=capsys)  # SMALL without its --epochs 1
    assert code == 130 and "holds epoch 1; continue with --resume" in err, err
    first = json.loads((out / "config.json").read_text())
    assert first["command"].startswith(PROG) and "--epochs 3" in first["command"] and "resumed" not in first
    code, stdout, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "4",
                                       "--quiet", capsys=capsys)
    assert code in FINISHED, err
    assert "epoch 2:" in stdout and "epoch 4:" in stdout
    record = json.loads((out / "config.json").read_text())
    assert record["command"] == first["command"]  # the original command is kept
    assert len(record["resumed"]) == 1 and "--resume --epochs 4" in record["resumed"][0]
    assert record["train"]["epochs"] == 4
    # fewer epochs than planned would quietly re-evaluate the run as it is (the baselines refuse it too)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "3",
                                  "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume --epochs 3", "planned 4 epochs", "never lower")
    assert json.loads((out / "config.json").read_text()) == record
    # a resume with no step left writes the report again, and is recorded as every resume is
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "4",
                                  "--quiet", capsys=capsys)
    assert code in FINISHED, err
    assert len(json.loads((out / "config.json").read_text())["resumed"]) == 2


@pytest.mark.slow
def test_resume_with_more_epochs_replans_the_cosine(small_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """As documented: from the resumed step on, the learning rates are those of a straight run of the new length."""
    import piga.training.train as training

    seen: list[tuple[int, float]] = []
    factor = training._lr_factor

    def recording(step: int, epoch: int, plan: training.TrainPlan, config: TrainConfig) -> float:
        seen.append((step, factor(step, epoch, plan, config)))
        return seen[-1][1]

    monkeypatch.setattr(training, "_lr_factor", recording)
    cfg = replace(TINY, batch_size=4, warmup_fraction=0.1, curriculum_fraction=0.1)  # 4 steps per epoch
    straight, _ = train(small_data, tmp_path / "a", replace(cfg, epochs=3), progress=False)
    straight_rates, seen[:] = dict(seen), []
    train(small_data, tmp_path / "b", replace(cfg, epochs=2), progress=False)
    short_rates, seen[:] = dict(seen), []
    resumed, state = train(small_data, tmp_path / "b", replace(cfg, epochs=3), resume=True, progress=False)
    assert state.epoch == 3 and sorted(seen) == [(s, straight_rates[s]) for s in range(8, 12)]
    assert short_rates[7] < straight_rates[8] > straight_rates[11]  # the rate rose again, then decays to the end
    assert any(short_rates[s] != straight_rates[s] for s in range(8))  # the first epochs had the 2-epoch schedule
    assert straight.physical_parameters() != resumed.physical_parameters()  # close, not identical


# --- recipes sized from the data, and the convergence check -----------------------------------


def test_the_plan_is_sized_from_the_file() -> None:
    from piga.training.train import plan_training

    fast = TrainConfig()
    big, small = plan_training(fast, 10_800), plan_training(fast, 336)  # the default file; 48 sequences x 7 windows
    assert (big.epochs, big.warmup_steps, big.curriculum_steps) == (6, 81, 222)  # 2022 steps
    assert big.epochs == -(-fast.budget_steps // 337) and small.epochs == -(-fast.budget_steps // 10)  # whole epochs
    for plan in (big, small):
        assert plan.total_steps >= fast.budget_steps
        assert plan.warmup_steps == round(fast.warmup_fraction * plan.total_steps)  # fractions, not absolute steps
        assert plan.warmup_steps + plan.curriculum_steps < plan.total_steps / 2  # the physics trains most of the run
    assert small.checkpoint_every > 1 and big.checkpoint_every == 1
    short = plan_training(replace(fast, epochs=1), 64)  # 2 steps: still one step of physics at the full horizon
    assert short.total_steps == 2 and short.warmup_steps + short.curriculum_steps < 2
    with pytest.raises(ValueError, match="fewer than one batch"):
        plan_training(fast, 31)


@pytest.mark.parametrize("field, value", [("lr_physics", 1e30), ("lr", float("nan")), ("warmup_fraction", 1.5),
                                          ("budget_steps", -1), ("optimizer", "sgd")])
def test_train_config_names_a_bad_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"TrainConfig.{field}"):
        TrainConfig(**{field: value})


@pytest.mark.slow  # a 60-step run (8 s alone); by default
# test_the_plan_is_sized_from_the_file checks the warm-up planned from the data
def test_a_file_that_ended_inside_the_old_warm_up_now_trains_its_physics(small_data: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """16 windows of batch 8: 2 steps an epoch. Under the old absolute 200-step warm-up, 16 epochs (32 steps)
    never ran the physics; sized from the data, the same command plans a run whose physics trains."""
    out = tmp_path / "r"
    code, stdout, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--batch-size", "8",
                                       "--budget-steps", "60", "--quiet", "--threads", "1", capsys=capsys)
    metrics = json.loads((out / "metrics.json").read_text())
    assert code == {"converged": 0, "unsettled": NOT_CONVERGED, "untrained": 1}[metrics["convergence"]["outcome"]], err
    assert "plan: 60 steps = 30 epochs x 2 steps" in stdout  # printed in one line at the start
    metrics = json.loads((out / "metrics.json").read_text())
    conv = metrics["convergence"]
    assert conv["physics_steps"] > 40 and conv["steps"] == 60
    assert all(abs(c["change_from_start"]) > 0.01 for c in conv["parameters"].values())  # g and a left 1 and 0.3
    assert metrics["converged"] == (conv["outcome"] == "converged")
    assert json.loads((out / "config.json").read_text())["plan"]["warmup_steps"] == 2


def test_a_run_stopped_before_its_physics_trained_exits_non_zero(small_data: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"  # 20 planned steps, the first 10 the warm-up; the budget stops it after the first epoch (2 steps)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--batch-size", "8", "--epochs", "10",
                                  "--warmup-fraction", "0.5", "--max-minutes", "1e-9", "--quiet", "--threads", "1",
                                  capsys=capsys)
    line = assert_one_line(code, err, "physics never trained", "warm-up", "--resume and a larger --max-minutes")
    assert code == 1, line
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["converged"] is False and metrics["convergence"]["outcome"] == "untrained"


def test_a_run_stopped_after_its_physics_trained_exits_3_with_a_warning(small_data: Path, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Trained and saved, but stopped before its plan ended: not converged, so not exit 0 (a script would take
    it for an identification), and not 1 (its model is there to --resume)."""
    out = tmp_path / "r"  # 40 planned steps, 2 of warm-up; the budget stops it after the first epoch (4 steps)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--batch-size", "4", "--epochs", "10",
                                  "--warmup-fraction", "0.05", "--max-minutes", "1e-9", "--quiet", "--threads", "1",
                                  capsys=capsys)
    assert code == NOT_CONVERGED == 3, err
    assert err.count("\n") == 1 and "warning: not converged" in err and "--resume" in err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["converged"] is False and metrics["convergence"]["outcome"] == "unsettled"
    assert (out / "checkpoint.pt").exists()


def test_a_command_training_through_this_one_says_its_own_way_to_train_longer(small_data: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """piga-demo's training that did not converge told its user to raise --max-minutes or --budget-steps, which
    piga-demo does not take: the command that trains through piga-train-model says its own way instead."""
    out = tmp_path / "r"

    def longer(planned: int, steps: int, need: str, epochs: int) -> str:
        return f"run the demo with --epochs (it took {steps} of {planned} in {epochs} epochs)"

    code, _, err = run_in_process("piga-demo", lambda argv: cli.main(argv, prog="piga-demo", longer=longer),
                                  str(small_data), "--out", str(out), "--batch-size", "4", "--epochs", "10",
                                  "--warmup-fraction", "0.05", "--max-minutes", "1e-9", "--quiet", "--threads", "1",
                                  capsys=capsys)
    assert code == NOT_CONVERGED, err
    assert err.count("\n") == 1 and err.startswith("piga-demo: warning: not converged: "), err
    assert "run the demo with --epochs (it took 4 of 40 in 10 epochs)" in err and "--max-minutes" not in err, err
    assert "(options of piga-train-model" not in err, err  # every option it names is the demo's


def test_another_commands_reason_names_whose_options_it_leaves() -> None:
    from piga.training.convergence import length_fix

    verdict = {"planned_steps": 40, "steps": 40,
               "reason": "g never left its initial value in 30 physics steps; raise --lr-physics or " + length_fix(40, 40)}
    owner = " (options of piga-train-model d.h5 --out r)"
    assert cli._reason_for(verdict, cli.PROG, None, owner, 8) == (verdict["reason"], "")
    reason, whose = cli._reason_for(verdict, "piga-demo", lambda planned, steps, need, epochs: f"--epochs past {steps}",
                                    owner, 8)
    assert reason.endswith("raise --lr-physics or --epochs past 40") and whose == owner  # --lr-physics is not its own
    verdict["reason"] = "too short to judge; " + length_fix(40, 40)
    assert cli._reason_for(verdict, "piga-demo", lambda planned, steps, need, epochs: "--epochs", owner, 8) == (
        "too short to judge; --epochs", "")


def test_converged_is_false_when_the_parameters_never_moved(small_data: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--batch-size", "8", "--epochs", "5",
                                  "--lr-physics", "1e-9", "--quiet", "--threads", "1", capsys=capsys)
    assert_one_line(code, err, "never left", "--lr-physics")
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["converged"] is False
    assert set(metrics["profile"]) == {"g", "a"} and metrics["frame_mse_hold"] > 0  # what the check read
    from piga.io.runs import convergence_warning

    assert "did not converge" in (convergence_warning(out) or "")  # what piga-control and piga-diagnose print


def test_the_convergence_check_on_made_up_trajectories() -> None:
    from types import SimpleNamespace

    from piga.training.convergence import check_convergence
    from piga.training.train import TrainPlan

    plan = asdict(TrainPlan(windows=3200, steps_per_epoch=100, epochs=10, warmup_steps=40, curriculum_steps=100,
                            average_steps=60))
    steps = np.arange(10, 1001, 10.0)

    def state(g: np.ndarray, a: np.ndarray, step: int = 1000) -> SimpleNamespace:
        trace = [[s, gv, av] for s, gv, av in zip(steps, g, a) if s <= step]
        return SimpleNamespace(step=step, start={"g": 1.0, "a": 0.3}, trace=trace, plan=plan,
                               history=[{"g": trace[-1][1], "a": trace[-1][2]}])

    settle = 1 - np.exp(-steps / 150)
    good = check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle))
    assert good.outcome == "converged", good.reason
    assert check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle), blank=(0.001, 0.0037)).outcome == "converged"
    # settled parameters whose model predicts worse than drawing the background: a 45-step run passed so, g 88% off
    blind = check_convergence(state(1 + 0.18 * settle, 0.3 - 0.01 * settle), blank=(0.0103, 0.0037))
    assert blind.outcome == "untrained" and "not clearly better than drawing the background alone" in blind.reason
    assert "the bar is 0.9x it" in blind.reason
    # frames that hardly differ from the background (a pendulum that barely moves): the data's fault, not the training's
    faint = check_convergence(state(1 + 0.18 * settle, 0.3 - 0.01 * settle), blank=(0.00412, 2.8e-6))
    assert faint.outcome == "untrained" and "check the data, not the training" in faint.reason
    # settled parameters whose model beats the background but hardly a pendulum held still: 20 sequences of 10 frames
    # settled so with g 67% off (MSE 0.50x the held frame's; identified runs measured 0.12x at most)
    still = check_convergence(state(1 + 3 * settle, 0.3 + 0.2 * settle), blank=(0.0030, 0.0035), hold=0.0060)
    assert still.outcome == "untrained" and "holding the last input frame still" in still.reason
    # a held-out split in which nothing moves (its frames the last input frame's): the data is named, not the training
    frozen = check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle), blank=(0.0005, 0.0035), hold=0.0)
    assert frozen.outcome == "untrained" and "nothing moves in the held-out sequences" in frozen.reason
    assert "train longer" not in frozen.reason
    unsplit = check_convergence(state(1 + 3 * settle, 0.3 + 0.2 * settle), blank=(0.0030, 0.0035), hold=0.0060,
                                held_out=False)  # a file without a test split is judged on its training frames
    assert "its training-split predictions" in unsplit.reason and "held-out" not in unsplit.reason
    moving = check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle), blank=(0.0005, 0.0035), hold=0.0060)
    assert moving.outcome == "converged", moving.reason
    baseline = SimpleNamespace(step=1000, start={}, trace=[], plan=plan, history=[])  # no parameters: the hold is not asked
    assert check_convergence(baseline, blank=(0.0030, 0.0035), hold=0.0060).outcome == "converged"
    drifting = check_convergence(state(1 + 9 * steps / 1000, 0.3 + 0.7 * settle))  # g still climbs at the end
    assert drifting.outcome == "unsettled" and "g moved" in drifting.reason and "a moved" not in drifting.reason
    stopped = check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle, step=500))
    assert stopped.outcome == "unsettled" and "500 of 1000" in stopped.reason
    stuck = check_convergence(state(np.ones_like(steps), 0.3 + 0.7 * settle))
    assert stuck.outcome == "untrained" and "g never left" in stuck.reason
    unlearned = check_convergence(state(np.ones_like(steps), 0.3 + 0.7 * settle), blank=(0.0103, 0.0037))
    assert "g never left" in unlearned.reason and "where --lr was raised, lower it" in unlearned.reason  # --lr 10
    assert "raise --lr-physics" in unlearned.reason  # (a physics rate too small leaves the predictions poor too)
    # a spring of one slot for two bodies has no pair: k and l stay put whatever the rate; the slots are the fix
    from piga.evaluation.objects import ObjectCheck

    one_slot = check_convergence(state(np.ones_like(steps), 0.3 + 0.7 * settle),
                                 objects=ObjectCheck(0.3, 0.3, 1.04, True).with_counts(1, 2))
    assert "has 1 object slot for the scene's 2 objects" in one_slot.reason and "--lr-physics" not in one_slot.reason
    collapsed = check_convergence(state(1 + 9 * settle, np.full_like(steps, 1e-9)))
    assert collapsed.outcome == "untrained" and "a collapsed" in collapsed.reason
    faded = check_convergence(state(1 + 9 * settle, 0.3 - 0.298 * settle))  # a settles at 0.002: reversed frames
    assert faded.outcome == "untrained" and "a shrank" in faded.reason and "--signed-actuation" in faded.reason
    reversed_dmc = check_convergence(state(1 + 9 * settle, 0.3 - 0.2968 * settle))  # a = 0.0032, 93x below: measured
    assert reversed_dmc.outcome == "untrained" and "a shrank" in reversed_dmc.reason
    weak = check_convergence(state(1 + 9 * settle, 0.3 - 0.29 * (1 - np.exp(-steps / 50))))  # a settles at 0.01, 30x below
    assert weak.outcome == "converged", weak.reason
    warm = check_convergence(state(np.ones_like(steps), np.full_like(steps, 0.3), step=30))
    assert warm.outcome == "untrained" and "never trained" in warm.reason and warm.physics_steps == 0
    # profiles: one side clearly better stopped short (unsettled); flat within 2% both ways is not determined by
    # the frames (a file with actuation gain 1e-6: a flat within 1.3%), listed and said in the summary
    from piga.evaluation.evaluate import summary_line
    from piga.evaluation.profile import ParameterProfile

    curved, flat_a = ParameterProfile(10.0, 4.2, 5.0, 1.65), ParameterProfile(1.0, 1.004, 1.013, 1.65)
    short = check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle), profile={"g": curved,
                                                                               "a": ParameterProfile(1.0, 1.3, 0.94, 1.65)})
    assert short.outcome == "unsettled" and "a = 1 settled" in short.reason and short.undetermined == []
    flat = check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle), profile={"g": curved, "a": flat_a})
    assert flat.outcome == "converged" and flat.undetermined == ["a"]
    assert check_convergence(state(1 + 9 * settle, 0.3 + 0.7 * settle), profile={
        "g": curved, "a": ParameterProfile(1.0, 1.02, 1.19, 1.65)}).undetermined == []  # the least curved identified a
    line = summary_line({"parameters": {"g": 10.0, "a": 1.0}, "convergence": flat.to_dict()})
    assert line == "g=10.0000, a=1.0000 (not determined by the training frames: its profile is flat)"
    errors = {"g": {"learned": 10.0, "true": 10.0, "relative_error": 0.0}, "a": {"learned": 1.0, "true": 1e-6, "relative_error": 1e6}}
    assert "a=1.0000 (" in summary_line({"parameters": {}, "parameter_errors": errors, "convergence": flat.to_dict()})
    assert summary_line({"parameters": {}, "parameter_errors": errors, "convergence": flat.to_dict()}).endswith(
        "; not determined by the training frames: its profile is flat)")


def test_a_parameter_still_moving_as_fast_as_its_decayed_learning_rate_allows_is_unsettled() -> None:
    """The trajectory of a 300-step run on 2 spring sequences (recorded every 3 steps): it passed as converged with k
    71% and l 43% off, its profile curved (k 2.2 / 2.6, l 2.1 / 2.7), because the cosine schedule had decayed to a
    few percent of its peak and l moved only 0.53% over the last 30 steps; that is 0.83x the sum of its learning
    rate over them (identified runs moved at most 0.13x, a run with a still 8% short 0.63x)."""
    from types import SimpleNamespace

    from piga.evaluation.profile import ParameterProfile
    from piga.training.convergence import ConvergenceConfig, check_convergence
    from piga.training.train import TrainConfig, TrainPlan, physics_lr

    plan = asdict(TrainPlan(windows=22, steps_per_epoch=2, epochs=150, warmup_steps=54, curriculum_steps=108,
                            average_steps=50, checkpoint_every=3))
    config = TrainConfig(budget_steps=300, batch_size=8, lr_physics=0.01, lr_final_fraction=0.01)
    lr = lambda step: physics_lr(step, plan, config)  # noqa: E731
    steps = np.arange(3, 301, 3.0)
    # log l climbs in step with the learning rate as it shrinks to its floor (the straight-line fit over the tail
    # reads such a decelerating climb at about 0.86x the rate's sum, as the run's recorded 0.83x)
    rate = np.array([lr(int(s)) for s in steps])
    climb = np.cumsum(rate) * 3
    l_on_its_way = 3.4 * np.exp(climb - climb[-1])
    settled = 1 + 0.168 * (1 - np.exp(-steps / 40))

    def run(l: np.ndarray) -> SimpleNamespace:
        trace = [[s, k, lv] for s, k, lv in zip(steps, settled, l)]
        return SimpleNamespace(step=300, start={"k": 1.0, "l": 1.0}, trace=trace, plan=plan,
                               history=[{"k": trace[-1][1], "l": trace[-1][2]}])

    profile = {"k": ParameterProfile(1.168, 2.202, 2.616, 1.65), "l": ParameterProfile(3.4, 2.068, 2.66, 1.65)}
    numbers = dict(blank=(0.00473, 0.01629), hold=0.0205, profile=profile, held_out=True)
    verdict = check_convergence(run(l_on_its_way), physics_lr=lr, **numbers)
    assert verdict.outcome == "unsettled", verdict.reason
    assert verdict.reason.startswith("a parameter was still on its way when the learning rate decayed: l moved +0.4")
    assert "0.86x the sum of its learning rate" in verdict.reason
    assert f"(the bar is {ConvergenceConfig.speed_tolerance:g}x)" in verdict.reason
    assert "train longer" in verdict.reason and "k moved" not in verdict.reason
    assert 0.8 < verdict.parameters["l"].tail_speed < 0.9 and abs(verdict.parameters["k"].tail_speed) < 0.1
    # before, without the learning rate: the drift test alone took it for settled
    assert check_convergence(run(l_on_its_way), **numbers).outcome == "converged"
    # the same l at half that pace (identified short pendulum runs: 0.05x; a run with a 8% short: 0.63x)
    slower = 3.4 * np.exp(0.5 * (climb - climb[-1]))
    assert check_convergence(run(slower), physics_lr=lr, **numbers).outcome == "converged"
    # measured on its training frames alone (a file with no test split), the same settled run is not called converged
    unchecked = check_convergence(run(slower), physics_lr=lr, **{**numbers, "held_out": False})
    assert unchecked.outcome == "unsettled" and "the file has no test sequences, so no frame it did not train on checks" \
        in unchecked.reason, unchecked.reason


def test_a_slot_that_draws_nothing_makes_a_converged_scene_run_untrained() -> None:
    """An empty slot is still moved by the physics, so parameters that settled mean nothing; a baseline (``blank``
    given: no physical parameters) has none to bend and is judged on its predictions alone."""
    from types import SimpleNamespace

    from piga.evaluation.objects import ObjectCheck
    from piga.training.convergence import check_convergence
    from piga.training.train import TrainPlan

    plan = asdict(TrainPlan(windows=3200, steps_per_epoch=100, epochs=10, warmup_steps=40, curriculum_steps=100,
                            average_steps=60))
    steps = np.arange(10, 1001, 10.0)
    g = 1 + 59 * (1 - np.exp(-steps / 150))
    state = SimpleNamespace(step=1000, start={"g": 1.0}, trace=[[s, v] for s, v in zip(steps, g)], plan=plan,
                            history=[{"g": g[-1]}])
    full = ObjectCheck(0.01, 0.3, 0.03, False, slot_ratios=(0.98, 0.97, 0.99))
    assert check_convergence(state, objects=full.with_counts(3, 3)).outcome == "converged"
    empty = ObjectCheck(0.01, 0.3, 0.03, False, slot_ratios=(0.98, 0.97, 0.99, 0.006)).with_counts(4, 3)
    verdict = check_convergence(state, objects=empty)
    assert verdict.outcome == "untrained" and "slot 3 of 4 renders nothing" in verdict.reason
    assert "--objects 3" in verdict.reason
    baseline = SimpleNamespace(step=1000, start={}, trace=[[s] for s in steps], plan=plan, history=[{}])
    assert check_convergence(baseline, objects=empty, blank=(0.001, 0.01)).outcome == "converged"
    # cut short (--max-minutes at step 500 of 1000): objects not yet learned are continued, not blamed on the seed
    short = SimpleNamespace(step=500, start={"g": 1.0}, trace=[[s, v] for s, v in zip(steps, g) if s <= 500], plan=plan,
                            history=[{"g": g[49]}])
    lost = ObjectCheck(0.3, 0.5, 0.6, True).with_counts(3, 3)
    verdict = check_convergence(short, objects=lost)
    assert verdict.outcome == "unsettled" and "before its objects were learned" in verdict.reason


@pytest.mark.slow
def test_cli_interrupted_right_after_its_first_checkpoint_keeps_it_with_its_record(
        small_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C between the first checkpoint's write and the record that goes with it: the run is kept, said so, and
    --resume continues it (it used to say "nothing was written" beside a checkpoint that blocked the rerun)."""
    import piga.training.train as training

    save = training.save_checkpoint

    def save_then_interrupt(*args: object, **kwargs: object) -> None:
        save(*args, **kwargs)
        raise KeyboardInterrupt

    out = tmp_path / "r"
    monkeypatch.setattr(training, "save_checkpoint", save_then_interrupt)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), *SMALL, capsys=capsys)
    assert code == 130 and "holds epoch 1; continue with --resume" in err, err
    assert json.loads((out / "config.json").read_text())["command"].startswith(PROG)
    monkeypatch.setattr(training, "save_checkpoint", save)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "2",
                                  "--quiet", capsys=capsys)
    assert code in FINISHED, err


@pytest.mark.parametrize("text, said", [(None, None), ('{"converged": true}', None), ("{trunc", "cannot be read"),
                                        ("[1, 2]", "not a metrics record"),
                                        ('{"converged": "no"}', "gives 'converged' as 'no', not true or false")])
def test_an_unreadable_metrics_record_is_said_not_skipped(tmp_path: Path, text: str | None, said: str | None) -> None:
    from piga.io.runs import convergence_warning

    if text is not None:
        (tmp_path / "metrics.json").write_text(text)
    warning = convergence_warning(tmp_path)
    assert warning is None if said is None else said in warning and "unknown" in warning and "\n" not in warning


def test_a_run_stopped_before_its_end_is_said_never_checked(tmp_path: Path) -> None:
    """piga-control on an interrupted training run (a checkpoint, no metrics.json) gave no warning at all."""
    from piga.io.runs import convergence_warning

    assert convergence_warning(tmp_path) is None  # no run at all: whoever reads it refuses it on its own
    (tmp_path / "checkpoint.pt").write_bytes(b"")
    (tmp_path / "config.json").write_text("{}")  # piga-train-model's record, written at its first checkpoint
    warning = convergence_warning(tmp_path)
    assert warning is not None and "has no metrics.json" in warning and "never checked for convergence" in warning
    assert "--resume" in warning and "\n" not in warning


@pytest.mark.parametrize("convergence", ['"settled"', "[1]", '{"reason": 5}', "null"])
def test_a_convergence_entry_of_another_form_gives_the_warning_without_its_reason(tmp_path: Path, convergence: str) -> None:
    """A 'convergence' entry edited into a string was an internal error in piga-control (AttributeError)."""
    from piga.io.runs import convergence_warning

    (tmp_path / "metrics.json").write_text(f'{{"converged": false, "convergence": {convergence}}}')
    assert convergence_warning(tmp_path) == f"warning: the run {tmp_path} did not converge: no reason recorded"


def test_a_data_file_replaced_while_training_is_not_what_the_run_is_scored_on(
        small_data: Path, tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`piga-collect --overwrite` onto the file mid-run: the run was scored on the new file's test split, and a run
    that had not identified its parameters exited 0."""
    import piga.training.train as training

    data, out = tmp_path / "d.h5", tmp_path / "r"
    shutil.copy(small_data, data)
    real_train = training.train

    def train_then_replace(*args: Any, **kwargs: Any) -> Any:
        result = real_train(*args, **kwargs)
        shutil.copy(tiny_data, data)  # another recording under the same name
        return result

    monkeypatch.setattr(training, "train", train_then_replace)
    code, _, err = run_in_process(PROG, cli.main, str(data), "--out", str(out), *SMALL, capsys=capsys)
    assert_one_line(code, err, f"{data} changed while the run trained", "keeps its checkpoint", "--resume")
    assert (out / "checkpoint.pt").exists() and not (out / "metrics.json").exists()
    monkeypatch.setattr(training, "train", real_train)
    shutil.copy(small_data, data)  # put back: the same command with --resume scores it
    code, _, err = run_in_process(PROG, cli.main, str(data), "--out", str(out), "--resume", "--quiet", "--threads", "1",
                                  capsys=capsys)
    assert code in FINISHED, err
    assert (out / "metrics.json").exists()


def test_a_one_step_model_of_a_file_not_from_gymnasium_is_told_of_the_continuous_preset() -> None:
    """dm_control's pendulum trained with the fast preset exits 0 with g 6% and a 8% low (its model steps once per
    frame; the system moves between frames): the summary says so, and names the preset that models it."""
    from types import SimpleNamespace

    from piga.cli.train import one_step_note
    from piga.training.train import PRESETS

    fast, continuous = (SimpleNamespace(config=PRESETS[p].model) for p in ("fast", "continuous"))
    note = one_step_note(fast, {"env_id": "piga/DMCPendulum-v0"})
    assert note is not None and "--preset continuous" in note and "\n" not in note
    assert one_step_note(fast, {"env_id": "piga/PixelPendulum-v0"}) is None
    assert one_step_note(continuous, {"env_id": "piga/DMCPendulum-v0"}) is None
    assert one_step_note(fast, {}) is not None  # an imported recording: no env said

