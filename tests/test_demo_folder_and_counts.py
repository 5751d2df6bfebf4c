"""A piga-demo's folder refused as the --out of a training command, and a demo whose run was replaced by another
kind's refused --resume before it changes anything; counts of one in the singular."""

from __future__ import annotations

import shutil
from dataclasses import asdict
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from piga.io.checkpoint import CHECKPOINT, DEMO_RUN, RunKind, is_demo_folder, read_checkpoint
from tests.helpers import run_in_process
from tests.test_faults import MAINS, TINY_DDPG, TINY_PLANET, refused


def _demo_folder(root: Path, data: Path, trained: bool) -> Path:
    """A folder as piga-demo leaves it: its data, pictures and table, and (``trained``) its run in model/; without,
    as a demo stopped before its first checkpoint leaves it."""
    demo = root / "demo"
    (demo / DEMO_RUN).mkdir(parents=True)
    shutil.copy(data, demo / "pendulum.h5")
    (demo / "frames.png").write_bytes(b"strip")
    if trained:
        for name in ("goal.png", "control.md"):
            (demo / name).write_bytes(b"kept")
        (demo / DEMO_RUN / CHECKPOINT).write_bytes(b"the demo's model")
    return demo


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("trained", [True, False])
@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
@pytest.mark.parametrize("prog, argv", [  # tiny runs: where the folder was taken they ended in seconds
    ("piga-train-model", ["DATA", "--epochs", "1", "--batch-size", "8", "--threads", "1", "--quiet"]),
    ("piga-baseline", ["planet", "DATA", *TINY_PLANET]),
    ("piga-baseline", ["ddpg", "--obs", "state", *TINY_DDPG]),
    ("piga-baseline", ["ddpg", "--algo", "sac", "--obs", "state", *TINY_DDPG]),
    ("piga-baseline", ["ddpg", "--algo", "drqv2", "--obs", "pixels", *TINY_DDPG]),
])
def test_training_commands_refuse_a_demo_folder(prog: str, argv: list[str], overwrite: list[str], trained: bool,
                                                tiny_data: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Their run went in among the demo's files (with --overwrite, beside them), and piga-demo then refused the
    folder as one holding "a run of its own"."""
    demo = _demo_folder(tmp_path, tiny_data, trained)
    before = _snapshot(demo)
    argv = [str(demo / "pendulum.h5") if word == "DATA" else word for word in argv]
    refused(prog, [*argv, "--out", str(demo), *overwrite], capsys,
            f"--out {demo} is a piga-demo's folder (its run is {demo / DEMO_RUN})", "give another --out")
    assert _snapshot(demo) == before


def test_a_demo_s_own_run_folder_is_not_a_demo_folder(tiny_data: Path, tmp_path: Path) -> None:
    """piga-demo trains (and continues) its run in --out/model through piga-train-model."""
    demo = _demo_folder(tmp_path, tiny_data, trained=True)
    assert is_demo_folder(demo) and not is_demo_folder(demo / DEMO_RUN)


def test_a_demo_folder_before_its_first_checkpoint_given_as_a_run_says_to_continue_the_demo(tiny_data: Path,
                                                                                            tmp_path: Path) -> None:
    demo = _demo_folder(tmp_path, tiny_data, trained=False)
    with pytest.raises(FileNotFoundError, match=r"looks like a piga-demo folder, whose run .*demo/model has no checkpoint "
                                                r"yet; continue the demo with piga-demo --out .*demo --resume"):
        read_checkpoint(demo, RunKind.PIGA)


# ---------------------------------------------------------------------------------------------
# counts of one
# ---------------------------------------------------------------------------------------------


def test_collect_and_show_write_one_sequence_in_the_singular(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "p1.h5"
    code, out, _ = run_in_process("piga-collect", MAINS["piga-collect"], "--out", str(data), "--sequences", "1",
                                  "--steps", "16", "--quiet", "--workers", "1", capsys=capsys)
    assert code == 0 and f"wrote {data}: 1 sequence x 16 frames" in out, out
    strip = str(tmp_path / "s.png")
    refused("piga-show", [str(data), "--out", strip, "--split", "test"], capsys, "is empty; give --split train (1 sequence)")
    refused("piga-show", [str(data), "--out", strip, "--sequences", "2"], capsys,
            f"--sequences 2: {data} has 1 sequence in its train split; give at most 1")


def test_import_writes_one_sequence_and_one_frame_in_the_singular(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    import imageio.v3 as iio

    for name, count in (("one", 1), ("eight", 8)):
        (tmp_path / name).mkdir()
        for i in range(count):
            frame = np.zeros((32, 32), np.uint8)
            frame[4:12, 3 * i:3 * i + 4] = 255  # a square that moves
            iio.imwrite(tmp_path / name / f"f{i}.png", frame)
        (tmp_path / f"{name}.csv").write_text("0.5\n" * max(count, 2))
    refused("piga-import", [str(tmp_path / "one"), str(tmp_path / "one.csv"), "--dt", "0.05", "--out",
                            str(tmp_path / "o1.h5")], capsys, "has 2 actions but", "one has 1 frame; give one action")
    out_file = tmp_path / "i8.h5"
    code, out, _ = run_in_process("piga-import", MAINS["piga-import"], str(tmp_path / "eight"), str(tmp_path / "eight.csv"),
                                  "--dt", "0.05", "--steps", "8", "--image-size", "32", "--out", str(out_file),
                                  capsys=capsys)
    assert code == 0 and f"wrote {out_file}: 1 sequence x 8 frames" in out, out


def test_the_plan_line_writes_counts_of_one_in_the_singular() -> None:
    from piga.training.train import TrainPlan

    one = TrainPlan(windows=1, steps_per_epoch=1, epochs=1, warmup_steps=1, curriculum_steps=1, average_steps=1)
    assert one.describe(10) == ("1 step = 1 epoch x 1 step (1 window); autoencoder warm-up 1 step, curriculum 1 step "
                                "(T_pred 1 -> 10), parameters averaged over the last 1 step")
    assert "no autoencoder warm-up (its warm-up of 1 step predicts 1 frame)" in one.describe(10, autoencoder=False)
    two = TrainPlan(windows=2, steps_per_epoch=2, epochs=2, warmup_steps=2, curriculum_steps=2, average_steps=2)
    assert two.describe(10).startswith("4 steps = 2 epochs x 2 steps (2 windows); autoencoder warm-up 2 steps, "
                                       "curriculum 2 steps")


def test_a_run_of_one_step_is_too_short_to_judge_in_the_singular() -> None:
    from piga.training.convergence import check_convergence
    from piga.training.train import TrainPlan

    plan = asdict(TrainPlan(windows=8, steps_per_epoch=1, epochs=1, warmup_steps=0, curriculum_steps=0, average_steps=0))
    state = SimpleNamespace(step=1, start={"g": 1.0, "a": 0.3}, trace=[[1, 1.5, 0.4]], plan=plan,
                            history=[{"g": 1.5, "a": 0.4}])
    assert "settled (1 step, fewer than 5 recorded" in check_convergence(state).reason


def test_a_demo_whose_run_is_another_kinds_is_refused_resume_before_anything_is_made(tiny_data: Path, tmp_path: Path,
                                                                                     capsys: pytest.CaptureFixture[str]
                                                                                     ) -> None:
    """A PlaNet-style run in place of the demo's model: the refusal came at the third step, after the strip was drawn
    again, and named no way out."""
    import json

    demo = _demo_folder(tmp_path, tiny_data, trained=True)
    (demo / DEMO_RUN / "config.json").write_text(json.dumps({"kind": "planet"}))
    before = _snapshot(demo)
    refused("piga-demo", ["--out", str(demo), "--sequences", "12", "--resume"], capsys,
            f"--resume: {demo / DEMO_RUN} holds a piga-baseline planet run", "pass --overwrite (not --resume)")
    assert _snapshot(demo) == before


def test_one_training_window_is_said_in_the_singular() -> None:
    from piga.training.train import TrainConfig, plan_training

    with pytest.raises(ValueError, match=r"^1 training window is fewer than one batch of 32, .*--batch-size"):
        plan_training(TrainConfig(batch_size=32), 1)


@pytest.mark.parametrize("extra", [[], ["--overwrite"], ["--resume"]])
@pytest.mark.parametrize("mine", [b"x\n", None])
def test_a_data_file_the_demo_did_not_write_is_not_offered_to_overwrite(mine: bytes | None, extra: list[str],
                                                                        tiny_data: Path, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """An unrelated u/pendulum.h5 was called "from an earlier demo; pass --resume ... or --overwrite", and --overwrite
    would have destroyed it. (``None``: another command's HDF5 file, piga-collect's.)"""
    from piga.cli import demo

    out = tmp_path / "u"
    out.mkdir()
    if mine is None:
        shutil.copy(tiny_data, out / "pendulum.h5")
    else:
        (out / "pendulum.h5").write_bytes(mine)
    before = _snapshot(out)
    code, _, err = run_in_process("piga-demo", demo.main, "--out", str(out), "--sequences", "2", "--epochs", "1",
                                  "--threads", "1", "--quiet", *extra, capsys=capsys)
    assert code == 1 and err.strip() == (f"piga-demo: error: {out / 'pendulum.h5'} exists and is not a piga-demo's data "
                                         "file; give another --out (a demo writes pendulum.h5, frames.png, model/, "
                                         "goal.png and control.md into it)"), err
    assert _snapshot(out) == before


def test_a_resumed_demo_with_fewer_epochs_is_refused_before_it_draws_again(tiny_data: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """It was refused at its training stage, after the strip (frames.png) was drawn again."""
    from piga.cli import demo
    from tests.helpers import train_tiny

    folder = tmp_path / "demo"
    folder.mkdir()
    shutil.copy(tiny_data, folder / "pendulum.h5")
    with h5py.File(folder / "pendulum.h5", "a") as f:  # as the demo collected it
        f.attrs["command"] = "piga-demo --out demo --sequences 12 --seed 3"
    (folder / "frames.png").write_bytes(b"strip")
    train_tiny(folder / "pendulum.h5", folder / DEMO_RUN, epochs=2)
    before = _snapshot(folder)
    code, _, err = run_in_process("piga-demo", demo.main, "--out", str(folder), "--resume", "--epochs", "1",
                                  "--sequences", "12", "--seed", "3", "--quiet", capsys=capsys)
    assert code == 1 and err.count("\n") == 1, err
    assert "--resume --epochs 1: the run already planned 2 epochs" in err and "never lower them" in err, err
    assert _snapshot(folder) == before
