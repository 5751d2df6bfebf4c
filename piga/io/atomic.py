"""Atomic file output: write to a temporary sibling, then rename over the target.

A run that dies midway leaves the target untouched. That holds whether the target was absent or
held an older file. ``os.replace`` is atomic within one filesystem, which is why the temporary file
sits in the target's own folder.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import os
import shlex
import shutil
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any


class OutputExistsError(FileExistsError):
    """The target exists and the caller did not allow overwriting it."""


def link_loop(path: str | os.PathLike[str]) -> Path | None:
    """The first link on ``path`` (a folder on the way, or the path itself) that loops back on itself (``a -> a``, or
    ``a -> b -> a``), or None. pathlib's ``exists()`` and ``is_dir()`` answer False for such a link, so that a check
    called it missing ("make it first", "a link to a missing file") and the write then failed with ELOOP."""
    path = Path(path)
    for part in (*reversed(path.parents), path):
        if str(part) in ("", "."):
            continue
        try:
            os.stat(part)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return part
            return None  # missing, or not a folder: the checks that follow say which
    return None


def loop_message(path: str | os.PathLike[str], loop: Path, flag: str | None = None) -> str:
    """The one line for ``path`` (given as ``flag``) whose link ``loop`` loops (:func:`link_loop`)."""
    where = f"{flag} {path}: " if flag else "" if Path(path) == loop else f"{path}: "
    return (f"{where}{loop} is a link that loops back on itself (too many levels of symbolic links); remove or fix "
            "the link")


def check_writable_target(path: str | os.PathLike[str], overwrite: bool) -> Path:
    """Fails early, before any work, if ``path`` cannot or may not be written.

    Raises:
        OutputExistsError: ``path`` exists and ``overwrite`` is False.
        NotADirectoryError / PermissionError / FileNotFoundError: the folder is missing or not
            writable, or ``path`` is a folder.
    """
    if not isinstance(overwrite, bool):  # overwrite="no", a truthy string, replaced the file
        raise TypeError(f"overwrite must be True or False, got {overwrite!r}")
    target = Path(path)
    _check_name_lengths(target)
    if (loop := link_loop(target)) is not None and loop != target:  # a folder on the way
        raise NotADirectoryError(loop_message(target, loop))
    if loop is not None and not overwrite:  # the target, a link: --overwrite replaces the link
        raise OutputExistsError(f"{target} exists (a link that loops back on itself); pass --overwrite to replace it")
    if target.is_dir():
        raise IsADirectoryError(f"{target} is a folder, not a file path")
    if target.exists() and not target.is_file():  # --overwrite replaced /dev/null with a file (as root, it may)
        raise PermissionError(f"{target} is a device, a pipe or a socket, not a file: name a file to write")
    if os.path.lexists(target) and not overwrite:  # a link to nothing too: os.replace would replace the link
        raise OutputExistsError(f"{target} exists{' (a link to a missing file)' if not target.exists() else ''}; "
                                "pass --overwrite to replace it")
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        blocking = next((p for p in (folder, *folder.parents) if p.exists()), None)
        if blocking is not None and not blocking.is_dir():
            raise NotADirectoryError(f"{blocking} is a file, not a folder, so {target} cannot be written there")
        if blocking is not None and _read_only(blocking):  # mkdir -p would fail there too
            raise PermissionError(f"folder {folder} does not exist, and cannot be made: {blocking} is on a read-only "
                                  "file system; write somewhere else")
        if _unexpanded_home(folder):
            raise FileNotFoundError(f"folder {folder} does not exist: {UNEXPANDED_HOME}")
        raise FileNotFoundError(f"folder {folder} does not exist; make it first (mkdir -p {shlex.quote(str(folder))})")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"folder {folder} is not writable")
    try:
        total = shutil.disk_usage(folder).total
    except OSError:  # no answer: the write itself will say
        total = None
    if total == 0:  # /proc, /sys: writable to root, yet no file can be made there (a command said so only at the end)
        raise PermissionError(stores_no_files(str(target), folder))
    return target


#: Said of a path whose first part, "~", the shell did not expand.
UNEXPANDED_HOME = ("'~' is a folder's name here, as the shell did not expand it (it was quoted); give the path unquoted, "
                   "or as $HOME/...")


def _unexpanded_home(path: Path) -> bool:
    """Whether ``path`` starts with a ``~`` (or ``~user``) that the shell did not expand (it was quoted), and no such
    folder exists here: a command would take it for a folder of that name in the working folder."""
    return bool(path.parts) and path.parts[0].startswith("~") and not Path(path.parts[0]).exists()


def stores_no_files(what: str, folder: Path) -> str:
    """The line for ``what``, to be written under ``folder`` on a file system of 0 B in all (/proc, /sys)."""
    return (f"{what} cannot be written under {folder}: it is on a file system that stores no files (0 B in all, as "
            "/proc and /sys are); write it somewhere else")


class FolderMovedError(FileNotFoundError):
    """An output folder was removed, moved or replaced by another folder while the command wrote in it."""


class OutputFolder:
    """A run's output folder, which the run makes at its first checkpoint (or finds there: ``--resume``,
    ``--overwrite``): once it has been seen, each later write checks that the path still names that folder (its
    device and inode), so that a folder moved or removed while the run trained is said, and not made again, empty,
    beside the moved one (a later checkpoint and the report went into the new folder, the record into the old).
    """

    def __init__(self, path: str | os.PathLike[str], flag: str = "--out"):
        self.path = Path(path)
        self.flag = flag
        self._identity: tuple[int, int] | None = None
        self.check()

    def _now(self) -> tuple[int, int] | None:
        try:
            st = os.stat(self.path)
        except OSError:
            return None
        return st.st_dev, st.st_ino

    def check(self) -> None:
        """Takes the folder as this run's the first time it is there; after that, refuses another, or none.

        Raises:
            FolderMovedError: the path names no folder now, or another one.
        """
        now = self._now()
        if self._identity is None:
            self._identity = now if self.path.is_dir() else None
        elif now != self._identity:
            raise FolderMovedError(f"{self.flag} {self.path} was removed, moved or replaced while the run was training "
                                   "(if it was moved, the folder it went to holds the run's last checkpoint); move it "
                                   "back and continue the run with --resume, or train it again")

    def make(self) -> Path:
        """The folder for the next write: made (with missing parents) if the run has none yet, else :meth:`check`-ed."""
        self.check()
        if self._identity is None:
            self.path.mkdir(parents=True, exist_ok=True)
            self.check()
        return self.path

    @contextlib.contextmanager
    def kept(self) -> Iterator[Path]:
        """Inside: writes in the folder, :meth:`check`-ed before; a write that fails as the folder is gone (a missing
        folder's own FileNotFoundError, "folder ... does not exist") raises :class:`FolderMovedError` instead."""
        self.check()
        try:
            yield self.path
        except FolderMovedError:
            raise
        except FileNotFoundError:
            self.check()
            raise


def _read_only(folder: Path) -> bool:
    """Whether ``folder`` is on a file system mounted read-only (False where that cannot be told)."""
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):  # (no statvfs: not POSIX)
        return False


def check_file_name(path: str | os.PathLike[str], flag: str, example: str) -> None:
    """Refuses a path whose name is only a suffix (".png", "out/.mp4": a hidden file with no suffix, to Python) or is
    empty ("."), naming what is missing: "use a .png path, got .png" told the user to use what they gave."""
    name = Path(path).name
    if not name or name in (".", ".."):
        raise ValueError(f"{flag} {path}: names a folder, not a file; give a file name such as {example}")
    if name.startswith(".") and Path(name).suffix == "" and name.count(".") == 1:
        raise ValueError(f"{flag} {path}: the name is only a suffix; give a name before it, such as "
                         f"{Path(example).stem}{name}")


def check_not_an_input(target: str | os.PathLike[str], inputs: dict[str, str | os.PathLike[str]],
                       flag: str = "--out") -> None:
    """Refuses an output that is one of the command's inputs, by any name (a link, ``./``): ``--overwrite`` would
    replace what it reads.

    Raises:
        ValueError: naming the input.
    """
    for what, path in inputs.items():
        try:
            same = os.path.samefile(target, path)
        except OSError:  # either is missing: not the same file
            continue
        if same:
            raise ValueError(f"{flag} {target} is the {what} ({path}), which it would replace; write to another path")


def check_folder_target(folder: str | os.PathLike[str], flag: str = "--out", logs: bool = True) -> Path:
    """Fails early, before any work, if the output folder ``folder`` (given as ``flag``) cannot be made: it is a
    file, or a file stands where one of its missing parents would go. ``logs``: TensorBoard writes under it, so its
    name must be UTF-8 text.

    Raises:
        NotADirectoryError: naming the file in the way.
    """
    path = Path(folder)
    _check_name_lengths(path, flag, folder=True)
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:  # TensorBoard's writer encodes its folder's name as UTF-8, strictly
        locale = _locale_name()
        if logs:  # under a UTF-8 locale the bytes themselves are not UTF-8: another locale would not help
            what, fix = (("holds bytes that are not UTF-8 text", "a UTF-8 or ASCII name")
                         if "utf" in locale.lower().replace("-", "") else
                         (f"is not UTF-8 text in this locale ({locale})", "an ASCII name or a UTF-8 locale (LC_ALL=C.UTF-8)"))
            raise ValueError(f"{flag} {path}: the name {what}, and a run's logs (TensorBoard's) cannot be written under "
                             f"it; use {fix}") from None
    if (loop := link_loop(path)) is not None:
        raise NotADirectoryError(loop_message(path, loop, flag))
    if path.is_symlink() and not path.exists():
        raise NotADirectoryError(f"{flag} {path} is a link to {os.readlink(path)}, which does not exist; remove the "
                                 "link or make its target first")
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{flag} {path} is a file, not a folder")
    if _unexpanded_home(path):  # a folder output makes its parents: it would make a folder named "~" here
        raise FileNotFoundError(f"{flag} {path}: {UNEXPANDED_HOME}")
    blocking = next((p for p in path.parents if p.exists()), None)
    if blocking is not None and not blocking.is_dir():
        raise NotADirectoryError(f"{flag} {path}: {blocking} is a file, not a folder, so {path} cannot be made there")
    nearest = path if path.exists() else blocking  # where the first file or folder will be made
    if nearest is not None and not os.access(nearest, os.W_OK | os.X_OK):  # a read-only mount too, even for root
        raise PermissionError(f"{flag} {path}: folder {nearest} is not writable")
    return path


def _check_name_lengths(path: Path, flag: str | None = None, folder: bool = False) -> None:
    """Refuses a path with a name (the file's or a folder's on the way) longer than the filesystem takes, before any
    other look at the path: each would raise ENAMETOOLONG, with the whole path in the message.

    Raises:
        ValueError: naming the part, its length and the limit.
    """
    def refuse(part: str, limit: int) -> None:
        where = "the name" if part == path.name else "a folder's name on the way"
        raise ValueError(f"{flag + ' ' if flag else ''}{part[:40]}...: {where} is {len(os.fsencode(part))} bytes, "
                         f"longer than the {limit} that the filesystem takes; give a shorter name")

    for part in path.parts:  # 255 (Linux's NAME_MAX) first: a longer folder name makes even is_dir() raise
        if len(os.fsencode(part)) > 255:
            refuse(part, 255)
    def is_folder(p: Path) -> bool:  # a path beyond PATH_MAX makes is_dir() raise ENAMETOOLONG (an OSError line)
        try:
            return p.is_dir()
        except OSError:
            return False

    existing = next((p for p in path.parents if is_folder(p)), Path("."))
    if len(os.fsencode(path.name)) > (limit := _name_max(existing)):
        refuse(path.name, limit)
    # the whole path, as its temporary sibling spells it (and, for a folder, with room for the files written in it)
    longest = len(os.fsencode(str(path))) - len(os.fsencode(path.name)) + len(os.fsencode(_partial_prefix(path))) + 10 \
        + (FOLDER_CONTENT_ROOM if folder else 0)
    if longest >= (limit := _path_max(existing)):
        raise ValueError(f"{flag + ' ' if flag else ''}{str(path)[:40]}...: the path is {len(os.fsencode(str(path)))} "
                         f"bytes; written through its temporary name{' and with the files in it' if folder else ''}, it "
                         f"would pass the {limit} that the system takes for a path; give a shorter one")


#: Bytes a folder target's path keeps free for the files written in it (``/plots/free_run_angles.png`` and such).
FOLDER_CONTENT_ROOM = 64


def _path_max(folder: Path) -> int:
    """The longest path, in bytes with its terminating NUL, that the system takes (4096 where it does not say)."""
    try:
        return os.pathconf(folder if str(folder) else ".", "PC_PATH_MAX")
    except (OSError, ValueError):
        return 4096


def _locale_name() -> str:
    """The locale of text, as a message names it (``C``, ``POSIX``, ``en_US.ISO-8859-1``)."""
    import locale

    return locale.setlocale(locale.LC_CTYPE) or "C"


def _name_max(folder: Path) -> int:
    """The longest file name, in bytes, that ``folder``'s filesystem takes (255 where it does not say)."""
    try:
        return os.pathconf(folder if str(folder) else ".", "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def _partial_prefix(target: Path, kind: str = "partial") -> str:
    """``.NAME.partial-``, or for a name too long to take the prefix and a PID, ``.DIGEST.partial-`` (a digest of the
    name), so that a legal name near the filesystem's limit can still be written through its temporary sibling;
    ``kind`` "kept": the sibling that keeps the file a set replaces until the set is whole (:func:`written_together`)."""
    prefix = f".{target.name}.{kind}-"
    if len(os.fsencode(prefix)) + 10 > _name_max(target.parent):  # 10: room for any PID
        prefix = f".{hashlib.sha1(os.fsencode(target.name)).hexdigest()[:20]}.{kind}-"
    return prefix


def partial_path(target: Path) -> Path:
    """The temporary sibling used while ``target`` is being written (unique per process)."""
    return target.with_name(f"{_partial_prefix(target)}{os.getpid()}")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` still runs. A zombie does not: a writer killed by SIGKILL together with its parent
    (``timeout -s KILL`` signals its own group, itself included) waits as one until init reaps it, and
    ``kill(pid, 0)`` still finds it: a rerun started at once kept the partial file in 2 tries of 2, one started 2 s
    later removed it. Linux's /proc gives the state ('Z', or 'X' for dead)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's (or a zombie: /proc says)
        pass
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:  # no /proc (macOS): kill's word; or it has just been reaped
        return not Path("/proc/self").exists() or Path(f"/proc/{pid}").exists()
    state = stat.rpartition(")")[2].split()[:1]  # "pid (comm) S ...": comm may hold spaces and parentheses
    return state not in (["Z"], ["X"])


def remove_stale_partials(target: Path) -> list[Path]:
    """Removes ``.NAME.partial-PID`` siblings of ``target`` left by a process that no longer runs, and the
    ``.NAME.kept-PID`` copies of an earlier ``target`` that such a process kept while it replaced a set of files
    (:func:`written_together`).

    A SIGKILL (or a power cut) leaves them; the next write of the same target cleans them up. Files
    of a live PID are left alone (another run may be writing). Returns the files removed.
    """
    removed = []
    prefixes = (_partial_prefix(target), _partial_prefix(target, "kept"))
    for path in target.parent.iterdir() if target.parent.is_dir() else ():
        if not (prefix := next((p for p in prefixes if path.name.startswith(p)), None)):
            continue
        pid = path.name[len(prefix):]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
                removed.append(path)
    return removed


def _rename_no_replace(tmp: Path, target: Path) -> None:
    """Renames ``tmp`` to ``target`` unless ``target`` exists, in one step: a hard link refuses an existing name, so a
    second writer that checked at the same moment (two commands given one ``--out``) cannot replace the first's file.
    On a filesystem without hard links (FAT, some network shares): a check, then ``os.replace``."""
    appeared = OutputExistsError(f"{target} appeared while writing; pass --overwrite to replace it")
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise appeared from None
    except OSError:  # no hard links here
        if os.path.lexists(target):
            raise appeared from None
        os.replace(tmp, target)
        return
    tmp.unlink()


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str], overwrite: bool = False) -> Iterator[Path]:
    """Yields a temporary path to write; on success renames it to ``path``.

    If the body raises, or the process is interrupted through SIGINT or SIGTERM (see
    :func:`piga.cli.common.run_cli`), the temporary file is removed and ``path`` is left as it was.
    A SIGKILL can leave a hidden ``.NAME.partial-PID`` file beside the target, but never a
    half-written target; the next write of the same target removes such leftovers
    (:func:`remove_stale_partials`).
    """
    target = check_writable_target(path, overwrite)
    remove_stale_partials(target)
    tmp = partial_path(target)
    try:
        yield tmp
        if overwrite:
            os.replace(tmp, target)
        else:
            _rename_no_replace(tmp, target)
    finally:
        with contextlib.suppress(OSError):  # gone already (renamed, or never made)
            tmp.unlink()


def _identity(path: Path) -> tuple[int, int, int] | None:
    """What tells one file at ``path`` from another written there later (device, inode, change time); None if absent."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino, st.st_ctime_ns


@contextlib.contextmanager
def written_together(paths: Iterable[str | os.PathLike[str]]) -> Iterator[None]:
    """The outputs ``paths`` of one command (``OUT.json``, ``OUT.md``, ``OUT.png``), written in the body, each
    atomically: if the body fails or is interrupted, those of them that it wrote are removed again, so that no part
    of the set is left to block the command's rerun (``exists; pass --overwrite``) or to link to a missing file, and
    the files that were there before (an ``--overwrite``) are put back as they were: each is kept under a hidden
    sibling, ``.NAME.kept-PID`` (a hard link; a copy where the file system has none), until the set is whole. An
    interrupted ``--overwrite`` lost the earlier OUT.json, replaced before OUT.md was written."""
    targets = [Path(p) for p in paths]
    kept: dict[Path, Path] = {}
    try:
        for path in targets:
            if path.is_file() and not path.is_symlink():  # (a link is replaced, not its target: nothing to keep)
                remove_stale_partials(path)
                keep = path.with_name(f"{_partial_prefix(path, 'kept')}{os.getpid()}")
                if os.path.lexists(keep):  # kept by an enclosing set of this process, which puts it back
                    continue
                try:
                    os.link(path, keep)
                except OSError:  # no hard links on this file system
                    shutil.copy2(path, keep)
                kept[path] = keep
    except BaseException:  # nothing replaced yet
        _remove(kept.values())
        raise
    before = [_identity(p) for p in targets]  # (after the links, which change a file's ctime)
    try:
        yield
    except BaseException:
        for path, was in zip(targets, before):
            if (now := _identity(path)) is not None and now != was:  # written by the body
                with contextlib.suppress(OSError):
                    path.unlink()
            if path in kept and _identity(path) is None:  # replaced (or removed) by the body: put back
                with contextlib.suppress(OSError):
                    os.replace(kept.pop(path), path)
        raise
    finally:
        _remove(kept.values())


def _remove(paths: Iterable[Path]) -> None:
    for path in paths:
        with contextlib.suppress(OSError):
            path.unlink()


def write_json(path: str | os.PathLike[str], payload: dict[str, Any], overwrite: bool = True) -> None:
    """Writes JSON atomically (NaN written as null)."""
    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        return x

    with atomic_output(path, overwrite=overwrite) as tmp:
        tmp.write_text(json.dumps(clean(payload), indent=2) + "\n")


def torch_save(payload: Any, path: str | os.PathLike[str]) -> None:
    """``torch.save(payload, path)``, where a full disk is ``OSError(ENOSPC)`` naming ``path``.

    torch's zip writer reports a failed write as a RuntimeError with no errno ("unexpected pos ..."), which reads
    as a bug; so the payload is serialised in memory (checkpoints are model weights and optimiser states, not
    data) and written with a plain file write, whose failure carries its errno.
    """
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(payload, buffer)
    with open(path, "wb") as file:
        file.write(buffer.getbuffer())


def missing_folders(folder: Path) -> list[Path]:
    """``folder`` and those of its parents that do not exist yet, innermost first."""
    return [p for p in (folder, *folder.parents) if not p.exists()]


def remove_empty_folders(folders: list[Path]) -> None:
    """Removes ``folders`` (innermost first, as :func:`missing_folders` lists them) while they are empty."""
    for p in folders:
        try:
            p.rmdir()
        except OSError:  # not empty, or already gone: the outer ones stay
            break
