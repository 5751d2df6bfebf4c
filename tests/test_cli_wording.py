"""The words of the commands' lines: the user's values as given, the refusal that names what to change first, every
file a refusal is about, and the units of what is written."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from envs.fields import number_text
from piga.cli import control
from tests.helpers import moving_png_folder, run_in_process
from tests.test_faults import refused

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture(scope="module")
def small_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A pendulum file: 4 sequences x 12 frames, split (2, 1, 1)."""
    from piga.data.collect import CollectConfig, collect

    path = tmp_path_factory.mktemp("data") / "d4.h5"
    return collect(CollectConfig(sequences=4, steps=12, seed=0, workers=1, split=(2, 1, 1)), path, progress=False,
                   command="t")


# ---------------------------------------------------------------------------------------------
# The user's whole numbers as integers
# ---------------------------------------------------------------------------------------------


def test_number_text_writes_a_whole_number_without_a_point() -> None:
    assert [number_text(v) for v in (1.0, 9.0, -9.0, 1e7, 1234567.0, 200.0, 0.5, 10.0000001)] == \
        ["1", "9", "-9", "1e+07", "1234567", "200", "0.5", "10.0000001"]
    assert number_text(10 ** 30) == "1" + "0" * 30  # an integer keeps its digits (float() would lose some)
    assert number_text("sideways") == "'sideways'"  # text where a number belongs is quoted, as repr quotes it


@pytest.mark.parametrize("prog, argv, needle, code", [
    ("piga-collect", ["--effect", "frame_drop=1"], "effect frame_drop=1 is out of range", 1),
    ("piga-collect", ["--effect", "cogging=1e7"], "effect cogging=1e+07 is out of range", 1),
    ("piga-collect", ["--max-speed", "9"], "--max-speed=9 is out of range", 1),
    ("piga-collect", ["--actuation-gain", "1234567"], "--actuation-gain=1234567 is out of range", 1),
    ("piga-collect", ["--sequences", "4", "--split", "2,1,0"],
     "split (2, 1, 0) must be fractions summing to 1 or counts summing to 4", 1),
    ("piga-control", ["--write-goal-image", "g.png", "--angle", "200"], "within [-180, 180], got 200", 1),
])
def test_refusals_write_the_users_whole_numbers_as_integers(prog: str, argv: list[str], needle: str, code: int,
                                                            tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """They read "frame_drop=1.0", "cogging=10000000.0", "--max-speed=9.0", "split (2.0, 1.0, 0.0)", "got 200.0"."""
    out = ["--out", str(tmp_path / "d.h5")] if prog == "piga-collect" else []
    line = refused(prog, [*out, *argv], capsys, needle, code=code)
    assert not re.search(r"\d\.0\b", line), line


def test_import_writes_the_split_as_given(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """12 frames in sequences of 4 are 3 sequences; the split's counts are written as the user gave them."""
    folder = moving_png_folder(tmp_path / "frames")
    csv = tmp_path / "u.csv"
    csv.write_text("0.5\n" * 12)
    refused("piga-import", [str(folder), str(csv), "--dt", "0.05", "--steps", "4", "--image-size", "32", "--split",
                            "2,1,1", "--out", str(tmp_path / "out.h5")], capsys,
            "split (2, 1, 1) must be fractions summing to 1 or counts summing to 3")


# ---------------------------------------------------------------------------------------------
# piga-show: the empty split first
# ---------------------------------------------------------------------------------------------


@pytest.fixture
def blank_test_only(small_data: Path, tmp_path: Path) -> Path:
    """``small_data``'s copy whose frames are all 0 and whose sequences are all in the test split."""
    import shutil

    path = shutil.copyfile(small_data, tmp_path / "blank.h5")
    with h5py.File(path, "a") as f:
        f["frames"][...] = 0
        f["split"][...] = 2
        f.attrs.pop("split_counts", None)  # the attribute would contradict the new /split
    return Path(path)


def test_show_names_an_empty_split_and_draws_blank_frames(blank_test_only: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """It said "every frame is blank": true, but what --split to give is the first thing to change."""
    refused("piga-show", [str(blank_test_only), "--out", str(tmp_path / "m.png"), "--split", "valid"], capsys,
            "split 'valid' of", "is empty; give --split test (4 sequences)")
    assert not (tmp_path / "m.png").exists()
    # a split that holds sequences: the blank frames are drawn, with one warning (a viewer is how one finds out)
    from piga.cli.show import main

    code, _, err = run_in_process("piga-show", main, str(blank_test_only), "--out", str(tmp_path / "m.png"), "--split",
                                  "test", capsys=capsys)
    assert code == 0 and (tmp_path / "m.png").exists()
    assert err.count("\n") == 1 and "warning: " in err and "every frame is blank" in err and "drawn all the same" in err
    # a count beyond the file is refused in one line, without the warning of a strip it does not draw
    refused("piga-show", [str(blank_test_only), "--out", str(tmp_path / "n.png"), "--split", "test", "--sequences",
                          "50"], capsys, "--sequences 50", "give at most 4")


# ---------------------------------------------------------------------------------------------
# piga-control --write-goal-image: every format --goal-image reads back
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def reader() -> object:
    """An untrained pendulum model whose encoder reads a render's angle (tests/test_control.py)."""
    from piga.world.model import ModelConfig, PhysicsModel

    model = PhysicsModel(ModelConfig())
    with torch.no_grad():
        model.encoder.background.fill_(1.0)
    return model


def _suffixes() -> list[str]:
    from piga.control.goal import GOAL_IMAGE_FORMATS

    return list(GOAL_IMAGE_FORMATS)


@pytest.mark.parametrize("suffix", _suffixes())
def test_write_goal_image_reads_back_to_its_angle(suffix: str, reader: object, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Each suffix --write-goal-image writes (.webp was refused) gives the angle back through --goal-image's reading:
    the scene check, then the encoder (lossy WebP would blur it; it is written lossless)."""
    import imageio.v3 as iio

    from piga.control.goal import MAX_SCENE_MISMATCH, load_scene_image, read_goal, render_goal_image, scene_mismatch

    path = tmp_path / f"goal{suffix}"
    code, out, err = run_in_process("piga-control", control.main, "--write-goal-image", str(path), "--angle", "30",
                                    capsys=capsys)
    assert code == 0 and f"wrote {path}" in out, err
    if suffix not in (".jpg", ".jpeg"):  # the others are written lossless
        assert np.array_equal(iio.imread(path), render_goal_image(30.0))
    image = load_scene_image(path, 64)
    assert scene_mismatch(image) < MAX_SCENE_MISMATCH / 10
    angle = read_goal(reader, image, g=10.0, a=1.0, mse_limit=1.0).angle  # type: ignore[arg-type]
    assert math.degrees(angle) == pytest.approx(30, abs=1)


def test_write_goal_image_names_every_suffix_it_takes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused("piga-control", ["--write-goal-image", str(tmp_path / "g.gif"), "--angle", "10"], capsys,
                   "--write-goal-image: use a path ending in", "got g.gif")
    page = (DOCS / "commands" / "control.md").read_text()
    row = next(r for r in page.splitlines() if r.startswith("| `--write-goal-image"))
    for suffix in _suffixes():
        assert suffix in line and suffix in row, (suffix, line, row)


# ---------------------------------------------------------------------------------------------
# A run written over: every file of every kind named
# ---------------------------------------------------------------------------------------------


def _fake_run(folder: Path, record: dict[str, str], names: list[str]) -> Path:
    """A run folder as far as the refusal reads it: ``record`` as config.json, and empty files (a folder for
    tensorboard) named ``names``."""
    folder.mkdir()
    (folder / "config.json").write_text(json.dumps(record))
    for name in names:
        (folder / name).mkdir() if name == "tensorboard" else (folder / name).write_bytes(b"")
    return folder


def test_baseline_refusal_lists_a_train_model_runs_figures(small_data: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """It listed "(checkpoint.pt, config.json, metrics.json, tensorboard)": a piga run's figures were left out."""
    names = ["checkpoint.pt", "metrics.json", "tensorboard", "curves.png", "rollout.png", "templates.png"]
    run = _fake_run(tmp_path / "R", {"command": "piga-train-model"}, names)
    line = refused("piga-baseline", ["planet", str(small_data), "--out", str(run), "--steps", "2", "--chunk-length",
                                     "5"], capsys, "already holds a piga-train-model run")
    assert all(name in line for name in [*names, "config.json"]), line


def test_train_model_refusal_lists_a_baselines_files(small_data: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    names = ["checkpoint.pt", "metrics.json", "tensorboard", "openloop.png"]
    run = _fake_run(tmp_path / "R", {"kind": "planet", "command": "piga-baseline planet"}, names)
    line = refused("piga-train-model", [str(small_data), "--out", str(run)], capsys,
                   "already holds a piga-baseline planet run")
    assert all(name in line for name in [*names, "config.json"]), line


# ---------------------------------------------------------------------------------------------
# The units of piga-control's OUT.json
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("option", ["--out OUT", "--sweep "])
def test_control_page_gives_the_units_of_out_json(option: str) -> None:
    """OUT.json's goal_angle and final_angle_error_mean are radians, OUT.md's and the printed lines' degrees: the
    page says so beside --out and beside --sweep's OUT.json, naming keys the summary writes."""
    from piga.evaluation.episodes import EpisodeSummary

    page = (DOCS / "commands" / "control.md").read_text()
    row = next(r for r in page.splitlines() if r.startswith(f"| `{option}"))
    assert "radians" in row and "degrees" in row, row
    keys = set(re.findall(r"`(\w+_angle\w*)`", row))
    assert keys and keys <= {f for f in EpisodeSummary.__dataclass_fields__}, keys


# ---------------------------------------------------------------------------------------------
# Lines that name only what the user gave, and pages that name every file written
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("argv, needle", [
    (["--env", "piga/DMCPendulum-v0", "--env-option", "camera=fixed", "--env-option", "camera_distance=3"],
     "--env-option camera=fixed is dm_control's own camera, which camera_distance=3 cannot move: drop it or "
     "camera=fixed"),
    (["--half"], "--half is for the spring scene (--system spring); the pendulum takes --gravity"),
])
def test_a_clash_names_the_options_given(argv: list[str], needle: str, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """The fixed camera's line had named flip='camera' and "DMCPendulumConfig", --half "the scenes" (bouncing too)."""
    line = refused("piga-collect", ["--out", str(tmp_path / "d.h5"), "--sequences", "4", *argv], capsys, needle)
    assert "DMCPendulumConfig" not in line and "flip" not in line


def test_the_diagnose_page_names_every_file_of_a_report() -> None:
    from piga.diagnostics.report import REPORT_FILES

    page = (DOCS / "commands" / "diagnose.md").read_text()
    assert all(f"`{name}`" in page for name in REPORT_FILES), REPORT_FILES
