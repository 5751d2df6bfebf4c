"""piga-import: a user's recording (frames or video, plus a CSV of actions) into piga's schema."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import h5py
import imageio.v3 as iio
import numpy as np
import pytest

from piga.cli import importer as cli
from piga.data.collect import CollectConfig, collect
from piga.data.schema import inspect_dataset, read_sequences
from piga.data.importer import ImportConfig, import_recording, read_actions, read_recording
from piga.data.scene import scene_to_gray
from tests.helpers import ENV, assert_one_line, assert_one_line_error, run_in_process

PROG = "piga-import"


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """A collected file written out as a user's recording: a folder of 17 PNGs and a CSV.

    Returns the folder, the CSV, and the frames (17, 64, 64) and actions (17,) they hold.
    """
    root = tmp_path_factory.mktemp("recording")
    data = collect(CollectConfig(sequences=3, steps=6, seed=4, workers=1, split=(1, 1, 1)), root / "c.h5",
                   progress=False, command="t")
    with h5py.File(data, "r") as f:
        frames = f["frames"][()].reshape(-1, 64, 64)[:17]  # 3 sequences of 5 frames, 2 left over
        actions = f["actions"][()].reshape(-1)[:17]
    folder = root / "frames"
    folder.mkdir()
    for i, frame in enumerate(frames):  # f2 before f10: natural order, not plain string order
        iio.imwrite(folder / f"f{i}.png", frame)
    csv = root / "actions.csv"
    csv.write_text("time,u\n" + "".join(f"{i * 0.05:.2f},{float(u)!r}\n" for i, u in enumerate(actions)))
    return folder, csv, frames, actions


def _cli(*argv: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    return run_in_process(PROG, cli.main, *argv, capsys=capsys)


def test_round_trip_through_the_script(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray]) -> None:
    folder, csv, frames, actions = recording
    out = tmp_path / "imported.h5"
    result = subprocess.run([PROG, str(folder), str(csv), "--dt", "0.05", "--out", str(out), "--steps", "5",
                             "--split", "1,1,1"], capture_output=True, text=True, env=ENV, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "3 sequences x 5 frames" in result.stdout and "the last 2 of 17 frames" in result.stdout
    info = inspect_dataset(out)
    assert (info.n_sequences, info.steps, info.image_shape, info.action_dim) == (3, 5, (64, 64), 1)
    assert not info.has_states and info.system == "pendulum" and info.dt == 0.05 and info.params == {}
    assert info.split_counts == {"train": 1, "valid": 1, "test": 1}
    assert info.attrs["seed"] == -1 and info.attrs["source"] == str(folder) and info.attrs["source_actions"] == str(csv)
    assert info.attrs["source_frames"] == 17 and info.attrs["dropped_frames"] == 2
    assert info.attrs["command"].startswith("piga-import ")
    got = np.concatenate([read_sequences(out, split)[0] for split in ("train", "valid", "test")])
    got_u = np.concatenate([read_sequences(out, split)[1] for split in ("train", "valid", "test")])
    assert got.reshape(-1, 64, 64).tobytes() == frames[:15].tobytes()  # exactly the frames, in recording order
    assert got_u.reshape(-1).tobytes() == actions[:15].tobytes()


def test_video_files(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray]) -> None:
    _, csv, frames, _ = recording
    gif = tmp_path / "r.gif"
    iio.imwrite(gif, frames)
    # a GIF comes back as RGB; Gymnasium's gray weights then truncate a few gray levels by one
    assert np.abs(read_recording(gif, 64).astype(int) - frames).max() <= 1
    mp4 = tmp_path / "r.mp4"
    iio.imwrite(mp4, np.repeat(frames[..., None], 3, axis=-1), fps=20)
    result = import_recording(mp4, csv, tmp_path / "v.h5", ImportConfig(dt=0.05, steps=8), command="t")
    assert (result.sequences, result.source_frames, result.dropped_frames) == (2, 17, 1)
    got = read_sequences(tmp_path / "v.h5", "train")[0]
    assert np.abs(got.reshape(-1, 64, 64).astype(int) - frames[:16]).mean() < 4  # lossy, but the same pictures


def test_a_video_whose_rate_disagrees_with_dt_is_said(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A 20 fps MP4 imported with --dt 0.1 was taken silently; its physics then stepped twice the time per frame."""
    from piga.data.importer import recording_frame_seconds

    folder, csv, frames, _ = recording
    mp4, gif = tmp_path / "r.mp4", tmp_path / "r.gif"
    iio.imwrite(mp4, np.repeat(frames[..., None], 3, axis=-1), fps=20)
    iio.imwrite(gif, frames, duration=100)
    assert recording_frame_seconds(mp4) == pytest.approx(0.05) and recording_frame_seconds(gif) == pytest.approx(0.1)
    assert recording_frame_seconds(folder) is None
    code, _, err = _cli(str(mp4), str(csv), "--dt", "0.1", "--out", str(tmp_path / "a.h5"), "--steps", "8", "--split",
                        "1,1,0", capsys=capsys)
    assert code == 0 and err == f"piga-import: warning: {mp4} says its frames are 0.05 s apart; the file takes --dt 0.1, " \
                                "as given, and the physics steps that long per frame\n", err
    code, _, err = _cli(str(mp4), str(csv), "--dt", "0.05", "--out", str(tmp_path / "b.h5"), "--steps", "8", "--split",
                        "1,1,0", capsys=capsys)
    assert code == 0 and err == ""


def test_import_warns_of_an_empty_split_as_collect_does(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """piga-import and piga-collect give the same line where a split's share rounds to no sequence (but for its advice,
    in each command's own options), and both take a split given as 0 (--split 0.5,0.5,0) as asked, without a word."""
    from piga.cli import collect as collect_cli

    folder, csv, _, _ = recording
    for split, warned in (("0.8,0.1,0.1", True), ("0.5,0.5,0", False)):
        code, _, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(tmp_path / "i.h5"), "--steps", "5",
                            "--split", split, "--overwrite", capsys=capsys)
        assert code == 0, err
        code, _, collected = run_in_process("piga-collect", collect_cli.main, "--out", str(tmp_path / "c.h5"), "--sequences",
                                            "3", "--steps", "4", "--workers", "1", "--split", split, "--overwrite",
                                            "--quiet", capsys=capsys)
        assert code == 0, collected
        said = [line.rsplit(" (", 1)[0] for line in (err.replace("piga-import", "piga-collect"), collected)]
        assert said[0] == said[1], (err, collected)
        assert ("--steps 2 or fewer" in err) == warned and ("give 6 sequences" in collected) == warned, (err, collected)
        assert ("leaves valid and test empty" in err) is warned, err


def test_an_image_stack_is_a_recording(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A multi-page TIFF, which imageio reads as one array (T, H, W), gray or colour, is T frames; an array that is
    no frames says what piga-import takes."""
    _, csv, frames, _ = recording
    gray, rgb = tmp_path / "gray.tif", tmp_path / "rgb.tif"
    iio.imwrite(gray, frames)
    iio.imwrite(rgb, np.repeat(frames[..., None], 3, axis=-1))
    assert read_recording(gray, 64).tobytes() == frames.tobytes()
    assert np.abs(read_recording(rgb, 64).astype(int) - frames).max() <= 1
    code, out, err = _cli(str(gray), str(csv), "--dt", "0.05", "--out", str(tmp_path / "o.h5"), "--steps", "5",
                          "--split", "1,1,1", capsys=capsys)
    assert code == 0 and err == "" and "3 sequences x 5 frames" in out
    np.savez(tmp_path / "x.npz", a=np.zeros(5))
    assert_one_line(*_cli(str(tmp_path / "x.npz"), str(csv), "--dt", "0.05", "--out", str(tmp_path / "n.h5"),
                          capsys=capsys)[::2], "x.npz: holds an array of shape (5,), not frames",
                    "a video file, an image stack such as a multi-page TIFF, or a folder of .png/.jpg frames")


def test_frames_are_converted_as_the_env_converts_its_render(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    pictures = rng.integers(0, 256, size=(4, 90, 120, 3), dtype=np.uint8)  # wide RGB, any size
    folder = tmp_path / "rgb"
    folder.mkdir()
    for i, picture in enumerate(pictures):
        iio.imwrite(folder / f"frame_{i:03d}.png", picture)
    got = read_recording(folder, 32)
    assert got.shape == (4, 32, 32) and got.dtype == np.uint8
    for frame, picture in zip(got, pictures):
        assert frame.tobytes() == scene_to_gray(picture, 32).tobytes()


@pytest.mark.parametrize(
    "text, want",
    [
        ("0.5\n-1\n2\n", [0.5, -1, 2]),
        ("Action\n0.5\n-1\n2\n", [0.5, -1, 2]),  # one column under its header
        ("t,action,other\n0,0.5,9\n1,-1,9\n2,2,9\n\n \n", [0.5, -1, 2]),  # blank lines at the end: the file's end
        ("\n\n# recorded at 20 Hz\nu\n0.5\n-1\n# the end\n", [0.5, -1]),  # blank and # lines before the header, at the end
        ("\ufeffu;t\n0.5;0\n-1;1\n2;2\n", [0.5, -1, 2]),  # a BOM, semicolons
        ("U\t t\n0.5\t0\n-1\t1\n2\t2\n", [0.5, -1, 2]),
        ("0.5,\n-1,\n2,\n", [0.5, -1, 2]),  # every row ends in a separator: data, not a header ['0.5', '']
        ("u;\n0.5;\n-1;\n", [0.5, -1]),
        ("2E0\n+2\n.5\n-1.\n", [2, 2, 0.5, -1]),  # the decimal spellings a CSV writer uses
    ],
)
def test_read_actions(tmp_path: Path, text: str, want: list[float]) -> None:
    path = tmp_path / "a.csv"
    path.write_text(text, encoding="utf-8")
    got = read_actions(path)
    assert got.dtype == np.float32 and got.tolist() == want


@pytest.mark.parametrize(
    "text, needle",
    [
        ("", "empty"),
        ("u\n", "header and no values"),
        ("0.5\nfast\n", "line 2: expected a finite number, got 'fast'"),
        ("u\n0.5\nnan\n", "line 3: expected a finite number, got 'nan'; write the action there"),
        ("u\n0.5\n-Infinity\n", "line 3: expected a finite number, got '-Infinity'; write the action there"),
        # beyond float64: read as inf, and told to write it in decimal digits, which it was
        ("u\n0.5\n1e400\n", "line 3: the action 1e400 is beyond ±1e+06 (the pendulum's torque is at most ±2)"),
        ("u\n-1E+999\n", "line 2: the action -1E+999 is beyond ±1e+06"),
        ("1,2\n3,4\n", "one number with a decimal comma or two columns of integers"),
        ("1,2,3\n3,4,5\n", "3 columns and no header row"),
        # a European locale's decimal comma: it was "2 columns ... add a header", and the header then "2 column(s),
        # but line 1 has 1"
        ("-0,5123\n0,25\n", "write numbers with a decimal point"),
        ("u\n-0,5123\n0,25\n", "line 2: '-0,5123', as every row, is one number with a decimal comma"),
        ("a,b\n1,2\n", "names no column 'u' or 'action'"),
        ("u,U\n1,2\n", "names 'u' more than once"),  # the first column was taken
        ("t,u\n0,1\n1\n", "line 3: 1 column(s), but line 1 has 2"),
        # a first line that is no number is a header only where it names the column as --help says
        ("abc\nabc\n", "line 1: expected a finite number or a header naming the column 'u' or 'action', got 'abc'"),
        ("torque\n0.5\n", "line 1: expected a finite number or a header naming the column 'u' or 'action', got 'torque'"),
        ("1_0\n", "line 1: expected a finite number, got '1_0'"),  # float() reads 10: no CSV writer means it
        ("0.5\n\u0661\n", "line 2: expected a finite number, got '\u0661'"),  # an Arabic-Indic 1
        ("u\n\uff11\n", "line 2: expected a finite number, got '\uff11' (write it in ASCII decimal digits"),  # fullwidth
        ("u,action\n1,2\n", "names both 'u' and 'action'; name one action column"),  # `u` was taken silently
        ("0.1,,0.3\n", "3 columns and no header row"),  # an empty field is not a header's name
        # a blank line before a value: a missing action there shifted every later one by a frame (or, where the count
        # no longer matched the frames, read only "has 47 actions but ... has 48 frames")
        ("0.5\n\n-1\n", "line 2 is empty, and actions follow it (line 3): a missing value would shift every later "
                         "action by one frame"),
        ("u\n0.5\n \n# a gap\n-1\n\n", "line 3 is empty, and actions follow it (line 5)"),
        # a # line before a value: an action commented out there shifted every later one by a frame, without a word
        ("# my actions\n0.5\n-1\n", "line 1 is a comment ('# my actions'), and actions follow it (line 2): a "
                                      "commented-out action would shift every later action by one frame; delete the line"),
        ("u\n0.5\n#0.53\n-1\n", "line 3 is a comment ('#0.53'), and actions follow it (line 4)"),
        ("u\n\n0.5\n", "line 2 is empty, and actions follow it (line 3)"),
        ("\n0.5\n-1\n", "line 1 is empty, and actions follow it (line 2)"),
    ],
)
def test_read_actions_errors(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "a.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        read_actions(path)
    assert needle in str(info.value), str(info.value)


def test_import_config_is_checked() -> None:
    for bad in [{"dt": 0.0}, {"dt": -0.1}, {"dt": float("nan")}, {"dt": 0.05, "steps": 1}, {"dt": 0.05, "image_size": 4}]:
        with pytest.raises(ValueError, match=next(iter(k for k in bad if k != "dt"), "dt")):
            ImportConfig(**bad)  # type: ignore[arg-type]


@pytest.mark.filterwarnings("ignore:The legacy `DICOM` plugin:DeprecationWarning")  # imageio probing junk.mp4
def test_cli_bad_input(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                       capsys: pytest.CaptureFixture[str]) -> None:
    folder, csv, _, _ = recording
    out = str(tmp_path / "o.h5")

    def run(*argv: str) -> tuple[int, str]:
        code, _, err = _cli(*argv, capsys=capsys)
        return code, err

    assert_one_line(*run(str(tmp_path / "absent"), str(csv), "--dt", "0.05", "--out", out),
                     "absent", "no such video file or frame folder")
    assert_one_line(*run(str(folder), str(tmp_path / "absent.csv"), "--dt", "0.05", "--out", out),
                     "no such actions file")
    junk_video = tmp_path / "junk.mp4"
    junk_video.write_text("not a video")
    assert_one_line(*run(str(junk_video), str(csv), "--dt", "0.05", "--out", out), "junk.mp4", "not a readable video or image stack")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert_one_line(*run(str(empty), str(csv), "--dt", "0.05", "--out", out), "no frames")
    broken = tmp_path / "broken"
    broken.mkdir()
    iio.imwrite(broken / "a0.png", np.zeros((8, 8), np.uint8))
    (broken / "a1.png").write_text("not a picture")
    assert_one_line(*run(str(broken), str(csv), "--dt", "0.05", "--out", out), "a1.png", "not a readable image")
    words = tmp_path / "words.csv"
    words.write_text("u\n0.1\nleft\n")
    assert_one_line(*run(str(folder), str(words), "--dt", "0.05", "--out", out), "words.csv", "line 3", "'left'")
    short = tmp_path / "short.csv"
    short.write_text("0.1\n" * 12)
    assert_one_line(*run(str(folder), str(short), "--dt", "0.05", "--out", out), "12 actions", "17 frames")
    assert_one_line(*run(str(folder), str(csv), "--dt", "0.05", "--out", out, "--steps", "18"),
                     "17 frames", "one sequence of 18 frames")
    code, err = run(str(folder), str(csv), "--dt", "0", "--out", out)
    assert_one_line(code, err, "--dt")
    assert code == 1
    assert_one_line(*run(str(folder), str(csv), "--dt", "-0.05", "--out", out), "--dt")
    assert_one_line(*run(str(folder), str(csv), "--out", out), "--dt")
    assert_one_line(*run(str(folder), str(csv), "--dt", "0.05", "--out", out, "--steps", "5", "--split", "0,0,1"),
                     "gives the training split no share")
    assert not Path(out).exists()
    assert list(tmp_path.glob(".*partial*")) == []


def test_cli_refuses_a_gap_in_the_actions_even_where_their_count_matches(
        tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray], capsys: pytest.CaptureFixture[str]) -> None:
    """An empty line between the values was skipped: a value missing there, with one more at the end, shifted every
    later action by a frame and the import succeeded. Empty lines at the end of the file are still its end."""
    folder, csv, _, actions = recording
    values = [f"{float(u)!r}" for u in actions]
    gap = tmp_path / "gap.csv"
    gap.write_text("u\n" + "\n".join(values[:6] + [""] + values[7:] + ["0.0"]) + "\n")
    out = tmp_path / "o.h5"
    code, _, err = _cli(str(folder), str(gap), "--dt", "0.05", "--out", str(out), "--steps", "5", capsys=capsys)
    assert_one_line(code, err, "gap.csv: line 8 is empty, and actions follow it (line 9)")
    assert not out.exists()
    tail = tmp_path / "tail.csv"
    tail.write_text("u\n" + "\n".join(values) + "\n\n\n")
    code, _, err = _cli(str(folder), str(tail), "--dt", "0.05", "--out", str(out), "--steps", "5", capsys=capsys)
    assert code == 0, err


def test_cli_refuses_a_frame_size_that_cannot_fit(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Above piga-collect's largest side the option refuses it; the memory check, before decoding, still names the
    frames that cannot fit."""
    from piga.data.importer import _check_resources

    folder, csv, _, _ = recording
    out = tmp_path / "o.h5"
    code, _, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(out), "--image-size", "2000000", capsys=capsys)
    assert_one_line(code, err, "argument --image-size: expected an integer in [8, 1024]")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="17 frames of 2000000x2000000 needs about .* of memory"):
        _check_resources(17, 2_000_000, 40, out)


def test_the_disk_check_counts_one_slice_of_the_recording(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A 20,000-frame recording at 64x64 was refused on a 64 MiB disk as needing up to 125.3 MiB: the file (39.2 MiB at
    the assumed 2x, with HDF5's own bytes) and the whole recording uncompressed, kept free to be written at once. It is
    written a slice at a time, and the room kept free is one slice as it takes the disk, and HDF5's metadata."""
    import shutil

    from piga.data import importer
    from piga.io.resources import ResourceError

    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real(path)._replace(free=64 * 2**20))
    importer._check_resources(20_000, 64, 40, tmp_path / "o.h5")  # 39.2 MiB + one slice of 8.0 MiB + the metadata's
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real(path)._replace(free=47 * 2**20))
    with pytest.raises(ResourceError, match=r"needs up to 47.3 MiB .*a file of about 39.2 MiB once compressed, and 8.2 "
                                            r"MiB kept free as it writes: about 8.0 MiB for the next sequences"):
        importer._check_resources(20_000, 64, 40, tmp_path / "o.h5")
    assert importer._slice_sequences(40, 64) * 40 * (64 * 64 + 4) <= importer.WRITE_SLICE_BYTES
    assert importer._slice_sequences(40, 1024) == 1  # one sequence larger than a slice is written alone


def test_an_import_written_in_slices_is_the_recording(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """Every sequence lands where the recording has it when each slice holds one sequence."""
    from piga.data import importer

    folder, csv, _, _ = recording
    whole, sliced = tmp_path / "whole.h5", tmp_path / "sliced.h5"
    config = importer.ImportConfig(dt=0.05, steps=4)
    importer.import_recording(folder, csv, whole, config, command="t")
    monkeypatch.setattr(importer, "WRITE_SLICE_BYTES", 1)
    importer.import_recording(folder, csv, sliced, config, command="t")
    with h5py.File(whole) as a, h5py.File(sliced) as b:
        assert a["frames"].shape[0] >= 2
        for key in ("frames", "actions", "split"):
            np.testing.assert_array_equal(a[key][()], b[key][()])


def test_cli_refuses_to_overwrite(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                  capsys: pytest.CaptureFixture[str]) -> None:
    folder, csv, _, _ = recording
    out = tmp_path / "mine.h5"
    out.write_text("precious")
    code, _, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(out), capsys=capsys)
    assert_one_line(code, err, "--overwrite")
    assert out.read_text() == "precious"
    code, stdout, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(out), "--steps", "17", "--overwrite",
                             capsys=capsys)
    assert code == 0, err
    assert inspect_dataset(out).n_sequences == 1 and "note" not in stdout


def test_script_needs_no_torch_and_reports_usage_errors(tmp_path: Path) -> None:
    code = "import sys, piga.cli.importer; print('torch' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV).stdout.strip() == "False"
    assert_one_line_error(subprocess.run([PROG], capture_output=True, text=True, env=ENV, timeout=60), "required")


@pytest.mark.parametrize("size, enlarged", [(64, False), (32, False), (96, True)])
def test_frames_enlarged_beyond_the_recording_are_noted(tmp_path: Path, recording: tuple[Path, Path, np.ndarray,
                                                        np.ndarray], capsys: pytest.CaptureFixture[str], size: int,
                                                        enlarged: bool) -> None:
    """64 px frames imported at --image-size 96 were upsampled without a word: the file looks sharper than it is."""
    folder, csv, _, _ = recording
    code, out, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(tmp_path / "d.h5"), "--steps", "5",
                          "--image-size", str(size), "--split", "1,1,1", capsys=capsys)
    assert code == 0 and err == ""
    assert ("note: the recording's frames are 64 px on their short side, so they were enlarged to 96 px, which adds no "
            "detail (--image-size 64 keeps them as recorded)" in out) == enlarged


def test_frames_smaller_than_the_smallest_size_are_not_advised_a_smaller_one(
        tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray], capsys: pytest.CaptureFixture[str]) -> None:
    """2 px frames at --image-size 8 were advised "a smaller --image-size keeps them as recorded", below the smallest."""
    from piga.data.schema import MIN_IMAGE_SIZE

    _, csv, frames, _ = recording
    folder = tmp_path / "tiny"
    folder.mkdir()
    for i, frame in enumerate(frames):
        iio.imwrite(folder / f"f{i}.png", frame[::32, ::32])  # (2, 2)
    code, out, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(tmp_path / "d.h5"), "--steps", "5",
                          "--image-size", str(MIN_IMAGE_SIZE), "--split", "1,1,1", capsys=capsys)
    assert code == 0 and err == "", err
    assert (f"so they were enlarged to {MIN_IMAGE_SIZE} px, which adds no detail ({MIN_IMAGE_SIZE} px, the smallest "
            "--image-size, is as close as piga reads them)") in out, out


@pytest.mark.parametrize("random", [False, True])
def test_a_stack_with_a_page_of_another_size_is_refused(random: bool, tmp_path: Path,
                                                       recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A multi-page TIFF with one page of another size: the pendulum's frames read "damaged ... incompatible
    keyframe" (tifffile's words), random ones were read with the page enlarged to the rest without a word; a folder of
    such frames is refused as one that shares no size."""
    from PIL import Image

    _, csv, frames, _ = recording
    pixels = np.random.default_rng(0).integers(0, 255, frames.shape, dtype=np.uint8) if random else frames
    pages = [Image.fromarray(x) for x in pixels]
    pages[5] = pages[5].resize((32, 32))
    pages[0].save(tmp_path / "mixed.tif", save_all=True, append_images=pages[1:])
    code, _, err = _cli(str(tmp_path / "mixed.tif"), str(csv), "--dt", "0.05", "--out", str(tmp_path / "d.h5"),
                        "--steps", "5", capsys=capsys)
    assert code == 1 and err.count("\n") == 1, err
    assert "5 is 32x32" in err and "0 is 64x64" in err and "the frames of one recording share one size" in err, err
    assert not (tmp_path / "d.h5").exists()


def test_a_crop_to_a_square_is_noted(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A tall recording lost its top and bottom to the centre crop without a word (the help says "centre crop")."""
    folder, csv, frames, _ = recording
    tall = tmp_path / "tall"
    tall.mkdir()
    for i, frame in enumerate(frames):
        iio.imwrite(tall / f"f{i}.png", np.pad(frame, ((16, 16), (0, 0)), mode="edge"))  # 64 wide, 96 high
    for source, said in ((tall, "64x96 px (width x height); their centre square was kept, cutting 32 px in all from "
                                "its top and bottom"), (folder, None)):
        code, out, err = _cli(str(source), str(csv), "--dt", "0.05", "--out", str(tmp_path / f"{source.name}.h5"),
                              "--steps", "5", "--split", "1,1,1", capsys=capsys)
        assert code == 0 and err == "", err
        assert (said in out) if said else "centre square" not in out, out


@pytest.mark.parametrize("levels, said", [((0,), "one flat level, 0"), ((0, 37, 74), "each one flat level, from 0 to 74")])
def test_a_blank_recording_is_named_not_the_file_never_written(levels: tuple[int, ...], said: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """The line named the output (never written), said "one flat level, 0" of frames whose level changes from frame
    to frame, and gave a simulation's advice (the objects' size and colours)."""
    folder = tmp_path / "flat"
    folder.mkdir()
    for i in range(12):
        iio.imwrite(folder / f"f{i}.png", np.full((64, 64), levels[i % len(levels)], np.uint8))
    csv = tmp_path / "a.csv"
    csv.write_text("".join(f"{0.1 * (i % 3)}\n" for i in range(12)))
    out = tmp_path / "out.h5"
    code, _, err = _cli(str(folder), str(csv), "--dt", "0.05", "--steps", "4", "--out", str(out), capsys=capsys)
    line = assert_one_line(code, err, f"{folder}: every frame is blank ({said})", "check the recording")
    assert str(out) not in line and "colours" not in line and not out.exists()


def test_a_still_recording_and_too_few_frames_are_said_of_the_recording(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A frozen recording was blamed on the output file (never written); one frame was told "(lower steps)", and
    --steps 1 is refused."""
    still = tmp_path / "still.tif"
    iio.imwrite(still, np.repeat(np.random.default_rng(0).integers(0, 255, (1, 64, 64), dtype=np.uint8), 12, 0))
    csv = tmp_path / "a.csv"
    csv.write_text("".join(f"{0.1 * (i % 3)}\n" for i in range(12)))
    out = tmp_path / "out.h5"
    code, _, err = _cli(str(still), str(csv), "--dt", "0.05", "--steps", "4", "--out", str(out), capsys=capsys)
    assert str(out) not in assert_one_line(code, err, f"{still}: nothing moves", "check the recording")
    code, _, err = _cli(str(still), str(csv), "--dt", "0.05", "--steps", "20", "--out", str(out), capsys=capsys)
    assert_one_line(code, err, f"{still} has 12 frames, too few for one sequence of 20 frames (lower --steps to 12)")
    one = tmp_path / "one.tif"
    iio.imwrite(one, np.zeros((1, 64, 64), np.uint8) + np.arange(64, dtype=np.uint8))
    (tmp_path / "one.csv").write_text("0.5\n")
    code, _, err = _cli(str(one), str(tmp_path / "one.csv"), "--dt", "0.05", "--steps", "2", "--out", str(out),
                        capsys=capsys)
    assert_one_line(code, err, "has 1 frame, too few for one sequence of 2 frames (a recording needs at least 2)")
    assert not out.exists()


def test_a_pipe_named_as_a_frame_is_refused(tmp_path: Path, recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A FIFO named f0099b.png in the frame folder was skipped: 200 frames written, one of them missing, rc 0."""
    import os
    import shutil

    folder, csv, _, _ = recording
    copy = Path(shutil.copytree(folder, tmp_path / "frames"))
    os.mkfifo(copy / "f3b.png")
    code, _, err = _cli(str(copy), str(csv), "--dt", "0.05", "--out", str(tmp_path / "d.h5"), "--steps", "5",
                        capsys=capsys)
    assert_one_line(code, err, "f3b.png: is not a regular file (a pipe, a socket or a device), though named as a frame")
    assert not (tmp_path / "d.h5").exists()


@pytest.mark.parametrize("steps, advice", [
    ("17", "(cut the recording into 6 sequences or more with --steps 2 or fewer, or import a longer one)"),
    ("5", "(cut the recording into 6 sequences or more with --steps 2 or fewer, or import a longer one, or counts "
          "such as --split 1,1,1)"),
])
def test_an_empty_split_is_advised_in_the_imports_terms(steps: str, advice: str, tmp_path: Path,
                                                         recording: tuple[Path, Path, np.ndarray, np.ndarray],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A recording cut into too few sequences for the split was told to "give 6 sequences or more": piga-import has
    no count of sequences, and a shorter --steps is what gives more."""
    folder, csv, _, _ = recording
    code, _, err = _cli(str(folder), str(csv), "--dt", "0.05", "--out", str(tmp_path / "a.h5"), "--steps", steps,
                        capsys=capsys)
    assert code == 0 and err.count("\n") == 1 and err.startswith("piga-import: warning: ") and err.endswith(advice + "\n"), err
    assert "give 6 sequences" not in err
