"""``--overwrite`` replaces a run of another kind whole: none of the replaced run's outputs stays beside the new run
(a PlaNet-style run over a piga run kept the piga run's figures, which looked complete)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from piga.cli import train
from piga.cli.baseline import _check_run_dir
from piga.io.checkpoint import CHECKPOINT, RUN_OUTPUTS, RunKind
from tests.helpers import run_in_process


def held_run(folder: Path, *names: str) -> Path:
    """A folder whose run wrote ``names`` (placeholders), with a file of the user's beside them."""
    folder.mkdir()
    for name in names:
        (folder / name).write_bytes(b"x")
    (folder / "notes.txt").write_text("mine")
    return folder


def test_a_baseline_overwrite_removes_a_piga_runs_outputs(tmp_path: Path) -> None:
    run = held_run(tmp_path / "run", CHECKPOINT, "config.json", "metrics.json", "rollout.png", "templates.png",
                   "curves.png")
    _check_run_dir(run, resume=False, overwrite=True, kind=RunKind.PLANET)
    assert sorted(p.name for p in run.iterdir()) == ["notes.txt"]


def test_without_overwrite_nothing_of_another_run_is_removed(tmp_path: Path) -> None:
    run = held_run(tmp_path / "run", "curves.png")  # a piga run's figure alone: no baseline output
    _check_run_dir(run, resume=False, overwrite=False, kind=RunKind.PLANET)
    assert (run / "curves.png").exists()


def test_a_piga_overwrite_removes_a_baselines_outputs(tiny_data: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    run = held_run(tmp_path / "run", CHECKPOINT, "openloop.png", "model.zip", "autoencoder.pt", "collected.h5")
    (run / "config.json").write_text(json.dumps({"kind": "planet"}))
    run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(run), "--epochs", "1", "--batch-size",
                   "16", "--threads", "1", "--quiet", "--overwrite", capsys=capsys)
    left = {p.name for p in run.iterdir()}
    assert CHECKPOINT in left and "notes.txt" in left
    assert not left & {"openloop.png", "model.zip", "autoencoder.pt", "collected.h5"}, left
    assert json.loads((run / "config.json").read_text()).get("kind") != "planet"
    assert set(RUN_OUTPUTS) >= {"openloop.png", "model.zip", *train.OUTPUTS}
