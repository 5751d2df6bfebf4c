"""Odd but legal input: names with '$', non-UTF-8 locales, dangling links, photos turned by EXIF, see-through pixels."""

from __future__ import annotations

import argparse
import errno
import io
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from piga.data.scene import read_image, scene_to_gray
from piga.io.atomic import OutputExistsError, check_folder_target, check_writable_target
from tests.helpers import ENV, run_in_process


def test_a_link_to_nothing_is_not_replaced_without_overwrite(tmp_path: Path) -> None:
    """os.replace would replace the link itself, silently, where Path.exists() says there is nothing."""
    link = tmp_path / "d.h5"
    link.symlink_to(tmp_path / "missing.h5")
    with pytest.raises(OutputExistsError, match="a link to a missing file"):
        check_writable_target(link, overwrite=False)
    assert check_writable_target(link, overwrite=True) == link
    folder = tmp_path / "run"
    folder.symlink_to(tmp_path / "gone")
    with pytest.raises(NotADirectoryError, match="does not exist"):
        check_folder_target(folder)


def test_overwrite_replaces_a_link_and_leaves_the_file_it_points_to(tmp_path: Path) -> None:
    """As docs/commands/index.md says: --overwrite of an output that is a symbolic link writes a file in its place."""
    from piga.io.atomic import atomic_output

    target, link = tmp_path / "target.json", tmp_path / "out.json"
    target.write_text("earlier")
    link.symlink_to(target)
    with pytest.raises(OutputExistsError):
        check_writable_target(link, overwrite=False)
    with atomic_output(link, overwrite=True) as tmp:
        tmp.write_text("new")
    assert not link.is_symlink() and link.read_text() == "new" and target.read_text() == "earlier"


def test_a_file_system_that_stores_no_files_is_refused_where_the_target_is_checked() -> None:
    """/proc and /sys are writable to root, yet hold no files: only the commands that also checked the disk said so
    before their work."""
    for folder in ("/proc", "/sys"):
        if not os.path.isdir(folder):
            pytest.skip(f"no {folder}")
        with pytest.raises(PermissionError, match=f"{folder}/x.json cannot be written under {folder}: it is on a file "
                                                  "system that stores no files"):
            check_writable_target(f"{folder}/x.json", overwrite=False)


def test_a_run_folder_name_that_is_not_utf8_in_this_locale_is_refused(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Under LC_ALL=C with PYTHONUTF8=0, 'rün' arrives as lone surrogates, which TensorBoard's writer cannot encode;
    under a UTF-8 locale such a name holds bytes that are not UTF-8, and a UTF-8 locale is no advice. A report, which
    has no TensorBoard logs, takes it."""
    from piga.io import atomic

    odd = tmp_path / "r\udcc3\udcbcn"
    monkeypatch.setattr(atomic, "_locale_name", lambda: "C")
    with pytest.raises(ValueError, match="LC_ALL=C.UTF-8"):
        check_folder_target(odd)
    monkeypatch.setattr(atomic, "_locale_name", lambda: "C.UTF-8")
    with pytest.raises(ValueError, match="holds bytes that are not UTF-8 text") as info:
        check_folder_target(odd)
    assert "locale" not in str(info.value)
    assert check_folder_target(odd, logs=False) == odd
    assert check_folder_target(tmp_path / "rün") == tmp_path / "rün"


def test_the_recorded_command_is_utf8_under_a_c_locale(tmp_path: Path) -> None:
    """The bytes of a non-ASCII name, held as surrogates under a C locale, are recorded as the UTF-8 text typed."""
    code = ("import sys; from piga.cli.common import command_line; "
            "print(ascii(command_line('piga-collect', sys.argv[1:])))")
    env = {**ENV, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    out = subprocess.run([sys.executable, "-c", code, "--out", "lc_ü.h5"], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ascii(shlex.join(["piga-collect", "--out", "lc_ü.h5"]))


def test_a_non_ascii_file_name_under_a_c_locale_is_shown_and_its_pages_written(tiny_data: Path, tmp_path: Path) -> None:
    """Under LC_ALL=C with PYTHONUTF8=0, piga-show's title of 'ü.h5' (held as surrogates) was a TypeError in
    matplotlib (the pages' writes, piga-control's .md among them, are UTF-8 now too: they failed in ASCII)."""
    import shutil

    env = {**ENV, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    shutil.copy(tiny_data, tmp_path / "ü.h5")
    shown = subprocess.run(["piga-show", "ü.h5", "--out", "ü.png"], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert shown.returncode == 0 and shown.stderr == "", shown.stderr
    assert (tmp_path / "ü.png").stat().st_size > 0


def test_a_photo_is_read_turned_as_its_exif_says(tmp_path: Path) -> None:
    from PIL import Image

    picture = np.zeros((20, 30, 3), np.uint8)
    picture[:5] = 255  # a white band at the top of the stored pixels
    image = Image.fromarray(picture)
    exif = image.getexif()
    exif[0x0112] = 3  # orientation: turned 180 degrees
    image.save(tmp_path / "photo.jpg", exif=exif, quality=95)
    seen = read_image(tmp_path / "photo.jpg")  # (20, 30, 3)
    assert seen[:5].mean() < 10 and seen[-5:].mean() > 240  # the band is at the bottom, as a viewer shows it


def test_see_through_pixels_are_refused_and_an_opaque_alpha_is_dropped() -> None:
    rgba = np.full((8, 8, 4), 255, np.uint8)
    assert scene_to_gray(rgba, 4).tolist() == scene_to_gray(rgba[..., :3], 4).tolist()
    rgba[0, 0, 3] = 128
    with pytest.raises(ValueError, match="1 of its 64 pixels are transparent"):
        scene_to_gray(rgba, 4)
    deep = np.full((8, 8, 4), 65535, np.uint16)  # a 16-bit PNG: opaque is 65535
    assert scene_to_gray(deep, 4).shape == (4, 4)


@pytest.mark.parametrize("colour, ok", [("red", True), ("#ff000080", False), ("none", False), ("#00ff00ff", True)])
def test_a_see_through_ball_colour_is_refused(colour: str, ok: bool) -> None:
    from piga.cli.collect import _color

    if ok:
        assert len(_color(colour)) == 3
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="opaque"):
            _color(colour)


def test_a_dollar_in_a_file_name_is_drawn_as_text(tmp_path: Path) -> None:
    """matplotlib reads '$...$' as TeX: 'cost_$x^$.h5' stopped piga-show with a parse error."""
    from piga.cli import collect, show

    data = tmp_path / "cost_$x^$.h5"
    assert collect.main(["--out", str(data), "--sequences", "2", "--steps", "3", "--workers", "1", "--split", "2,0,0",
                         "--quiet"]) == 0
    assert show.main([str(data), "--out", str(tmp_path / "s.png"), "--frames", "2"]) == 0
    assert (tmp_path / "s.png").stat().st_size > 0
    assert os.path.exists(data)


def test_planet_refuses_a_pixel_pendulum_file_whose_env_config_contradicts_its_frames(tmp_path: Path) -> None:
    """piga-control would render frames of env_config's size for a model that learned others."""
    import h5py

    from agents.planet.config import PlanetTrainConfig
    from agents.planet.train import check_planet_data
    from piga.cli import collect
    from piga.data.schema import DataFormatError, inspect_dataset

    data = tmp_path / "d.h5"
    assert collect.main(["--out", str(data), "--sequences", "2", "--steps", "60", "--workers", "1", "--split", "2,0,0",
                         "--quiet"]) == 0
    check_planet_data(inspect_dataset(data), PlanetTrainConfig())  # as collected: accepted
    with h5py.File(data, "a") as f:
        f.attrs["env_config"] = '{"image_size": 32}'
    with pytest.raises(DataFormatError, match="image_size 32"):
        check_planet_data(inspect_dataset(data), PlanetTrainConfig())


def test_a_name_near_the_filesystems_limit_is_written_and_one_beyond_it_is_refused(tmp_path: Path) -> None:
    """The temporary sibling '.NAME.partial-PID' of a 251-byte name was too long to create (an OSError naming the hidden
    file, and a traceback from its cleanup)."""
    from piga.io.atomic import atomic_output, partial_path, remove_stale_partials

    target = tmp_path / ("a" * 251 + ".h5")
    with atomic_output(target) as tmp:
        tmp.write_text("x")
    assert target.read_text() == "x" and len(os.fsencode(partial_path(target).name)) <= 255
    stale = partial_path(target).with_name(partial_path(target).name.rsplit("-", 1)[0] + "-999999999")
    stale.write_text("left by a killed run")
    assert remove_stale_partials(target) == [stale]
    with pytest.raises(ValueError, match="the name is 259 bytes, longer than the 255"):
        check_writable_target(tmp_path / ("b" * 256 + ".h5"), overwrite=False)
    with pytest.raises(ValueError, match="--out .*the name is 256 bytes"):
        check_folder_target(tmp_path / ("c" * 256))


def test_stale_partials_of_a_name_with_glob_characters_are_removed(tmp_path: Path) -> None:
    from piga.io.atomic import partial_path, remove_stale_partials

    target = tmp_path / "run[1].h5"
    stale = partial_path(target).with_name(f".{target.name}.partial-999999999")
    stale.write_text("left by a killed run")
    (tmp_path / ".run1.h5.partial-999999999").write_text("another file's")
    assert remove_stale_partials(target) == [stale]
    assert (tmp_path / ".run1.h5.partial-999999999").exists()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="a zombie is told apart through Linux's /proc")
def test_the_partial_file_of_a_zombie_writer_is_removed(tmp_path: Path) -> None:
    """A rerun right after `timeout -s KILL` kept `.k4.h5.partial-PID`: the killed writer was a zombie, not yet reaped,
    and kill(PID, 0) still found it."""
    import subprocess
    import time

    from piga.io.atomic import partial_path, remove_stale_partials

    target = tmp_path / "k4.h5"
    child = subprocess.Popen(["true"])  # not waited for: a zombie once it exits
    try:
        deadline = time.monotonic() + 10
        while Path(f"/proc/{child.pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z":
            assert time.monotonic() < deadline, "the child did not exit"
            time.sleep(0.01)
        stale = partial_path(target).with_name(partial_path(target).name.rsplit("-", 1)[0] + f"-{child.pid}")
        stale.write_text("left by a killed run")
        alive = partial_path(target).with_name(partial_path(target).name.rsplit("-", 1)[0] + f"-{os.getppid()}")
        alive.write_text("a running writer's")
        assert remove_stale_partials(target) == [stale]
        assert alive.exists()
    finally:
        child.wait()


@pytest.mark.parametrize("hard_links", [True, False])
def test_a_file_that_appears_while_writing_is_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  hard_links: bool) -> None:
    """Two commands given one output both found it free: the second to finish is refused, and the first's file stays
    (with hard links the refusal is one atomic step; without them, as on FAT, a check just before the rename)."""
    from piga.io.atomic import atomic_output

    if not hard_links:
        def no_links(*args: object) -> None:
            raise PermissionError(errno.EPERM, "Operation not permitted")
        monkeypatch.setattr(os, "link", no_links)
    target = tmp_path / "out.h5"
    with pytest.raises(OutputExistsError, match="appeared while writing; pass --overwrite"):
        with atomic_output(target) as tmp:
            tmp.write_text("second")
            target.write_text("first")
    assert target.read_text() == "first" and os.listdir(tmp_path) == ["out.h5"]
    with atomic_output(tmp_path / "new.h5") as tmp:
        tmp.write_text("written")
    assert (tmp_path / "new.h5").read_text() == "written" and sorted(os.listdir(tmp_path)) == ["new.h5", "out.h5"]
    with atomic_output(target, overwrite=True) as tmp:
        tmp.write_text("replaced")
    assert target.read_text() == "replaced"


@pytest.mark.parametrize("shift, ok", [(31, True), (-31, True), (32, False), (-63, False)])
def test_a_shift_that_moves_the_pivot_out_of_the_frame_is_refused(shift: float, ok: bool) -> None:
    """shift=-63 passed the old check (|shift| < 64), collected, and then every frame was blank."""
    from envs.pendulum import PixelPendulumConfig

    if ok:
        PixelPendulumConfig(effects=(("shift", shift),))
    else:
        with pytest.raises(ValueError, match="its pivot out of view"):
            PixelPendulumConfig(effects=(("shift", shift),))


def test_an_output_that_is_an_input_is_refused_even_with_overwrite(tmp_path: Path) -> None:
    """piga-import --out ACTIONS.csv --overwrite replaced the actions it read."""
    from piga.io.atomic import check_not_an_input

    actions = tmp_path / "a.csv"
    actions.write_text("0.5\n")
    (tmp_path / "link.csv").symlink_to(actions)
    with pytest.raises(ValueError, match="is the actions file"):
        check_not_an_input(tmp_path / "link.csv", {"recording": tmp_path / "v.mp4", "actions file": actions})
    check_not_an_input(tmp_path / "new.h5", {"actions file": actions})  # another path: accepted


def test_a_folder_name_on_the_way_beyond_the_limit_is_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="a folder's name on the way is 300 bytes"):
        check_writable_target(tmp_path / ("d" * 300) / "x.h5", overwrite=False)


def test_too_few_windows_names_a_stride_that_was_raised() -> None:
    """--window-stride 1000 left 16 windows, and the refusal blamed only the batch size and the data."""
    from piga.training.train import TrainConfig, plan_training

    with pytest.raises(ValueError, match=r"or lower --window-stride \(now 1000\)"):
        plan_training(TrainConfig(window_stride=1000), 16)
    with pytest.raises(ValueError, match=r"give more data$"):
        plan_training(TrainConfig(), 16)
    # sequences one window long give one window at any stride: a bouncing file of 10 x 10 frames at the scene
    # preset's stride of 2 was told to lower it
    with pytest.raises(ValueError, match=r"give more data$"):
        plan_training(TrainConfig(window_stride=2), 8, layout=(8, 1))
    with pytest.raises(ValueError, match=r"or lower --window-stride to 1 or less \(now 2\)"):
        plan_training(TrainConfig(window_stride=2), 16, layout=(16, 2))


@pytest.mark.parametrize("sequences, starts, stride", [(20, 27, 20), (20, 27, 12), (3, 100, 50), (32, 5, 5), (1, 80, 9)])
def test_the_stride_named_for_too_few_windows_fills_a_batch(sequences: int, starts: int, stride: int) -> None:
    """A batch of 64 on 20 sequences of 27 start frames at a stride of 20: told only to lower the stride, a user who
    tried 12 was refused again (every stride from 14 to 26 gives 40 windows, 12 and 13 give 60)."""
    import re

    from piga.training.train import TrainConfig, plan_training

    config = TrainConfig(window_stride=stride, batch_size=64)
    windows = sequences * len(range(0, starts, stride))
    with pytest.raises(ValueError, match=r"lower --window-stride to (\d+) or less") as info:
        plan_training(config, windows, layout=(sequences, starts))
    most = int(re.search(r"to (\d+) or less", str(info.value)).group(1))
    assert sequences * len(range(0, starts, most)) >= 64  # it fills a batch
    assert sequences * len(range(0, starts, most + 1)) < 64  # and is the largest that does


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_full_standard_output_is_reported_after_the_files_are_complete(tmp_path: Path) -> None:
    """`> /dev/full` made the last 'wrote' line fail after the file was written: exit 1 with a disk-full line, and
    the user (told nothing was saved) had the identical rerun refused as 'exists'. The line now says what failed."""
    out = tmp_path / "d.h5"
    with open("/dev/full", "w") as full:
        done = subprocess.run(["piga-collect", "--sequences", "2", "--steps", "8", "--out", str(out)],
                              stdout=full, stderr=subprocess.PIPE, text=True, env=ENV)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1] == ("piga-collect: error: could not write to standard output (No space "
                                                   "left on device); the command itself finished and its outputs are complete")
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr
    import h5py

    with h5py.File(out) as f:
        assert f["frames"].shape[:2] == (2, 8)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_full_standard_error_loses_the_progress_bar_not_the_work(tmp_path: Path) -> None:
    """`2> log` on a full disk: the progress bar's write failed, and collect (and training) stopped with exit 1,
    its file removed, nothing said anywhere. The work now goes on; what stderr would have shown is dropped."""
    import h5py

    out = tmp_path / "d.h5"
    with open("/dev/full", "w") as full:
        done = subprocess.run(["piga-collect", "--sequences", "2", "--steps", "8", "--workers", "1", "--out", str(out)],
                              stdout=subprocess.PIPE, stderr=full, text=True, env=ENV)
    assert done.returncode == 0 and done.stdout.startswith(f"wrote {out}")
    with h5py.File(out) as f:
        assert f["frames"].shape[:2] == (2, 8)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_help_onto_a_full_standard_output_is_not_a_silent_success() -> None:
    """argparse's exit after --help passed by the check: `--help > /dev/full` exited 0 with nothing shown."""
    with open("/dev/full", "w") as full:
        done = subprocess.run(["piga-collect", "--help"], stdout=full, stderr=subprocess.PIPE, text=True, env=ENV)
    assert done.returncode == 1
    assert done.stderr.strip() == "piga-collect: error: could not write to standard output (No space left on device)"


class _FullStream(io.StringIO):
    """A standard output whose every write fails as a full disk does."""

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("returned, expected", [(None, 1), (0, 1), (3, 3)])
def test_a_lost_standard_output_keeps_the_commands_own_failure(monkeypatch: pytest.MonkeyPatch,
                                                               capsys: pytest.CaptureFixture[str],
                                                               returned: int | None, expected: int) -> None:
    """A run that did not converge exits 3; with its stdout lost too it exited 1, hiding that."""
    from piga.cli.common import run_cli

    def main(argv: object) -> int | None:
        print("trained")
        return returned

    monkeypatch.setattr(sys, "stdout", _FullStream())
    with pytest.raises(SystemExit) as exit_:
        run_cli("piga-x", main, [])
    assert exit_.value.code == expected
    assert capsys.readouterr().err.strip().endswith("could not write to standard output (No space left on device); "
                                                    "the command itself finished and its outputs are complete")


def test_output_after_a_failed_write_is_dropped_and_the_failure_kept() -> None:
    from piga.cli.common import _GuardedStream

    class Failing:
        def __init__(self) -> None:
            self.written: list[str] = []

        def write(self, text: str) -> int:
            if len(self.written) == 1:
                raise OSError(28, "No space left on device")
            self.written.append(text)
            return len(text)

        def flush(self) -> None:
            pass

    stream = Failing()
    guard = _GuardedStream(stream)
    assert guard.write("a") == 1 and guard.failed is None
    assert guard.write("b") == 1 and guard.failed is not None and guard.failed.errno == 28
    guard.write("c")
    guard.flush()
    assert stream.written == ["a"]


@pytest.mark.parametrize("closed", [">&-", "2>&-", "<&-"])
def test_a_closed_standard_stream_drops_what_it_would_show(tmp_path: Path, closed: str) -> None:
    """Started with stdout closed, Python's sys.stdout is None: the 'wrote' line was an internal error (exit 70)
    after the file was written. Each closed stream is now the null device."""
    out = tmp_path / "d.h5"
    command = f"piga-collect --sequences 2 --steps 8 --out {shlex.quote(str(out))} {closed}"
    done = subprocess.run(["sh", "-c", command], capture_output=True, text=True, env=ENV)
    assert done.returncode == 0, done.stderr
    assert "internal error" not in done.stderr and out.exists()


def test_a_run_folder_under_a_read_only_folder_is_refused_before_any_work(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """train-model, planet, ddpg and demo printed their plan, worked, then failed with a raw 'OSError: [Errno 30]'
    (a read-only mount stops root too, where a permission bit does not, so os.access is what is asked)."""
    locked = tmp_path / "ro"
    locked.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == locked else real(p, mode))
    with pytest.raises(PermissionError, match=f"--out {locked / 'run' / 'a'}: folder {locked} is not writable"):
        check_folder_target(locked / "run" / "a")
    with pytest.raises(PermissionError, match="is not writable"):
        check_folder_target(locked)  # an existing run folder, to be resumed into
    assert check_folder_target(tmp_path / "free") == tmp_path / "free"


def test_a_deleted_current_folder_is_one_line_before_torch_loads(tmp_path: Path) -> None:
    """In a deleted folder torch's MKL fails to load with a fatal native exit (no Python error), and relative paths
    point nowhere (h5py's raw error): each command says so first."""
    code = "import os; os.chdir('g'); os.rmdir('../g'); from piga.cli.diagnose import entry; entry()"
    (tmp_path / "g").mkdir()
    done = subprocess.run([sys.executable, "-c", code, "--help"], capture_output=True, text=True, env=ENV, cwd=tmp_path)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.strip() == ("piga-diagnose: error: the current folder no longer exists (it was deleted or "
                                   "moved); cd to a folder that exists and run the command again")


def test_ddpg_threads_0_is_torchs_choice_and_a_bad_count_names_its_field() -> None:
    """The parser took --threads 0 (torch's choice, as for PlaNet-style) and the config then refused it with a dump
    of every setting."""
    from agents.sb3.config import SB3Config

    assert SB3Config(threads=0).threads == 0
    with pytest.raises(ValueError, match=r"^SB3Config.threads must be >= 0, got -1$"):
        SB3Config(threads=-1)
    with pytest.raises(ValueError, match=r"^SB3Config.batch_size must be >= 1, got 0$"):
        SB3Config(batch_size=0)


@pytest.mark.slow
def test_help_under_an_ascii_locale_is_printed_with_escapes() -> None:
    """Under LC_ALL=C with PYTHONUTF8=0 stdout is ASCII: '--help' (θ, ·) failed with an encoding error (exit 1)."""
    env = {**ENV, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    done = subprocess.run(["piga-train-model", "--help"], capture_output=True, env=env)
    assert done.returncode == 0 and done.stderr == b"", done.stderr
    assert b"--lr-physics" in done.stdout


def test_a_planet_sequence_of_one_step_names_its_flag() -> None:
    from agents.planet.config import PlanetTrainConfig
    from piga.cli.common import _FLAGS, with_flags

    with pytest.raises(ValueError, match=r"^PlanetTrainConfig.chunk_length must be >= 2 \(a sequence") as info:
        PlanetTrainConfig(chunk_length=1)
    _FLAGS.clear()
    _FLAGS["chunk_length"] = "--chunk-length"
    assert with_flags(str(info.value)).startswith("--chunk-length must be >= 2")
    _FLAGS.clear()


def test_a_failing_background_thread_is_logged_not_printed(capsys: pytest.CaptureFixture[str],
                                                              monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """TensorBoard's writer thread, its folder moved away mid-run, printed 'Exception in thread' and a traceback."""
    import threading

    from piga.cli import common

    monkeypatch.setattr(common, "log_folder", lambda: tmp_path / "logs")

    def main(argv: object) -> int:
        def fail() -> None:
            raise FileNotFoundError("events.out.tfevents")

        thread = threading.Thread(target=fail, name="writer")
        thread.start()
        thread.join()
        return 0

    before = threading.excepthook
    with pytest.raises(SystemExit) as exit_:
        common.run_cli("piga-x", main, [])
    assert exit_.value.code == 0 and capsys.readouterr().err == ""
    (log,) = (tmp_path / "logs").iterdir()
    assert "in thread writer" in log.read_text() and "events.out.tfevents" in log.read_text()
    assert threading.excepthook is before  # restored for whatever runs next in this process


def test_a_quoted_tilde_is_named_not_made(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--out '~/x.h5' (quoted) was told "make it first (mkdir -p ~)", which the shell expands to the home folder."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="the shell did not expand it"):
        check_writable_target("~/x.h5", overwrite=False)
    with pytest.raises(FileNotFoundError, match=r"mkdir -p 'a b'\)"):  # a name with a space, as a shell takes it
        check_writable_target("a b/x.h5", overwrite=False)


def test_a_quoted_tilde_folder_is_named_not_made(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A folder output makes its parents: --out '~/r' (quoted) made a folder named "~" in the working folder, which a
    later `rm -rf ~` to remove it would take for the home folder. A "~" folder that exists is the user's."""
    monkeypatch.chdir(tmp_path)
    for out in ("~/r", "~", "~user/r"):
        with pytest.raises(FileNotFoundError, match=f"--out {out}: '~' is a folder's name here, as the shell did not"):
            check_folder_target(out)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "~").mkdir()
    assert check_folder_target("~/r") == Path("~/r")


@pytest.mark.parametrize("command", ["piga-train-model", "piga-diagnose", "piga-baseline", "piga-demo"])
def test_a_quoted_tilde_folder_is_refused_by_the_commands_that_make_one(
        command: str, tiny_data: Path, tiny_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import baseline, demo, diagnose, train

    main, argv = {"piga-train-model": (train.main, [str(tiny_data)]),
                  "piga-diagnose": (diagnose.main, ["--model", str(tiny_run), "--data", str(tiny_data)]),
                  "piga-baseline": (baseline.main, ["planet", str(tiny_data), "--chunk-length", "6"]),
                  "piga-demo": (demo.main, [])}[command]
    monkeypatch.chdir(tmp_path)
    code, _, err = run_in_process(command, main, *argv, "--out", "~/r", capsys=capsys)
    assert code == 1 and err.count("\n") == 1 and "the shell did not expand it" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_folder_that_cannot_be_made_on_a_read_only_disk_is_named(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """On a read-only file system, --out ro/sub/x.h5 was told "make it first (mkdir -p ro/sub)", which fails there."""
    class ReadOnly:
        f_flag = os.ST_RDONLY

    monkeypatch.setattr(os, "statvfs", lambda path: ReadOnly())
    with pytest.raises(PermissionError, match=f"{tmp_path} is on a read-only file system"):
        check_writable_target(tmp_path / "sub" / "x.h5", overwrite=False)


@pytest.mark.parametrize("odd, needle", [
    ("actions", "has 2 action columns (a pendulum takes 1): piga-train-model"),
    ("frames", "has 1 frame per sequence (a video needs two): piga-train-model"),
    ("both", "has 2 action columns (a pendulum takes 1) and 1 frame per sequence (a video needs two): piga-train-model"),
    ("wide", "has frames of 64x24 px (a model takes square ones): piga-train-model"),
    ("system", "has the system 'banana', which no model knows (known: bouncing, gravity, pendulum, spring): "
               "piga-train-model"),
    ("spring", "has 1 action column (a spring takes 0): piga-train-model"),
])
def test_show_warns_once_of_what_the_other_commands_refuse(odd: str, needle: str, tiny_data: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """It drew a file of two action columns, or of one frame a sequence, or a pendulum's file labelled 'spring', without
    a word, which every other command refuses."""
    from piga.cli.show import main

    data = tmp_path / "odd.h5"
    shutil.copyfile(tiny_data, data)
    with h5py.File(data, "a") as f:
        for name in ("frames", "actions", "states", "rewards") if odd not in ("system", "spring") else ():
            array = f[name][()]
            if odd == "wide":
                array = array[..., 20:44] if name == "frames" else array
            else:
                if odd != "actions":
                    array = array[:, :1]
                if odd != "frames" and name == "actions":
                    array = np.repeat(array, 2, axis=-1)
            del f[name]
            f[name] = array
        if odd == "wide":  # frames no env rendered (the env_config's 64x64 ones are refused on open)
            del f.attrs["env_config"]
        if odd in ("system", "spring"):  # drawn without a word: it names no model, or one without actions
            f.attrs["system"] = "banana" if odd == "system" else "spring"
    code, out, err = run_in_process("piga-show", main, str(data), "--out", str(tmp_path / "s.png"), capsys=capsys)
    assert code == 0 and (tmp_path / "s.png").exists() and "wrote" in out, err
    assert err.count("\n") == 1 and err.startswith("piga-show: warning: ") and needle in err, err
    assert "drawn all the same" in err, err
