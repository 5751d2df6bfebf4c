"""One command at a time in a run folder: a second one is refused in one line, before it writes anything, and a
lock ends with its command (or its process, however it ends)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from piga.cli import baseline, train
from piga.io.lock import FolderInUseError, lock_run_folder, release_run_folders
from tests.helpers import ENV, assert_one_line, run_in_process

#: A process that locks the folder argv[1] as a command does, says so, and waits to be killed.
HOLDER = "import sys, time; from piga.io.lock import lock_run_folder; lock_run_folder(sys.argv[1]); print('locked', flush=True); time.sleep(300)"


def _hold(folder: Path) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True, env=ENV)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_command_on_a_folder_in_use_is_refused_before_it_writes(tmp_path: Path, tiny_data: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    holder = _hold(out)
    try:
        for prog, main, argv in (("piga-train-model", train.main, [str(tiny_data), "--out", str(out), "--epochs", "1"]),
                                 ("piga-baseline", baseline.main, ["planet", str(tiny_data), "--out", str(out), "--steps", "2", "--chunk-length", "4"]),
                                 ("piga-baseline", baseline.main, ["ddpg", "--obs", "state", "--out", str(out), "--resume"])):
            code, _, err = run_in_process(prog, main, *argv, capsys=capsys)
            assert_one_line(code, err, f"{prog}: error: --out {out} is in use by another piga command (PID {holder.pid}); "
                                       "wait for it to end, or give another --out")
        assert not out.exists()
    finally:
        holder.kill()
        holder.wait()
    lock_run_folder(out)  # the kernel dropped the killed holder's lock
    release_run_folders()


def test_a_lock_is_the_commands_and_ends_with_it(tmp_path: Path) -> None:
    lock_run_folder(tmp_path / "a")
    lock_run_folder(tmp_path / "a")  # the same process again: its own lock
    other = subprocess.run([sys.executable, "-c", HOLDER.replace("time.sleep(300)", "pass"), str(tmp_path / "a")],
                           capture_output=True, text=True, env=ENV)
    assert other.returncode == 1 and "FolderInUseError" in other.stderr and f"PID {__import__('os').getpid()}" in other.stderr
    release_run_folders()
    started = time.monotonic()
    holder = _hold(tmp_path / "a")  # released: another process takes it at once
    holder.kill()
    holder.wait()
    assert time.monotonic() - started < 60
    with pytest.raises(FolderInUseError):
        held = _hold(tmp_path / "b")
        try:
            lock_run_folder(tmp_path / "b" / ".." / "b")  # the same folder by another spelling
        finally:
            held.kill()
            held.wait()


def test_a_run_still_training_is_named_by_the_commands_that_read_it(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """piga-control on a run mid-training scored its last checkpoint as if it were the model, without a word."""
    from piga.cli.common import warn_if_unconverged
    from piga.io.lock import held_by

    run = tmp_path / "run"
    assert held_by(run) is None
    holder = _hold(run)
    try:
        assert held_by(run) == str(holder.pid)
        warn_if_unconverged("piga-control", run)
        said = (f"piga-control: warning: the run {run} is still being trained (PID {holder.pid}); this used its last "
                "checkpoint, not its final model")
        assert capsys.readouterr().err.strip() == said
        # a baseline run too: its "did not learn" read the records of a checkpoint on its way
        from piga.cli.control import _warn_if_did_not_learn
        from piga.io.checkpoint import RunKind

        _warn_if_did_not_learn(str(run), RunKind.DDPG)
        assert capsys.readouterr().err.strip() == said
    finally:
        holder.kill()
        holder.wait()
    assert held_by(run) is None


def test_a_run_started_but_not_yet_checkpointed_is_named_as_such(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """piga-control on a run that holds its folder but has no checkpoint yet asked whether it was a run folder."""
    from piga.cli import control

    run = tmp_path / "run"
    holder = _hold(run)
    try:
        code, _, err = run_in_process("piga-control", control.main, "--model", str(run), "--episodes", "1", "--quiet",
                                      capsys=capsys)
        assert_one_line(code, err, "no checkpoint yet", f"is being trained by another piga command (PID {holder.pid})")
    finally:
        holder.kill()
        holder.wait()


def test_the_lock_holds_across_temporary_folders(tmp_path: Path) -> None:
    """A command run with another TMPDIR (a scheduler gives each job its own) locked in another folder, and both
    commands wrote the run."""
    other = tmp_path / "tmp"
    other.mkdir()
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True,
                            env={**ENV, "TMPDIR": str(other)})
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
        with pytest.raises(FolderInUseError, match=f"PID {proc.pid}"):
            lock_run_folder(tmp_path / "run")
    finally:
        proc.kill()
        proc.wait()
        release_run_folders()


def test_a_released_lock_leaves_no_file(tmp_path: Path) -> None:
    """Every command left its lock file behind: /tmp/piga-locks held 10,640 of them."""
    from piga.io.lock import _lock_path, held_by

    path = _lock_path(tmp_path / "run")
    lock_run_folder(tmp_path / "run")
    assert path.is_file()
    release_run_folders()
    assert not path.exists() and held_by(tmp_path / "run") is None
    holder = _hold(tmp_path / "run")  # taken again at once, on a new file
    try:
        with pytest.raises(FolderInUseError, match=f"PID {holder.pid}"):
            lock_run_folder(tmp_path / "run")
    finally:
        holder.kill()
        holder.wait()
    assert path.is_file()  # a killed holder leaves its file: unlocked, and reused
    lock_run_folder(tmp_path / "run")
    release_run_folders()
    assert not path.exists()


def test_a_lock_file_removed_between_open_and_lock_is_not_trusted(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A holder that removes its file as it ends can do so after a second command opened it: the second then locked
    a removed file, and a third, on a new file, took the folder too. The lock is taken on the file the path names."""
    import fcntl

    from piga.io.lock import _lock_path

    path = _lock_path(tmp_path / "run")
    real = fcntl.flock
    removed = []

    def flock_after_removal(fd: int, operation: int) -> None:
        if not removed:  # the first try: its holder removes the file just now
            removed.append(fd)
            path.unlink()
        real(fd, operation)

    monkeypatch.setattr(fcntl, "flock", flock_after_removal)
    lock_run_folder(tmp_path / "run")
    try:
        assert removed and path.is_file()
        other = subprocess.run([sys.executable, "-c", HOLDER.replace("time.sleep(300)", "pass"), str(tmp_path / "run")],
                               capture_output=True, text=True, env=ENV)
        assert other.returncode == 1 and "FolderInUseError" in other.stderr  # the file there is the one locked
    finally:
        release_run_folders()


def test_a_folder_where_the_lock_file_goes_is_named(tmp_path: Path) -> None:
    """It made the command run unlocked, without a word."""
    from piga.io.lock import _lock_path

    path = _lock_path(tmp_path / "run")
    path.mkdir(parents=True)
    try:
        with pytest.raises(FolderInUseError, match="its lock file .* is a folder; remove it"):
            lock_run_folder(tmp_path / "run")
    finally:
        path.rmdir()


def test_collect_import_and_diagnose_refuse_an_output_in_use(tmp_path: Path, tiny_data: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Two piga-collect --overwrite into one file both said "wrote", and a second diagnosis into one folder was
    refused only after its work ("appeared while writing")."""
    from piga.cli import collect, diagnose, importer

    for prog, main, out, argv in (
            ("piga-collect", collect.main, tmp_path / "d.h5", ["--sequences", "3", "--steps", "4", "--quiet"]),
            ("piga-import", importer.main, tmp_path / "i.h5", [str(tmp_path), str(tmp_path / "a.csv"), "--dt", "0.05"]),
            ("piga-diagnose", diagnose.main, tmp_path / "rep", ["--model", str(tmp_path), "--data", str(tiny_data)])):  # refused before the model is read
        holder = _hold(out)
        try:
            code, _, err = run_in_process(prog, main, *argv, "--out", str(out), capsys=capsys)
            assert_one_line(code, err, f"is in use by another piga command (PID {holder.pid})")
        finally:
            holder.kill()
            holder.wait()
        assert not out.exists()
