"""``--overwrite`` replaces a run whole, of another kind too: none of the replaced run's outputs stays beside the new
run (a PlaNet-style run over a piga run kept the piga run's figures, which looked complete). And it replaces it only
once the new run has a checkpoint: a run interrupted or refused before that leaves the earlier run as it was."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from piga.cli import baseline, train
from piga.cli.baseline import _check_run_dir
from piga.io.checkpoint import CHECKPOINT, RUN_OUTPUTS, RunKind
from piga.io.replaced import ASIDE, ReplacedRun, replacing, settle_replaced
from tests.helpers import assert_one_line, run_in_process


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
    with replacing() as replaced:
        _check_run_dir(run, resume=False, overwrite=True, kind=RunKind.PLANET, replaced=replaced)
        assert sorted(p.name for p in run.iterdir()) == [ASIDE, "notes.txt"]  # set aside until a checkpoint
    assert sorted(p.name for p in run.iterdir()) == ["notes.txt"]


def test_without_overwrite_nothing_of_another_run_is_removed(tmp_path: Path) -> None:
    run = held_run(tmp_path / "run", "curves.png")  # a piga run's figure alone: no baseline output
    _check_run_dir(run, resume=False, overwrite=False, kind=RunKind.PLANET, replaced=ReplacedRun())
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


def _contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _earlier_run(folder: Path) -> dict[str, bytes]:
    run = held_run(folder, CHECKPOINT, "metrics.json", "curves.png")
    (run / "config.json").write_text(json.dumps({"command": "piga-train-model old.h5 --out run"}))
    (run / "tensorboard").mkdir()
    (run / "tensorboard" / "events.out").write_bytes(b"the earlier run's curves")
    return _contents(run)


def _stopped_before_a_checkpoint(run_dir: Path, error: BaseException) -> None:
    """What a training stopped before its first checkpoint leaves: its curves and its record begun."""
    (run_dir / "tensorboard").mkdir(exist_ok=True)
    (run_dir / "tensorboard" / "events.new").write_bytes(b"new")
    (run_dir / "config.json").write_text("{}")
    raise error


@pytest.mark.parametrize("command", ["train-model", "planet"])
@pytest.mark.parametrize("error", ["interrupt", "failure"])
def test_an_overwrite_stopped_before_its_first_checkpoint_leaves_the_earlier_run(
        command: str, error: str, tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C two seconds into ``--overwrite`` deleted the earlier run's curves (piga-train-model) or the whole
    earlier run (a baseline), while the line said that nothing was written."""
    run = tmp_path / "run"
    before = _earlier_run(run)
    exc: BaseException = KeyboardInterrupt() if error == "interrupt" else RuntimeError("boom")

    def stopped(data: object, run_dir: Path, *args: object, **kwargs: object) -> None:
        _stopped_before_a_checkpoint(Path(run_dir), exc)

    if command == "train-model":
        monkeypatch.setattr("piga.training.train.train", stopped)
        code, _, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(run), "--epochs", "1",
                                      "--batch-size", "16", "--threads", "1", "--quiet", "--overwrite", capsys=capsys)
    else:
        monkeypatch.setattr("agents.planet.train.train_planet", stopped)
        code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run),
                                      "--steps", "2", "--chunk-length", "4", "--threads", "1", "--quiet", "--overwrite",
                                      capsys=capsys)
    if error == "interrupt":
        assert_one_line(code, err, "interrupted; nothing was written", status=130)
    else:
        assert_one_line(code, err, "internal error", status=70)
    assert _contents(run) == before and not (run / ASIDE).exists()


def test_an_overwrite_refused_after_setting_the_run_aside_puts_it_back(
        tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A baseline's --overwrite sets the earlier run aside before its disk is checked: a refusal there puts it back."""
    import shutil

    run = tmp_path / "run"
    before = _earlier_run(run)
    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real(path)._replace(free=0))
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--steps",
                                  "2", "--chunk-length", "4", "--threads", "1", "--quiet", "--overwrite", capsys=capsys)
    assert_one_line(code, err, "disk")
    assert _contents(run) == before and not (run / ASIDE).exists()


def test_an_interrupt_while_setting_aside_puts_back_what_was_moved(tmp_path: Path) -> None:
    run = tmp_path / "run"
    before = _earlier_run(run)
    replaced = ReplacedRun()
    with pytest.raises(KeyboardInterrupt), replacing() as replaced:
        moved = replaced.set_aside(run, [CHECKPOINT, "config.json"])
        assert moved == [CHECKPOINT, "config.json"] and not (run / CHECKPOINT).exists()
        (run / CHECKPOINT).write_bytes(b"a new run's checkpoint, not yet its first")
        raise KeyboardInterrupt
    assert _contents(run) == before and not (run / ASIDE).exists()


@pytest.mark.parametrize("new_checkpoint", [False, True])
def test_a_killed_overwrite_is_settled_by_the_next_command(new_checkpoint: bool, tmp_path: Path) -> None:
    """SIGKILL between setting the earlier run aside and the new run's first checkpoint: the earlier run comes back;
    after it: the earlier run goes."""
    run = tmp_path / "run"
    before = _earlier_run(run)
    ReplacedRun().set_aside(run)  # (never dropped nor restored: the process was killed)
    (run / "config.json").write_text("{}")  # the new run's record, written before its checkpoint
    if new_checkpoint:
        (run / CHECKPOINT).write_bytes(b"new")
    line = settle_replaced(run)
    assert line is not None and ("removed" if new_checkpoint else "restored") in line
    assert not (run / ASIDE).exists()
    if new_checkpoint:
        assert _contents(run) == {CHECKPOINT: b"new", "config.json": b"{}", "notes.txt": b"mine"}
    else:
        assert _contents(run) == before
    assert settle_replaced(run) is None


def test_train_model_settles_a_killed_overwrite_before_it_looks_at_the_folder(
        tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without the settling, the folder (its checkpoint aside) read as an earlier run's outputs without a checkpoint."""
    run = tmp_path / "run"
    before = _earlier_run(run)
    ReplacedRun().set_aside(run)
    code, out, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(run), "--epochs", "1",
                                    "--batch-size", "16", "--threads", "1", "--quiet", capsys=capsys)
    assert_one_line(code, err, "already holds a run")
    assert "restored the run" in out and _contents(run) == before


def test_a_run_whose_checkpoint_is_cut_short_is_not_sent_to_resume(tiny_data: Path, tiny_run: Path, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """"already holds a run; pass --resume" for a checkpoint cut short, which --resume then could not read."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    argv = (str(tiny_data), "--out", str(run), "--epochs", "1", "--batch-size", "16", "--threads", "1", "--quiet")
    code, _, err = run_in_process("piga-train-model", train.main, *argv, capsys=capsys)
    assert_one_line(code, err, "already holds a run", "pass --resume")
    data = (run / CHECKPOINT).read_bytes()
    (run / CHECKPOINT).write_bytes(data[: len(data) // 2])
    code, _, err = run_in_process("piga-train-model", train.main, *argv, capsys=capsys)
    line = assert_one_line(code, err, "cannot be read", "--overwrite")
    assert "pass --resume" not in line


def test_a_reader_names_a_run_set_aside_by_a_killed_overwrite(tmp_path: Path) -> None:
    from piga.io.checkpoint import read_checkpoint

    run = tmp_path / "run"
    _earlier_run(run)
    ReplacedRun().set_aside(run)
    with pytest.raises(FileNotFoundError, match=r"killed before its new run's first checkpoint.*\.replaced"):
        read_checkpoint(run, RunKind.PIGA)
