"""Messages in plain words: what is wrong with a file, not the name of the exception that found it."""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from tests.helpers import ENV
from tests.test_faults import refused

#: A Python exception's name, as it must not appear in a user's line.
EXCEPTION_NAME = re.compile(r"\b[A-Z]\w*(Error|Exception)\b|EOFError")


@pytest.mark.parametrize("content, needle", [
    (b"", "checkpoint.pt: not a readable piga checkpoint (it is empty)"),  # "EOFError: Ran out of input"
    (bytes(range(0xC1, 0x100)) * 20, "(its bytes are not a file of this kind)"),  # "UnicodeDecodeError: 'utf-8' ..."
    (b"garbage\n", "(its bytes are not a file of this kind)"),  # "invalid literal for int() with base 10: 'arbage\n'"
    (1000, "(it is cut short or damaged)"),  # "PytorchStreamReader failed reading zip archive: ..."
    (5000, "(it is cut short or damaged)"),  # "[Errno 22] Invalid argument"
    (b"\x80\x04\x95", "(it is cut short or damaged)"),  # a pickle cut short: "pickle data was truncated"
], ids=["empty", "random", "text", "cut-1000", "cut-5000", "pickle-cut"])
def test_an_unreadable_checkpoint_is_said_in_words(content: bytes | int, needle: str, tmp_path: Path) -> None:
    from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint

    path = tmp_path / CHECKPOINT
    if isinstance(content, int):  # a checkpoint cut short after that many bytes
        torch.save({"model": {"w": torch.zeros(10000)}}, path)
        content = path.read_bytes()[:content]
    path.write_bytes(content)
    with pytest.raises(ValueError) as error:
        read_checkpoint(tmp_path, RunKind.PIGA)
    assert needle in str(error.value) and "truncated" in str(error.value), error.value
    assert not EXCEPTION_NAME.search(str(error.value)), error.value
    assert "Errno" not in str(error.value) and "int()" not in str(error.value), error.value


def test_a_whole_archive_of_other_entries_is_not_called_cut_short(tmp_path: Path) -> None:
    """A complete zip archive that torch cannot read as a checkpoint is named by its entries, not as cut short."""
    import zipfile

    from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint

    with zipfile.ZipFile(tmp_path / CHECKPOINT, "w") as archive:
        archive.writestr("notes.txt", "not a checkpoint")
    with pytest.raises(ValueError, match=r"\(its entries are not those that piga-train-model writes\)"):
        read_checkpoint(tmp_path, RunKind.PIGA)


def test_a_data_file_whose_metadata_is_damaged_is_said_in_words(tiny_data: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Bytes flipped in a data file's attributes left HDF5's own error: exit 70, "internal error (RuntimeError: Error
    iterating over attributes (ran off end of input buffer while decoding))"."""
    from piga.data.schema import DataFormatError, inspect_dataset

    damaged = bytearray(tiny_data.read_bytes())
    for i in range(3000, 40000, 97):
        damaged[i] ^= 0xFF
    path = tmp_path / "damaged.h5"
    path.write_bytes(bytes(damaged))
    with pytest.raises(DataFormatError) as error:
        inspect_dataset(path)
    assert f"{path}: not a readable HDF5 file (damaged: it opens, but its attributes" in str(error.value), error.value
    assert not EXCEPTION_NAME.search(str(error.value)), error.value
    refused("piga-show", [str(path), "--out", str(tmp_path / "s.png")], capsys, "not a readable HDF5 file (damaged")


@pytest.mark.parametrize("offset, needle", [
    (800, "its index names /frames, but it cannot be found"),  # "... (to <h5py._hl.group.HardLink object at 0x7f...>)"
    (1505, "it opens, but its attributes or its index of datasets cannot be read"),  # "ValueError: Insufficient precision"
])
def test_a_data_file_with_one_byte_flipped_is_said_in_words(offset: int, needle: str, tmp_path: Path) -> None:
    """Bytes of a collected file's header flipped one at a time (offsets found by flipping each of its first 4000)."""
    from piga.data.collect import CollectConfig, collect
    from piga.data.schema import DataFormatError, inspect_dataset

    path = tmp_path / "d.h5"
    collect(CollectConfig(sequences=12, steps=16, seed=3, workers=1, split=(8, 2, 2)), path, progress=False,
            command="test")
    damaged = bytearray(path.read_bytes())
    damaged[offset] ^= 0xFF
    path.write_bytes(bytes(damaged))
    with pytest.raises(DataFormatError) as error:
        inspect_dataset(path)
    assert f"{path}: not a readable HDF5 file (damaged: {needle}" in str(error.value), error.value
    assert "0x" not in str(error.value) and not EXCEPTION_NAME.search(str(error.value)), error.value


def test_a_broken_metrics_record_is_said_in_words(tmp_path: Path) -> None:
    """It read "metrics.json cannot be read (JSONDecodeError)"."""
    from piga.io.checkpoint import read_run_record
    from piga.io.runs import convergence_warning

    (tmp_path / "metrics.json").write_text("{bad")
    (tmp_path / "config.json").write_bytes(b"\xff\xfe{")
    warning = convergence_warning(tmp_path)
    assert warning == (f"warning: {tmp_path / 'metrics.json'} cannot be read (not valid JSON: it breaks off or goes "
                       "wrong at line 1, column 2); whether the run converged is unknown"), warning
    assert read_run_record(tmp_path) == ({}, "cannot be read (not text: its bytes are not UTF-8)")


@pytest.mark.parametrize("edit, needle", [
    (lambda run: (run / "metrics.json").write_text("{}"), "metrics.json does not say whether the run converged"),
    (lambda run: shutil.copyfile(run / "other.pt", run / "checkpoint.pt"), "judged a model of 4 steps, but checkpoint.pt "
                                                                          "holds one of 7 (another run's, or replaced"),
], ids=["empty-metrics", "another-runs-checkpoint"])
def test_a_verdict_that_does_not_judge_the_model_is_not_taken_for_converged(edit: Callable[[Path], None], needle: str,
                                                                           tiny_run: Path, tmp_path: Path) -> None:
    """A metrics.json edited to {} read as converged, and another run's checkpoint put beside a converged run's records
    planned under that run's verdict: both without a word."""
    from piga.io.runs import convergence_warning

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    payload = torch.load(run / "checkpoint.pt", weights_only=False)
    payload["state"]["step"] = 7  # another run's: the tiny run's report judged its 4 steps
    torch.save(payload, run / "other.pt")
    assert json.loads((run / "metrics.json").read_text())["training"]["steps"] == 4
    before = convergence_warning(run)
    assert before is None or "judged" not in before, before
    edit(run)
    warning = convergence_warning(run)
    assert warning is not None and needle in warning and "whether" in warning, warning


@pytest.mark.parametrize("name, needle", [
    ("d.h5", "(it is an HDF5 file, such as piga's data files, which need no import)"),  # "OSError: cannot find loader"
    ("empty.mp4", "(it is empty)"),
    ("broken.mp4", "(damaged, or of a format its reader does not take)"),  # "OSError: Could not load meta information"
    ("text.mp4", "(damaged, or of a format its reader does not take)"),  # it quoted "Could not load meta information"
    # tifffile logged "<tifffile.TiffPages @8> invalid page offset ..." on stderr above the line
    ("cut.tif", "(damaged, or of a format its reader does not take)"),
])
def test_import_says_why_a_recording_cannot_be_read(name: str, needle: str, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    recording = tmp_path / name
    if name.endswith(".h5"):
        with h5py.File(recording, "w") as f:
            f["frames"] = np.zeros((1, 4, 8, 8), np.uint8)
    elif name.endswith(".tif"):  # a 20-page stack cut short
        import imageio.v3 as iio

        iio.imwrite(recording, np.random.default_rng(0).integers(0, 255, (20, 32, 32), dtype=np.uint8))
        recording.write_bytes(recording.read_bytes()[:15000])
    else:
        recording.write_bytes(b"" if name == "empty.mp4" else b"not a video\n" if name == "text.mp4" else
                              b"\0\0\0\x18ftypmp42" + bytes(range(256)) * 8)
    (tmp_path / "u.csv").write_text("u\n" + "0.1\n" * 12)
    line = refused("piga-import", [str(recording), str(tmp_path / "u.csv"), "--dt", "0.05", "--steps", "4", "--out",
                                   str(tmp_path / "o.h5")], capsys, f"{name}: not a readable video or image stack", needle)
    assert not EXCEPTION_NAME.search(line) and "meta information" not in line, line
    assert not (tmp_path / "o.h5").exists()


def test_a_tiff_cut_short_is_one_line_from_a_fresh_process(tmp_path: Path) -> None:
    """tifffile logged "<tifffile.TiffPages @8> invalid page offset ..." through Python's last-resort handler, a line
    on stderr above the command's own (in a fresh process: pytest's own log handlers hide it in this one)."""
    import subprocess
    import sys

    import imageio.v3 as iio

    recording = tmp_path / "cut.tif"
    iio.imwrite(recording, np.random.default_rng(0).integers(0, 255, (20, 32, 32), dtype=np.uint8))
    recording.write_bytes(recording.read_bytes()[:15000])
    (tmp_path / "u.csv").write_text("u\n" + "0.1\n" * 20)
    done = subprocess.run([sys.executable, "-c", "from piga.cli.importer import entry; entry()",
                           str(recording), str(tmp_path / "u.csv"), "--dt", "0.05", "--steps", "4", "--out",
                           str(tmp_path / "o.h5")], capture_output=True, text=True, env={**ENV, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 1 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "tifffile" not in done.stderr and "damaged" in done.stderr, done.stderr


def test_a_tiff_cut_short_that_still_reads_is_refused_as_damaged(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A TIFF stack cut short read as the pages before the cut: imported as half a recording with exit 0 (or the
    actions blamed for the count), and taken whole as a goal image (its first page)."""
    import imageio.v3 as iio

    from piga.data.scene import read_image

    whole = tmp_path / "whole.tif"
    iio.imwrite(whole, np.random.default_rng(0).integers(0, 255, (20, 32, 32), dtype=np.uint8))
    for name, cut in (("end.tif", 0.95), ("middle.tif", 0.6)):
        (tmp_path / name).write_bytes(whole.read_bytes()[: int(whole.stat().st_size * cut)])
    assert iio.imread(tmp_path / "end.tif").shape == (20, 32, 32)  # (the reader takes it, warning on its logger)
    (tmp_path / "u.csv").write_text("u\n" + "0.1\n" * 20)
    line = refused("piga-import", [str(tmp_path / "end.tif"), str(tmp_path / "u.csv"), "--dt", "0.05", "--steps", "4",
                                   "--out", str(tmp_path / "o.h5")], capsys,
                   "end.tif: not a readable video or image stack (damaged: its reader could not find all of it")
    assert "u.csv" not in line and not (tmp_path / "o.h5").exists(), line
    with pytest.raises(ValueError, match=r"middle.tif: not a readable image \(damaged: its reader could not find all"):
        read_image(tmp_path / "middle.tif")


@pytest.fixture(scope="module")
def continuous_run(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-epoch run of the 'continuous' preset's model (RK4 within the frame, a learned damping), finished."""
    from piga.training.report import write_run_report
    from piga.training.train import PRESETS, TrainConfig, train

    run = tmp_path_factory.mktemp("continuous") / "run"
    config = TrainConfig(epochs=1, batch_size=16, warmup_fraction=0.1, curriculum_fraction=0.1, threads=1)
    model_config = replace(PRESETS["continuous"].model, rec_frames="input", pred_frames=4)
    model, state = train(tiny_data, run, config, model_config, progress=False)
    write_run_report(model, state, tiny_data, run)
    return run


@pytest.mark.parametrize("goal", [False, True])
def test_control_refuses_a_continuous_model_before_reading_or_warning(goal: bool, continuous_run: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """It printed the "did not converge" warning, and read --goal-image ("goal read from g15.png: 15.07 deg"), before
    the refusal: two lines for one error."""
    argv = ["--model", str(continuous_run), "--episodes", "1", "--steps", "20", "--quiet"]
    if goal:
        (tmp_path / "goal.png").write_bytes(b"not read: the refusal comes first")
        argv += ["--goal-image", str(tmp_path / "goal.png")]
    refused("piga-control", argv, capsys, f"{continuous_run}: this model integrates within the frame or learned a damping",
            "no env plans it at its frames' rate (0.05 s apart): to control piga/PixelPendulum-v0, train a model with "
            "--preset fast")


def test_a_continuous_model_of_gymnasiums_frames_is_not_sent_back_to_gymnasiums_env(
        continuous_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Each env's refusal pointed to the other, which refused it too."""
    pytest.importorskip("dm_control", reason="needs the optional extra piga[dmc]")
    refused("piga-control", ["--model", str(continuous_run), "--env", "piga/DMCPendulum-v0", "--episodes", "1", "--quiet"],
            capsys, "with --preset continuous, which no env plans at that rate: to control piga/PixelPendulum-v0, train "
            "a model with --preset fast; to control piga/DMCPendulum-v0, train one on its frames")


@pytest.mark.parametrize("axis", ["sequences", "frames"])
@pytest.mark.parametrize("prog", ["piga-show", "piga-train-model"])
def test_frames_that_disagree_with_every_other_array_are_named(axis: str, prog: str, tiny_data: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """It blamed /actions ("/actions must be float [N=6, T=16, A], got float32 (12, 16, 1)") when /frames alone differed."""
    data = tmp_path / "cut.h5"
    shutil.copyfile(tiny_data, data)
    with h5py.File(data, "a") as f:
        frames = f["frames"][:6] if axis == "sequences" else f["frames"][:, :6]
        del f["frames"]
        f["frames"] = frames
    needle = ("/frames holds 6 sequences but /actions, /rewards, /split, /states hold 12" if axis == "sequences" else
              "/frames holds 6 frames per sequence but /actions, /rewards, /states hold 16")
    argv = [str(data), "--out", str(tmp_path / "out.png")] if prog == "piga-show" else [
        str(data), "--out", str(tmp_path / "run"), "--threads", "1", "--quiet"]
    line = refused(prog, argv, capsys, needle)
    assert "/actions must be" not in line and "/actions has shape" not in line, line
