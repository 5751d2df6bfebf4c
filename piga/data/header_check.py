"""A data file's metadata read first in a child process, where HDF5's C library cannot take the command down.

A flipped byte in an HDF5 file's header can make the library crash (a segmentation fault while it decodes an
attribute) or loop for ever, inside one call that Python cannot interrupt or catch. Read in the command's own
process, such a file killed it with no message, or hung it. :func:`unreadable_header` reads in a child process what
the commands read of a file before its frames (the file's attributes and the named datasets' metadata, attributes
and first element), and says in words what happened if the child crashed or did not finish. A child that merely
raised is not judged here: the command's own reading then says what is wrong, in its own words.

Each file is read so once per process while it stays unchanged (its device, inode, size and modification time), and
not at all where this process wrote it (:func:`remember_written`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

TIMEOUT_S = 30.0  # a header of a valid file reads in milliseconds; the child's Python and h5py start in about 0.3 s

CRASHES = frozenset(getattr(signal, name) for name in ("SIGSEGV", "SIGBUS", "SIGABRT", "SIGILL", "SIGFPE")
                    if hasattr(signal, name))

# The child's program: only h5py, so that it starts fast. The first entry of sys.path (the current folder, for -c)
# is dropped, where it is there, so that a file named h5py.py there is not imported in its place.
_READ_HEADER = """
import sys
if sys.path[:1] == [""]:
    del sys.path[0]
import h5py
path, names = sys.argv[1], sys.argv[2:]

def read(obj):
    for key in obj.attrs:
        obj.attrs[key]

with h5py.File(path, "r") as f:
    read(f)
    for name in names:
        ds = f.get(name)
        if not isinstance(ds, h5py.Dataset):
            continue
        read(ds)
        ds.shape, ds.dtype, ds.chunks, ds.is_virtual, ds.external
        if ds.chunks is not None:
            ds.id.get_num_chunks()
        if ds.size:
            ds[(0,) * ds.ndim]
"""

_read: set[tuple[int, int, int, int]] = set()  # (device, inode, size, mtime in ns) of files whose header read cleanly


def _identity(path: Path) -> tuple[int, int, int, int]:
    stat = path.stat()
    return stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns


def remember_written(path: Path) -> None:
    """Marks ``path``, which this process has just written whole through h5py, as read: its header is the library's
    own (piga-demo reads the file it collected, and the tests the files they make, without a child each)."""
    _read.add(_identity(path))


def unreadable_header(path: Path, datasets: Sequence[str]) -> str | None:
    """What is wrong with ``path``'s header in words, where reading it crashed or hung a child process; else None
    (it read, or reading it raised an error that the caller's own reading will name, or no child could start)."""
    try:
        key = _identity(path)
    except OSError:
        return None  # the caller's own open says why
    if key in _read:
        return None
    try:
        child = subprocess.run([sys.executable, "-c", _READ_HEADER, os.fspath(path), *datasets],
                               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               timeout=TIMEOUT_S, check=False)
    except subprocess.TimeoutExpired:  # run() has killed the child
        return f"reading its header did not end within {TIMEOUT_S:g} s: damaged, or on a disk that does not answer"
    except OSError:  # no child could start (a limit on processes, no interpreter at sys.executable): read it here
        return None
    if -child.returncode in CRASHES:
        return "damaged: HDF5's library crashes while reading its header"
    if child.returncode == 0:
        _read.add(key)
    return None
