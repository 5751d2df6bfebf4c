"""One command at a time in a run folder.

Two commands writing one run folder (the same ``--out`` twice, two ``--resume`` of one run) each passed the "already
holds a run" check before either wrote anything, then replaced each other's checkpoint: a run that exited "trained"
was gone. :func:`lock_run_folder` takes an exclusive lock for the folder's path until the process ends, and a
second command is refused in one line naming the first one's PID.

The lock is ``fcntl.flock`` on a file named by a digest of the folder's real path, in a ``piga-locks`` folder of
the temporary folder, so that nothing is made in ``--out`` before a run exists. The kernel drops the lock when its
process ends in any way (SIGKILL included), so a lock never outlives its run, and a command that ends removes its
lock file (one killed leaves it, unlocked, for the next command to reuse). Where no lock can be taken (no ``fcntl``,
a temporary folder that cannot be written), the command runs unlocked, as before.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path

__all__ = ["FolderInUseError", "held_by", "lock_run_folder", "release_run_folders"]

#: Locks held by this process, kept open for its life (closing a descriptor drops its lock).
_HELD: dict[str, int] = {}


class FolderInUseError(ValueError):
    """Another command holds the run folder."""


def _lock_path(folder: Path) -> Path:
    """The lock file of ``folder``: in ``/tmp/piga-locks`` whatever ``TMPDIR`` says (a scheduler gives each job a
    TMPDIR of its own, and two jobs with two lock folders both wrote one run folder), or in the temporary folder
    where there is no writable /tmp."""
    key = hashlib.sha256(os.path.realpath(folder).encode("utf-8", "surrogateescape")).hexdigest()[:32]
    shared = Path("/tmp")
    root = shared if shared.is_dir() and os.access(shared, os.W_OK | os.X_OK) else Path(tempfile.gettempdir())
    return root / "piga-locks" / f"{key}.lock"


def lock_run_folder(folder: str | os.PathLike[str], flag: str = "--out") -> None:
    """Locks ``folder`` (given as ``flag``) for this process, until it ends.

    Raises:
        FolderInUseError: another process holds it.
    """
    try:
        import fcntl
    except ImportError:  # not POSIX
        return
    path = _lock_path(Path(folder))
    if str(path) in _HELD:
        return
    if path.is_dir():  # os.open would fail, and the run would go unlocked without a word
        raise FolderInUseError(f"{flag} {folder} cannot be locked: its lock file {path} is a folder; remove it")
    while True:
        try:
            if not path.parent.is_dir():
                path.parent.mkdir(exist_ok=True)
                os.chmod(path.parent, 0o1777)  # every user's locks (mkdir's mode is cut by the umask), as /tmp's own
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:  # a temporary folder that cannot be written, another user's lock file: run unlocked
            return
        with contextlib.suppress(OSError):  # another user's command must open it too (the umask cut the mode)
            os.fchmod(fd, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            os.close(fd)
            raise FolderInUseError(f"{flag} {folder} is in use by another piga command (PID {holder}); wait for it to "
                                   f"end, or give another {flag}") from None
        except OSError:  # a filesystem without locks
            os.close(fd)
            return
        if _names(path, fd):
            break
        os.close(fd)  # its last holder removed the file between our open and our lock: lock the file there now
    os.ftruncate(fd, 0)
    os.pwrite(fd, str(os.getpid()).encode("ascii"), 0)
    _HELD[str(path)] = fd


def release_run_folders() -> None:
    """Drops this process's locks: a command run in-process (a test, a notebook) releases its folder as it returns,
    as a process does by ending."""
    while _HELD:
        path, fd = _HELD.popitem()
        with contextlib.suppress(OSError):  # removed while still locked (see lock_run_folder): none accumulate
            os.unlink(path)
        os.close(fd)


def _names(path: Path, fd: int) -> bool:
    """Whether ``path`` still names the file open as ``fd`` (not removed, nor replaced, since it was opened)."""
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path))
    except OSError:
        return False


def held_by(folder: str | os.PathLike[str]) -> str | None:
    """The PID of another process that holds ``folder`` (a run still training), or None: free, or no way to tell."""
    try:
        import fcntl
    except ImportError:
        return None
    path = _lock_path(Path(folder))
    if str(path) in _HELD:
        return None
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # never locked, or not ours to read
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
    except OSError:
        return None
    finally:
        os.close(fd)  # a shared lock taken here ends with its descriptor
    return None
