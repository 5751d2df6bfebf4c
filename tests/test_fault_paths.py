"""Paths at their edges: pipes in run folders, moved run folders, links that loop, small disks."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import ENV, assert_one_line, run_in_process
from tests.test_faults import TINY_PLANET, _listing, refused


@pytest.fixture(scope="module")
def piga_run(tiny_run: Path) -> Path:
    """A one-epoch piga-train-model run on ``tiny_data``: the session's (tests/conftest.py)."""
    return tiny_run


@contextlib.contextmanager
def _no_hang(seconds: int = 60) -> Iterator[None]:
    """Fails a command that blocks (the open of a pipe waits for a writer for ever) instead of hanging the tests."""
    def hung(number: int, frame: Any) -> None:
        raise TimeoutError(f"still running after {seconds} s (blocked on a pipe?)")

    saved = signal.signal(signal.SIGALRM, hung)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, saved)


def _with_fifo(run: Path, dst: Path, name: str) -> Path:
    """A copy of ``run`` at ``dst`` whose file ``name`` is a pipe."""
    shutil.copytree(run, dst)
    (dst / name).unlink(missing_ok=True)  # (a run trained through the library has no config.json)
    os.mkfifo(dst / name)
    return dst


# ---------------------------------------------------------------------------------------------
# A pipe in a run folder
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("prog, name, argv", [
    ("piga-control", "checkpoint.pt", ["--episodes", "1", "--steps", "20", "--quiet"]),
    ("piga-control", "metrics.json", ["--episodes", "1", "--steps", "20", "--quiet"]),
    ("piga-control", "config.json", ["--episodes", "1", "--steps", "20", "--quiet"]),
    ("piga-diagnose", "checkpoint.pt", ["--data", "DATA", "--out", "OUT", "--bootstrap", "0", "--threads", "1", "--quiet"]),
])
def test_a_pipe_in_a_run_folder_is_refused_not_opened(prog: str, name: str, argv: list[str], piga_run: Path,
                                                      tiny_data: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A pipe as a run's checkpoint.pt or metrics.json made piga-control and piga-diagnose wait for ever: the open of
    a pipe waits for a writer."""
    run = _with_fifo(piga_run, tmp_path / "rm", name)
    given = [str(tiny_data) if a == "DATA" else str(tmp_path / "rep") if a == "OUT" else a for a in argv]
    with _no_hang():
        refused(prog, ["--model", str(run), *given], capsys,
                f"{run / name} is a pipe (FIFO), not a regular file: it is not the run's {name}; remove it")
    assert not (tmp_path / "rep").exists()


@pytest.mark.parametrize("how", ["--resume", "--overwrite"])
def test_training_onto_a_pipe_as_the_checkpoint_is_refused_before_it_trains(how: str, piga_run: Path, tiny_data: Path,
                                                                          tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """--resume waited for ever on a pipe as the checkpoint; --overwrite trained an epoch, then refused the pipe."""
    from piga.training import train as training

    def never(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("trained before the pipe was refused")

    monkeypatch.setattr(training, "train", never)
    run = _with_fifo(piga_run, tmp_path / "r1", "checkpoint.pt")
    with _no_hang():
        refused("piga-train-model", [str(tiny_data), "--out", str(run), how, "--epochs", "1", "--batch-size", "16",
                                     "--threads", "1", "--quiet"], capsys,
                f"{run / 'checkpoint.pt'} is a pipe (FIFO), not a regular file")
    assert (run / "checkpoint.pt").is_fifo()


# ---------------------------------------------------------------------------------------------
# A run folder moved while it trains
# ---------------------------------------------------------------------------------------------


def _moves_after(module: Any, name: str, run: Path, moved: Path, monkeypatch: pytest.MonkeyPatch, after: bool) -> None:
    """``module.name`` moves the folder ``run`` to ``moved`` at its first call: after it ran (``after``), or before."""
    real = getattr(module, name)

    def moving(*args: Any, **kwargs: Any) -> Any:
        if not after and not moved.exists():
            run.rename(moved)
        result = real(*args, **kwargs)
        if after and not moved.exists():
            run.rename(moved)
        return result

    monkeypatch.setattr(module, name, moving)


@pytest.mark.parametrize("when", ["checkpoint", "report"])
def test_a_run_folder_moved_while_it_trains_is_not_made_again(when: str, tiny_data: Path, tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``mv r r_moved`` while piga-train-model ran: the run made r/ again for its next checkpoint and its report (no
    config.json), and ended as if nothing had happened, its older checkpoint in r_moved/."""
    from piga.training import report, train as training

    run, moved = tmp_path / "r", tmp_path / "r_moved"
    if when == "checkpoint":
        _moves_after(training, "save_checkpoint", run, moved, monkeypatch, after=True)
    else:
        _moves_after(report, "write_run_report", run, moved, monkeypatch, after=False)
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--epochs", "1", "--batch-size", "16", "--threads",
                                 "1", "--quiet"], capsys,
            f"--out {run} was removed, moved or replaced while the run was training", "continue the run with --resume")
    assert not run.exists() and (moved / "checkpoint.pt").is_file()


def test_a_run_folder_replaced_by_another_is_refused(tmp_path: Path) -> None:
    """Another folder made under the run folder's name is not the run's: compared by device and inode."""
    from piga.io.atomic import FolderMovedError, OutputFolder

    folder = OutputFolder(tmp_path / "a" / "r")
    assert folder.make().is_dir()  # made, with its parent, at the first write
    folder.check()
    (tmp_path / "a" / "r").rename(tmp_path / "moved")
    (tmp_path / "a" / "r").mkdir()
    with pytest.raises(FolderMovedError, match="was removed, moved or replaced"):
        folder.make()


def test_a_planet_run_folder_moved_while_it_trains_is_not_made_again(tiny_data: Path, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """piga-baseline planet made its run folder again at each checkpoint, as piga-train-model did."""
    from agents.planet import train as planet_train

    run, moved = tmp_path / "pl", tmp_path / "pl_moved"
    _moves_after(planet_train, "_save", run, moved, monkeypatch, after=True)
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(run), *TINY_PLANET], capsys,
            f"--out {run} was removed, moved or replaced while the run was training")
    assert not run.exists() and (moved / "checkpoint.pt").is_file()


# ---------------------------------------------------------------------------------------------
# A small disk
# ---------------------------------------------------------------------------------------------


def _small_disk(monkeypatch: pytest.MonkeyPatch, size: int) -> None:
    """Every disk looks ``size`` bytes large, and empty."""
    real = shutil.disk_usage

    def usage(path: Any) -> Any:
        return real(path)._replace(total=size, free=size)

    monkeypatch.setattr(shutil, "disk_usage", usage)


@pytest.mark.slow
def test_a_small_file_is_written_on_a_small_empty_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A 100 KB file on an empty 6 MiB disk: after collecting, "the disk is full", as the writer kept 8 MiB free for
    HDF5's caches, which hold no more than the file's data."""
    from piga.cli import collect

    _small_disk(monkeypatch, 6 * 2**20)
    out = tmp_path / "c.h5"
    code, _, err = run_in_process("piga-collect", collect.main, "--sequences", "30", "--steps", "20", "--workers", "1",
                                  "--quiet", "--out", str(out), capsys=capsys)
    assert code == 0 and out.is_file(), err


def test_a_file_the_writer_has_no_room_for_is_refused_before_the_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The check before the work asks for the room that the writer keeps free, so the refusal comes first, with the
    need in numbers, not "the disk is full" after collecting."""
    from piga.data import collect as collecting

    def never(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("collected before the disk was checked")

    monkeypatch.setattr(collecting, "_vector_env", never)
    _small_disk(monkeypatch, 6 * 2**20)
    line = refused("piga-collect", ["--sequences", "1000", "--steps", "50", "--workers", "1", "--quiet", "--out",
                                    str(tmp_path / "c.h5")], capsys, "needs up to", "has 6.0 MiB free")
    assert "full" not in line
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("frames, in_file", [("blank", "164 B in the file"), ("noise", "96.1 KiB in the file")])
def test_the_writer_names_its_need_not_a_full_disk(frames: str, in_file: str, tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Refused by the writer (the disk filled after the command's check), the line gives the free space and the need:
    the slice's bytes as they take the file (zlib at the codec's level: blank frames shrink to a few bytes, noise not
    at all) and the room kept for HDF5's metadata."""
    import numpy as np

    from piga.data.schema import DatasetWriter
    from piga.io.resources import ResourceError

    pixels = np.zeros((2, 3, 128, 128), np.uint8) if frames == "blank" else \
        np.random.default_rng(0).integers(0, 256, (2, 3, 128, 128), dtype=np.uint8)
    with pytest.raises(ResourceError) as refusal:
        with DatasetWriter(tmp_path / "d.h5", 2, 3, (128, 128), 1, None, {"system": "pendulum", "dt": 0.05}) as writer:
            _small_disk(monkeypatch, 2000)
            writer.write(0, pixels, np.zeros((2, 3, 1), np.float32))
    line = str(refusal.value)
    assert "its disk has 2.0 KiB free, less than the " in line and "full" not in line
    assert f"({in_file}, and 140.2 KiB kept free for HDF5's metadata" in line, line
    assert _listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# Links that loop
# ---------------------------------------------------------------------------------------------


@pytest.fixture
def loops(tmp_path: Path) -> Path:
    """``lk/`` with ``selfdir -> selfdir``, ``la -> lb -> la`` and ``self.h5 -> self.h5``."""
    folder = tmp_path / "lk"
    folder.mkdir()
    for name, target in (("selfdir", "selfdir"), ("lb", "la"), ("la", "lb"), ("self.h5", "self.h5")):
        (folder / name).symlink_to(target)
    return folder


@pytest.mark.parametrize("prog, argv, loop", [
    ("piga-collect", ["--out", "lk/la/c.h5"], "lk/la"),
    ("piga-collect", ["--out", "lk/selfdir/c.h5"], "lk/selfdir"),
    ("piga-train-model", ["DATA", "--out", "lk/la"], "lk/la"),
    ("piga-train-model", ["DATA", "--out", "lk/selfdir/r"], "lk/selfdir"),
    ("piga-baseline", ["planet", "DATA", "--out", "lk/selfdir/pl", *TINY_PLANET], "lk/selfdir"),
    ("piga-demo", ["--out", "lk/selfdir/d"], "lk/selfdir"),
    ("piga-show", ["lk/self.h5", "--out", "s.png"], "lk/self.h5"),
    ("piga-control", ["--model", "lk/la", "--episodes", "1", "--steps", "20"], "lk/la"),
])
def test_a_link_that_loops_is_named_before_the_work(prog: str, argv: list[str], loop: str, loops: Path, tiny_data: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A link that loops was "a folder that does not exist; make it first" (which failed), "a link to lb, which does
    not exist" (lb exists), or, after the training, the raw "[Errno 40] Too many levels of symbolic links"."""
    monkeypatch.chdir(loops.parent)
    given = [str(tiny_data) if a == "DATA" else a for a in argv]
    if prog == "piga-collect":
        given += ["--sequences", "3", "--steps", "4", "--workers", "1", "--quiet"]
    if prog == "piga-train-model":
        given += ["--epochs", "1", "--batch-size", "16", "--threads", "1", "--quiet"]
    refused(prog, given, capsys, f"{loop} is a link that loops back on itself (too many levels of symbolic links); "
            "remove or fix the link")
    assert sorted(p.name for p in loops.iterdir()) == ["la", "lb", "self.h5", "selfdir"]


def test_a_file_link_to_itself_is_named_a_loop(loops: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """``self.h5 -> self.h5`` was "a link to a missing file"."""
    monkeypatch.chdir(loops.parent)
    refused("piga-collect", ["--out", "lk/self.h5", "--sequences", "3", "--steps", "4", "--workers", "1", "--quiet"],
            capsys, "lk/self.h5 exists (a link that loops back on itself); pass --overwrite to replace it")


# ---------------------------------------------------------------------------------------------
# A file gone while a command runs; the early interrupt's name
# ---------------------------------------------------------------------------------------------


def test_a_data_file_gone_while_a_command_runs_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """h5py's open of a file moved away was printed raw: "[Errno 2] Unable to synchronously open file (unable to open
    file: name = 'd.h5', errno = 2, ...)"."""
    import h5py

    gone = tmp_path / "d.h5"

    def main(argv: Sequence[str] | None) -> int:
        h5py.File(gone, "r")
        return 0

    code, _, err = run_in_process("piga-diagnose", main, capsys=capsys)
    assert_one_line(code, err, f"piga-diagnose: error: {gone}: no such file (removed or moved while it ran?)")


def test_the_script_names_are_pyprojects() -> None:
    """The early interrupt names a command from its own table; it must be pyproject's [project.scripts]."""
    import tomllib

    from piga.cli import SCRIPTS

    scripts = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())["project"]["scripts"]
    assert SCRIPTS == {value.removesuffix(":entry"): name for name, value in scripts.items()}


def test_ctrl_c_while_a_module_loads_names_the_command_without_a_lookup() -> None:
    """``python -m piga.cli.importer`` interrupted in its first ~0.1 s was "piga: interrupted" when the entry points'
    lookup failed mid-import."""
    code = ("import importlib.metadata, os, signal, sys, time; sys.argv[0] = '-m'; "
            "sys.orig_argv = [sys.executable, '-m', 'piga.cli.importer']; "
            "importlib.metadata.entry_points = lambda **kwargs: 1 / 0; import piga.cli; "
            "os.kill(os.getpid(), signal.SIGINT); time.sleep(30)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=ENV)
    assert result.returncode == 130 and result.stderr == "piga-import: interrupted; nothing was written\n", result.stderr


@pytest.mark.parametrize("system", ["pendulum", "spring"])
def test_a_collection_without_room_is_told_what_collect_can_change(system: str, tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """piga-collect's disk refusal ended "ask for less", which names no option."""
    _small_disk(monkeypatch, 1000)
    line = refused("piga-collect", ["--system", system, "--out", str(tmp_path / "d.h5"), "--sequences", "4"], capsys,
                   "needs up to", "free some space, write --out elsewhere, or give fewer --sequences or --steps or a "
                   "smaller --image-size")
    assert "ask for less" not in line and not (tmp_path / "d.h5").exists()


def test_an_import_without_room_is_told_what_import_can_change(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """piga-import's disk refusal ended "ask for less", though import has no count to lower."""
    import imageio.v3 as iio
    import numpy as np

    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(6):
        iio.imwrite(frames / f"f{i}.png", np.full((64, 64), 40 * i, np.uint8))
    (tmp_path / "a.csv").write_text("0.5\n" * 6)
    _small_disk(monkeypatch, 1000)
    line = refused("piga-import", [str(frames), str(tmp_path / "a.csv"), "--dt", "0.05", "--steps", "3", "--out",
                                   str(tmp_path / "d.h5")], capsys, "needs up to", "a smaller --image-size")
    assert "ask for less" not in line and not (tmp_path / "d.h5").exists()


@pytest.mark.parametrize("name", ["checkpoint.pt", "data.h5"])
def test_a_run_given_as_a_file_asks_for_its_folder(name: str, tmp_path: Path) -> None:
    """--model model/checkpoint.pt read "model/checkpoint.pt/checkpoint.pt: no checkpoint (is model/checkpoint.pt a
    piga-train-model run folder?)", a path the user never typed."""
    from piga.io.checkpoint import RunKind, read_checkpoint

    (tmp_path / name).write_bytes(b"x")
    folder = f" ({tmp_path})" if name == "checkpoint.pt" else ""
    with pytest.raises(FileNotFoundError) as info:
        read_checkpoint(tmp_path / name, RunKind.PIGA)
    assert str(info.value) == f"{tmp_path / name} is a file; give the run's folder{folder}"


def test_control_refuses_a_folder_as_its_out_stem(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--out co`` with a folder co wrote co.json and co.md beside it; piga-collect and piga-import refuse a folder."""
    folder = tmp_path / "co"
    folder.mkdir()
    refused("piga-control", ["--oracle", "--episodes", "1", "--steps", "20", "--quiet", "--out", str(folder)], capsys,
            f"argument --out: '{folder}' is a folder; name the files to write in it")
    assert _listing(tmp_path) == ["co"]
