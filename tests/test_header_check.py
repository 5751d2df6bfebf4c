"""A data file whose header crashes or hangs HDF5's C library is refused in words, read first in a child process."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from piga.cli.show import main as show_main
from piga.data import header_check
from piga.data.schema import DATASETS, DataFormatError, inspect_dataset
from tests.helpers import assert_one_line, run_in_process

CRASH = "import os, signal; os.kill(os.getpid(), signal.SIGSEGV)"
HANG = "import time; time.sleep(60)"
RAISES = "raise OSError('unable to open')"


@pytest.fixture(autouse=True)
def _nothing_read_yet(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test starts with no file known to read cleanly (the module remembers them for the process)."""
    monkeypatch.setattr(header_check, "_read", set())


@pytest.fixture
def data(tiny_data: Path, tmp_path: Path) -> Path:
    return Path(shutil.copy(tiny_data, tmp_path / "d.h5"))


def test_a_valid_file_reads_in_the_child_and_is_not_read_there_again(data: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    starts: list[list[str]] = []
    real = subprocess.run

    def counted(args: list[str], **kwargs: object) -> subprocess.CompletedProcess[bytes]:
        starts.append(args)
        return real(args, **kwargs)

    monkeypatch.setattr(header_check.subprocess, "run", counted)
    assert header_check.unreadable_header(data, DATASETS) is None
    assert len(header_check._read) == 1  # exit 0: the child read every dataset it was given
    inspect_dataset(data)
    inspect_dataset(data)
    assert len(starts) == 1 and starts[0][-len(DATASETS):] == list(DATASETS)
    data.write_bytes(data.read_bytes())  # changed (a new modification time): read again
    inspect_dataset(data)
    assert len(starts) == 2


def test_a_file_this_process_wrote_is_not_read_in_a_child(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from piga.data.collect import CollectConfig, collect

    path = tmp_path / "made.h5"
    collect(CollectConfig(sequences=6, steps=8, seed=5, workers=1, split=(4, 1, 1)), path, progress=False, command="test")
    monkeypatch.setattr(header_check, "_READ_HEADER", CRASH)  # a child would refuse it
    assert inspect_dataset(path).n_sequences == 6
    path.touch()  # changed since it was written: read in a child again
    with pytest.raises(DataFormatError, match="crashes"):
        inspect_dataset(path)


@pytest.mark.parametrize("program, words", [(CRASH, "HDF5's library crashes while reading its header"),
                                            (HANG, "reading its header did not end within 0.5 s: damaged, or on a disk that "
                                                  "does not answer")])
def test_a_child_that_crashes_or_hangs_refuses_the_file_in_one_line(program: str, words: str, data: Path,
                                                                     monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(header_check, "_READ_HEADER", program)
    monkeypatch.setattr(header_check, "TIMEOUT_S", 0.5)
    code, _, err = run_in_process("piga-show", show_main, str(data), "--out", str(data.with_suffix(".png")),
                                  capsys=capsys)
    assert_one_line(code, err, str(data), words, "collect, import or copy it again")
    assert not data.with_suffix(".png").exists() and header_check._read == set()


def test_a_child_that_merely_raises_leaves_the_words_to_the_command(data: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(header_check, "_READ_HEADER", RAISES)
    assert header_check.unreadable_header(data, DATASETS) is None
    assert header_check._read == set()  # not remembered as read: the next command checks it again
    inspect_dataset(data)  # the file itself is fine


def test_no_child_at_all_reads_the_file_here(data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(header_check.sys, "executable", str(data.parent / "no-python"))
    assert header_check.unreadable_header(data, DATASETS) is None
    inspect_dataset(data)


def test_the_child_does_not_import_a_module_from_the_current_folder(data: Path, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "h5py.py").write_text("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    monkeypatch.chdir(tmp_path)
    assert header_check.unreadable_header(data, DATASETS) is None


def _flipped(source: Path, offset: int, out: Path) -> Path:
    raw = bytearray(source.read_bytes())
    raw[offset] ^= 0xFF
    out.write_bytes(bytes(raw))
    return out


#: What inspect_dataset reads, in a process of its own, with no child first: for the precondition of the test below.
READ_DIRECTLY = """
import sys
from pathlib import Path

import h5py
from piga.data.schema import _check_attrs_agree, _validate

with h5py.File(sys.argv[1], "r") as f:
    try:
        _check_attrs_agree(_validate(f, Path(sys.argv[1])), f)
    except Exception:
        pass
"""


def _read_in_process(path: Path, seconds: float) -> str:
    """How this HDF5 takes ``path`` when a process reads it directly: "crash", "hang" or "reads"."""
    try:
        done = subprocess.run([sys.executable, "-c", READ_DIRECTLY, str(path)], capture_output=True, timeout=seconds,
                              check=False)
    except subprocess.TimeoutExpired:
        return "hang"
    return "crash" if done.returncode < 0 else "reads"


@pytest.mark.parametrize("offset, effect", [(2601, "crash"), (3064, "hang")])
def test_a_real_flipped_byte_that_takes_hdf5_down_is_refused(offset: int, effect: str, tiny_data: Path,
                                                            tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Bytes of the session's tiny file (seed 3, 12 x 16 frames) found by flipping each of its first 4,000 in turn."""
    path = _flipped(tiny_data, offset, tmp_path / f"flipped{offset}.h5")
    if (seen := _read_in_process(path, 5)) != effect:
        pytest.skip(f"this HDF5 ({__import__('h5py').version.hdf5_version}) {seen} on that byte, not {effect}")
    monkeypatch.setattr(header_check, "TIMEOUT_S", 3.0)
    with pytest.raises(DataFormatError, match="not a readable HDF5 file \\((damaged: HDF5's library crashes|reading "
                                              "its header did not end within 3 s: damaged)"):
        inspect_dataset(path)
