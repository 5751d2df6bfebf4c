"""``--overwrite`` replaces a run whole, of another kind too: none of the replaced run's outputs stays beside the new
run (a PlaNet-style run over a piga run kept the piga run's figures, which looked complete). And it replaces it only
once the new run has a checkpoint: a run interrupted or refused before that leaves the earlier run as it was."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

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


def _earlier_demo(out: Path) -> dict[str, bytes]:
    """A folder as an earlier piga-demo left it (its data file a real one of the demo's; the rest placeholders)."""
    from piga.data.collect import CollectConfig, collect

    out.mkdir()
    collect(CollectConfig(sequences=3, steps=4, seed=1, workers=1), out / "pendulum.h5", progress=False,
            command=f"piga-demo --out {out}")
    for name in ("frames.png", "goal.png", "control.md", "model/checkpoint.pt", "model/metrics.json"):
        (out / name).parent.mkdir(exist_ok=True)
        (out / name).write_bytes(b"earlier " + name.encode())
    return _contents(out)


def _new_collect(config: object, path: Path, **kwargs: object) -> None:
    Path(path).write_bytes(b"new data")


@pytest.mark.parametrize("stop", ["collected", "refused in training", "interrupted in training"])
def test_a_demo_overwrite_stopped_before_its_first_checkpoint_leaves_the_earlier_demo(
        stop: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C after the collection of a piga-demo --overwrite had already replaced the earlier demo's data file,
    while its model, goal.png and control.md stayed: a folder of two demos, the earlier data lost."""
    from piga.cli import demo
    from piga.cli.common import PigaError

    out = tmp_path / "demo"
    earlier = _earlier_demo(out)

    def collect_then_stop(config: object, path: Path, **kwargs: object) -> None:
        _new_collect(config, path)
        raise KeyboardInterrupt

    def training(argv: list[str], prog: str, **_: Any) -> int:
        assert (out / "pendulum.h5").read_bytes() == b"new data"
        raise PigaError("refused") if stop == "refused in training" else KeyboardInterrupt

    monkeypatch.setattr(demo, "collect", collect_then_stop if stop == "collected" else _new_collect)
    monkeypatch.setattr(demo, "_check_enough_sequences", lambda config: None)
    monkeypatch.setattr(demo.show, "main", lambda argv: Path(argv[argv.index("--out") + 1]).write_bytes(b"new") and 0)
    monkeypatch.setattr(demo.train, "main", training)
    code, _, err = run_in_process("piga-demo", demo.main, "--out", str(out), "--overwrite", "--quiet", capsys=capsys)
    if stop == "refused in training":
        assert_one_line(code, err, "refused")
    else:
        assert_one_line(code, err, f"interrupted; nothing was written; {out} holds the earlier demo as it was",
                        status=130)
    assert _contents(out) == earlier


def test_a_demo_overwrite_that_got_a_checkpoint_replaces_the_earlier_demo_whole(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    from piga.cli import demo
    from piga.cli.common import Interrupted

    out = tmp_path / "demo"
    _earlier_demo(out)

    def trained_then_stopped(argv: list[str], prog: str, **_: Any) -> int:
        (out / "model" / "checkpoint.pt").write_bytes(b"new checkpoint")
        raise Interrupted("model/checkpoint.pt holds epoch 1; continue with --resume")

    monkeypatch.setattr(demo, "collect", _new_collect)
    monkeypatch.setattr(demo, "_check_enough_sequences", lambda config: None)
    monkeypatch.setattr(demo.show, "main", lambda argv: 0)
    monkeypatch.setattr(demo.train, "main", trained_then_stopped)
    code, _, err = run_in_process("piga-demo", demo.main, "--out", str(out), "--overwrite", "--quiet", capsys=capsys)
    assert_one_line(code, err, "keeps pendulum.h5, model/checkpoint.pt from this demo", "--resume in place of --overwrite",
                    status=130)
    # the earlier demo's goal image and table went with it: no folder of two demos
    assert _contents(out) == {"pendulum.h5": b"new data", "model/checkpoint.pt": b"new checkpoint",
                              "model/metrics.json": b"earlier model/metrics.json"}  # (the model's own: train-model's)


@pytest.mark.parametrize("new_checkpoint", [False, True])
def test_a_killed_demo_overwrite_is_settled_by_the_next_demo(new_checkpoint: bool, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGKILL: the earlier demo's files wait in --out/.replaced. The next demo puts them back where the run in
    model/ did not train on the new data file, and deletes them where it did."""
    from piga.cli import demo

    out = tmp_path / "demo"
    earlier = _earlier_demo(out)
    (out / ASIDE).mkdir()
    for name in ("pendulum.h5", "frames.png", "goal.png", "control.md"):
        (out / name).rename(out / ASIDE / name)
    from piga.data.collect import CollectConfig, collect

    collect(CollectConfig(sequences=3, steps=4, seed=2, workers=1), out / "pendulum.h5", progress=False,
            command=f"piga-demo --out {out} --seed 2")
    new_data = (out / "pendulum.h5").read_bytes()
    monkeypatch.setattr(demo, "_trained_on", lambda run, data, strict=False: new_checkpoint and data == out / "pendulum.h5")
    code, out_text, err = run_in_process("piga-demo", demo.main, "--out", str(out), "--quiet", capsys=capsys)
    assert_one_line(code, err, "exists from an earlier demo", "--resume")  # the plain rerun, settled first
    if new_checkpoint:
        assert out_text.startswith(f"removed {out / ASIDE}: the earlier demo that an --overwrite replaced")
        assert _contents(out) == {"pendulum.h5": new_data, "model/checkpoint.pt": b"earlier model/checkpoint.pt",
                                  "model/metrics.json": b"earlier model/metrics.json"}
    else:
        assert out_text.startswith(f"restored the earlier demo in {out} from {out / ASIDE}")
        assert _contents(out) == earlier


def test_a_killed_demos_half_written_files_go_with_the_next_demo(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A demo killed while it collected left .pendulum.h5.partial-PID, which a refused rerun and a whole --resume (that
    keeps its data file, never writing it again) left behind."""
    import subprocess
    import sys

    from piga.cli import demo
    from piga.io.atomic import partial_path

    out = tmp_path / "demo"
    earlier = _earlier_demo(out)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = partial_path(out / "pendulum.h5").with_name(f".pendulum.h5.partial-{int(dead.stdout)}")
    stale.write_bytes(b"half a file")
    code, _, err = run_in_process("piga-demo", demo.main, "--out", str(out), "--quiet", capsys=capsys)
    assert_one_line(code, err, "exists from an earlier demo")  # refused, and the leftover gone all the same
    assert not stale.exists() and _contents(out) == earlier
