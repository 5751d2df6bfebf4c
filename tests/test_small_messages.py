"""Messages about small files: the splits that a strip can show, counts of one, a system with nothing to learn."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import pytest

from piga.cli import show
from piga.data.collect import empty_split_warning
from piga.evaluation.evaluate import summary_line
from tests.helpers import assert_one_line, run_in_process


def test_an_empty_split_names_the_splits_that_hold_sequences(tiny_data: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "no_test.h5"
    shutil.copy(tiny_data, data)
    with h5py.File(data, "a") as f:
        split = f["split"][:]
        split[split == 2] = 1  # the test sequences become validation ones
        f["split"][...] = split
        if "split_counts" in f.attrs:
            f.attrs["split_counts"] = json.dumps({"train": 8, "valid": 4, "test": 0})
    code, _, err = run_in_process("piga-show", show.main, str(data), "--out", str(tmp_path / "s.png"), "--split", "test",
                                  capsys=capsys)
    assert_one_line(code, err, f"split 'test' of {data} is empty; give --split train (8 sequences) or valid (4 sequences)")


def test_counts_of_one_are_singular() -> None:
    assert "of 1 sequence leaves" in empty_split_warning((0.8, 0.1, 0.1), {"train": 1, "valid": 0, "test": 0})
    assert "of 4 sequences leaves" in empty_split_warning((0.8, 0.1, 0.1), {"train": 4, "valid": 0, "test": 0})


def test_a_system_with_nothing_to_learn_says_so() -> None:
    """Bouncing balls printed a bare "learned: " line."""
    assert summary_line({"parameters": {}, "parameter_errors": {}}) == "no parameter (none to learn)"
    assert summary_line({"parameters": {"g": 9.9}, "parameter_errors": {}}) == "g=9.9000"


def test_a_run_with_no_parameter_that_lost_an_object_is_not_said_to_miss_its_parameters(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Bouncing balls (no physical parameter) with an object lost read "the run did not identify its parameters",
    while the run's own line said "learned: no parameter (none to learn)"."""
    import piga.training.report as report
    from envs.scenes import scene_config
    from piga.cli.train import main as train_main
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene
    from piga.evaluation.objects import ObjectCheck

    data = collect_scene(SceneCollectConfig(scene=scene_config("bouncing"), sequences=5, steps=11, seed=0, workers=1,
                                            split=(3, 1, 1)), tmp_path / "bouncing.h5", progress=False, command="test")
    monkeypatch.setattr(report, "check_objects", lambda model, frames: ObjectCheck(0.3, 0.5, 0.6, True))
    code, _, err = run_in_process("piga-train-model", train_main, str(data), "--out", str(tmp_path / "run"),
                                  "--batch-size", "3", "--budget-steps", "3", "--threads", "1", "--quiet", capsys=capsys)
    line = assert_one_line(code, err, "the run did not learn to predict: an object was not found")
    assert "parameters" not in line


def test_the_learned_line_shows_the_offset_the_warning_names() -> None:
    """A run left unsettled by its offset warned "offset moved ..." beside a learned line without the offset."""
    errors = {"g": {"learned": 9.9, "true": 10.0, "relative_error": 0.01}}
    metrics = {"parameters": {"g": 9.9, "offset": 0.02}, "parameter_errors": errors}
    assert "offset" not in summary_line(metrics | {"convergence": {"reason": "every learned parameter settled"}})
    unsettled = {"reason": "still drifting at the end: offset moved +3.00% over the last 10% of steps; train longer"}
    assert summary_line(metrics | {"convergence": unsettled}).endswith(", offset=0.0200")


@pytest.fixture(scope="module")
def piga_run(tiny_run: Path) -> Path:
    """A one-epoch piga-train-model run on ``tiny_data``: the session's (tests/conftest.py)."""
    return tiny_run


@pytest.mark.parametrize("given, said", [
    ((), "at --gravity-mult 1 (the default) nothing changes: give --gravity-mult"),
    (("--gravity-mult", "1"), "at --gravity-mult 1 nothing changes: give another --gravity-mult"),
    (("--gravity-mult", "1.0"), "at --gravity-mult 1 nothing changes: give another --gravity-mult"),
])
def test_not_told_at_gravity_x1_is_refused(piga_run: Path, given: tuple[str, ...], said: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import control

    code, _, err = run_in_process("piga-control", control.main, "--model", str(piga_run), "--not-told", *given,
                                  capsys=capsys)
    assert_one_line(code, err, "--not-told keeps the piga agent's gravity at x1", said)


def test_a_demo_folder_given_as_a_run_names_its_model(tmp_path: Path) -> None:
    from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint

    (tmp_path / "demo" / "model").mkdir(parents=True)
    (tmp_path / "demo" / "model" / CHECKPOINT).write_bytes(b"x")
    with pytest.raises(FileNotFoundError, match=r"looks like a piga-demo folder, whose trained run is .*demo/model; give "
                                                r"that"):
        read_checkpoint(tmp_path / "demo", RunKind.PIGA)
