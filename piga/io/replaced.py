"""The run that ``--overwrite`` replaces, set aside until the new run has a checkpoint of its own.

Deleting the earlier run's outputs when the command starts loses them to anything that stops the new run before its
first checkpoint: a Ctrl-C, a refusal (the disk, the memory), a crash. Instead they move into ``RUN/.replaced`` (a
rename in the same folder: no copy, no extra disk) and are deleted at the new run's first checkpoint. A command that
ends before it puts them back (:func:`replacing`), so that the folder holds the earlier run as it was.

A process killed outright (SIGKILL, a power cut) leaves ``.replaced`` behind; the next command that writes the run
folder settles it (:func:`settle_replaced`): with a checkpoint in the folder the new run had written one, and the
earlier run goes; without one, the earlier run comes back.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path

from piga.io.checkpoint import CHECKPOINT, REPLACED_ASIDE as ASIDE, RUN_OUTPUTS


def _present(path: Path) -> bool:
    return path.exists() or path.is_symlink()


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif _present(path):
        path.unlink(missing_ok=True)


class ReplacedRun:
    """The outputs of the run in ``run_dir`` that this command replaces (none until :meth:`set_aside`)."""

    def __init__(self) -> None:
        self.run_dir: Path | None = None
        self.before: set[str] = set()  # the outputs that the folder held when they were set aside
        self.moved: list[str] = []  # those in ASIDE, to put back

    def set_aside(self, run_dir: Path, names: Sequence[str] = RUN_OUTPUTS) -> list[str]:
        """Moves those of ``names`` that ``run_dir`` holds into ``run_dir/.replaced`` (the checkpoint first: a folder
        without one, the move cut short, is then put back whole by :func:`settle_replaced`); returns them."""
        self.run_dir = Path(run_dir)
        self.before = {name for name in (*RUN_OUTPUTS, *names) if _present(self.run_dir / name)}
        present = sorted((name for name in names if name in self.before), key=lambda name: name != CHECKPOINT)
        if present:
            (self.run_dir / ASIDE).mkdir(exist_ok=True)
        for name in present:
            self.moved.append(name)  # (before the move: :meth:`restore` puts back only what the folder holds)
            os.replace(self.run_dir / name, self.run_dir / ASIDE / name)
        return present

    def drop(self) -> None:
        """Deletes the replaced run: the new run has a checkpoint (or has ended well without one)."""
        if self.run_dir is not None and self.moved:
            _remove(self.run_dir / ASIDE)
        self.moved.clear()

    def restore(self) -> None:
        """Puts the replaced run back, in place of what the new run wrote."""
        if self.run_dir is None or not self.moved:
            return
        aside = self.run_dir / ASIDE
        moved = {name for name in self.moved if _present(aside / name)}
        # the new run's outputs: those the folder did not hold, and those whose earlier version is aside
        _restore(self.run_dir, [name for name in (*RUN_OUTPUTS, *moved) if name not in self.before or name in moved],
                 moved)
        self.moved.clear()


def _restore(run_dir: Path, new: Sequence[str] | set[str], moved: Sequence[str] | set[str]) -> None:
    """Removes the outputs ``new`` from ``run_dir`` and moves ``moved`` back from ASIDE, which goes."""
    aside = run_dir / ASIDE
    for name in new:
        _remove(run_dir / name)
    for name in moved:
        os.replace(aside / name, run_dir / name)
    _remove(aside)


@contextlib.contextmanager
def replacing() -> Iterator[ReplacedRun]:
    """A :class:`ReplacedRun` whose outputs come back if the block ends with an exception (a refusal, an interrupt)
    before :meth:`ReplacedRun.drop`, and are deleted if it ends well."""
    replaced = ReplacedRun()
    try:
        yield replaced
    except BaseException:
        replaced.restore()
        raise
    replaced.drop()


def settle_replaced(run_dir: str | os.PathLike[str]) -> str | None:
    """Settles the ``.replaced`` folder that a command killed outright left in ``run_dir``: deleted where the folder
    holds a checkpoint (the new run's), put back where it does not. Returns a line that says which, or None."""
    # (what the new run wrote beside them, a record or curves without a checkpoint, stays)
    return settle_set_aside(run_dir, RUN_OUTPUTS, _present(Path(run_dir) / CHECKPOINT), "the run", "run")


def settle_set_aside(folder: str | os.PathLike[str], names: Sequence[str], keep_new: bool, what: str,
                     kind: str) -> str | None:
    """Settles ``folder/.replaced`` where a command killed outright set aside the outputs ``names`` of ``what`` (the
    earlier run, or piga-demo's earlier files) before the new ``kind``'s first checkpoint: deleted where ``keep_new``
    (the new one got that far), else put back in place of the new versions. Returns a line that says which, or None."""
    folder = Path(folder)
    aside = folder / ASIDE
    if not aside.is_dir() or aside.is_symlink():
        return None
    if keep_new:
        _remove(aside)
        return (f"removed {aside}: {what} that an --overwrite replaced, left there by a command stopped after the new "
                f"{kind}'s first checkpoint")
    moved = [name for name in names if _present(aside / name)]
    _restore(folder, moved, moved)
    return (f"restored {what} in {folder} from {aside}, where an --overwrite stopped before the new {kind}'s first "
            "checkpoint had set it aside")
