"""The lengths that commands are given: a training run shorter than its recipe, a gravity sweep that changes
nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from piga.cli.train import main as train_main
from tests.helpers import assert_one_line, run_in_process
from tests.test_faults import refused


@pytest.fixture(scope="module")
def small_spring(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """5 spring sequences x 11 frames: a file whose fast recipe plans far more steps than a test trains."""
    from envs.scenes import scene_config
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene

    path = tmp_path_factory.mktemp("spring") / "spring.h5"
    config = SceneCollectConfig(scene=scene_config("spring"), sequences=5, steps=11, seed=0, workers=1, split=(3, 1, 1))
    return collect_scene(config, path, progress=False, command="test")


@pytest.mark.slow
def test_a_scene_run_shorter_than_its_recipe_retries_no_seed(small_spring: Path, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """--budget-steps 20 where the fast preset plans 1,650: an object lost (a stand-in check) is the length's, so the
    run stops after its first check with the line that names the length, not after three more seeds of 20 steps."""
    import piga.training.report as report
    from piga.evaluation.objects import ObjectCheck

    monkeypatch.setattr(report, "check_objects", lambda model, frames: ObjectCheck(0.3, 0.5, 0.6, True))
    out = tmp_path / "run"
    code, stdout, err = run_in_process("piga-train-model", train_main, str(small_spring), "--out", str(out),
                                       "--batch-size", "3", "--budget-steps", "20", "--threads", "1", "--quiet",
                                       capsys=capsys)
    line = assert_one_line(code, err, "did not identify its parameters", "an object was not found",
                           "in a run of 20 steps where the fast preset plans", "train it that long")
    assert code == 1 and "seeds" not in line
    assert "training again" not in stdout
    record = json.loads((out / "config.json").read_text())
    assert record["train"]["seed"] == 0 and record["train"]["seed_retries"] == 0 and "retried_seeds" not in record


@pytest.mark.slow
def test_a_resumed_scene_run_still_shorter_than_its_recipe_is_told_to_train_that_long(
        small_spring: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """After --resume --epochs 3 of a 2-epoch run (6 steps of 1,650 planned), the advice turned to "train again with
    another --seed or more --seed-retries", contradicting the first run's "train it that long"."""
    import piga.training.report as report
    from piga.evaluation.objects import ObjectCheck

    monkeypatch.setattr(report, "check_objects", lambda model, frames: ObjectCheck(0.3, 0.5, 0.6, True))
    out = tmp_path / "run"
    common = [str(small_spring), "--out", str(out), "--batch-size", "3", "--threads", "1", "--quiet"]
    code, _, err = run_in_process("piga-train-model", train_main, *common, "--epochs", "2", capsys=capsys)
    assert_one_line(code, err, "where the fast preset plans", "train it that long")
    code, _, err = run_in_process("piga-train-model", train_main, *common, "--epochs", "3", "--resume", capsys=capsys)
    line = assert_one_line(code, err, "an object was not found", "in a run of 3 steps where the fast preset plans",
                           "train it that long")
    assert "another --seed or more --seed-retries" not in line


@pytest.mark.parametrize("sweep", ["1:1:0.1", "1:1.05:0.1"])
def test_not_told_refuses_a_sweep_whose_every_multiplier_is_1(sweep: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """As a single run at x1 is refused --not-told: nothing changes. Refused before the run folder is read."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text("{}")
    refused("piga-control", ["--model", str(run), "--sweep", sweep, "--not-told", "--quiet"], capsys,
            "--not-told keeps the piga agent's gravity at x1", f"at --sweep {sweep} (every multiplier x1) nothing "
            "changes", "drop --not-told")
