"""A run folder and its checkpoint: what kind of run it is, and its one ``checkpoint.pt``.

| kind | written by | its checkpoint's ``kind`` |
|---|---|---|
| :attr:`RunKind.PIGA` | ``piga-train-model`` (its ``config.json`` has no ``kind``) | none |
| :attr:`RunKind.PLANET` | ``piga-baseline planet`` | ``"planet"`` |
| :attr:`RunKind.DDPG` | ``piga-baseline ddpg`` (DDPG or SAC) | ``"ddpg"`` |

Every run writes its checkpoint with :func:`write_checkpoint` (atomic) and reads it with
:func:`read_checkpoint`, which says which file and what it found when the file is missing, unreadable
or of another kind. The agent each kind runs as is registered in :mod:`piga.control.registry`.

This module imports torch only when a checkpoint is read or written.
"""

from __future__ import annotations

import contextlib
import enum
import json
import os
import pickle
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

#: The checkpoint's file name in every run folder.
CHECKPOINT = "checkpoint.pt"
#: Every file or folder that a run of any kind (piga-train-model's, a baseline's) writes into its folder: what
#: ``--overwrite`` replaces, whichever kind of run the folder held (a PlaNet-style run over a piga run kept the piga
#: run's figures beside its own).
RUN_OUTPUTS = (CHECKPOINT, "config.json", "metrics.json", "tensorboard", "rollout.png", "templates.png", "curves.png",
               "openloop.png", "model.zip", "autoencoder.pt", "collected.h5", "replay_buffers")

#: The folder, inside a run folder, that holds the outputs of the run that --overwrite replaces until the new run's
#: first checkpoint (:mod:`piga.io.replaced`).
REPLACED_ASIDE = ".replaced"

#: The files of a run folder that commands read: its checkpoint and its two records.
RUN_FILES = (CHECKPOINT, "config.json", "metrics.json")

__all__ = ["CHECKPOINT", "DEMO_RUN", "DIVERGED", "REPLACED_ASIDE", "RUN_FILES", "RunKind", "check_run_file", "check_run_files",
           "checked_run_kind", "checkpoint_kind", "divergence_warning", "is_demo_folder", "kind_mismatch",
           "read_checkpoint", "record_divergence", "recorded_data_path", "recorded_path", "require_piga_run", "run_kind",
           "write_checkpoint", "unreadable"]


class RunKind(enum.Enum):
    """What a run folder holds: its ``config.json``'s ``kind`` (``piga`` when it has none)."""

    PIGA = "piga"
    PLANET = "planet"
    DDPG = "ddpg"

    @property
    def is_baseline(self) -> bool:
        """A baseline runs as trained: it cannot be told a gravity change or given a goal."""
        return self is not RunKind.PIGA

    @property
    def writer(self) -> str:
        """The command that writes such a run."""
        return "piga-train-model" if self is RunKind.PIGA else f"piga-baseline {self.value}"

    @property
    def label(self) -> str:
        """Its name in messages: "piga", "PlaNet-style", "DDPG" (an SB3 run, DDPG or SAC)."""
        return {RunKind.PIGA: "piga", RunKind.PLANET: "PlaNet-style", RunKind.DDPG: "DDPG"}[self]

    @classmethod
    def parse(cls, name: str, where: str = "run kind") -> RunKind:
        """The kind named ``name``.

        Raises:
            ValueError: an unknown name, naming ``where`` it was read and the known kinds.
        """
        try:
            return cls(name)
        except ValueError:
            raise ValueError(f"{where}: unknown run kind {name!r}; known: {', '.join(k.value for k in cls)}") from None


def run_kind(run_dir: str | os.PathLike[str]) -> RunKind:
    """The kind of a run folder: ``config.json``'s ``kind``; :attr:`RunKind.PIGA` when it has none
    (``piga-train-model``'s) or has no readable ``config.json`` (then loading the piga model says what is missing).

    Raises:
        ValueError: an unknown kind.
    """
    record, _ = read_run_record(run_dir)
    return RunKind.parse(str(record.get("kind", "piga")), f"{Path(run_dir)}/config.json")


def held_kind(run_dir: str | os.PathLike[str]) -> RunKind | None:
    """The kind of run a folder holds, by its record (``config.json``'s ``kind``; a piga run where it names none),
    or None where the record names no known kind (the command's own checks then say what is wrong)."""
    try:
        return run_kind(run_dir)
    except (ValueError, OSError):
        return None


def checkpoint_kind(run_dir: str | os.PathLike[str]) -> RunKind | None:
    """The kind that ``run_dir``'s checkpoint names (``piga`` where it names none), read without its tensors (torch's
    memory map): None where there is no checkpoint, or none that reads (the run's loader then says what is wrong)."""
    import torch

    path = Path(run_dir) / CHECKPOINT
    if not path.is_file():
        return None
    try:
        payload = torch.load(path, map_location="cpu", weights_only=False, mmap=True)
        return RunKind(str(payload.get("kind", RunKind.PIGA.value)))
    except Exception:  # truncated, foreign, not a zip (no memory map), an unknown kind: its loader's error says which
        return None


def checked_run_kind(run_dir: str | os.PathLike[str]) -> RunKind:
    """:func:`run_kind`, with the checkpoint as the authority: a kind that ``config.json`` names otherwise, or cannot
    name (missing, unreadable) for a baseline's checkpoint, is refused before a command judges its options by it.

    Raises:
        ValueError: as :func:`read_checkpoint` for another kind's checkpoint.
    """
    claimed = run_kind(run_dir)
    found = checkpoint_kind(run_dir)
    if found is None or found is claimed:
        return claimed
    raise kind_mismatch(run_dir, found, claimed)


def kind_mismatch(run_dir: str | os.PathLike[str], found: RunKind, expected: RunKind) -> ValueError:
    """The error for ``run_dir``'s checkpoint, of kind ``found``, where a ``expected`` run was looked for: for a
    baseline's without a readable ``config.json``, the record; for one whose ``config.json`` names another kind, the
    two files that disagree."""
    path = Path(run_dir) / CHECKPOINT
    record_path = Path(run_dir) / "config.json"
    record, why = read_run_record(run_dir)
    if found.is_baseline and why:  # a baseline's run: known by its record
        return ValueError(f"{record_path}, the run's record, {why}: {path} is a {found.writer} checkpoint, and commands "
                          f"read a run's kind from its config.json; restore the file, or train the run again with "
                          "--overwrite")
    if (named := record.get("kind", RunKind.PIGA.value)) != found.value and not why:
        return ValueError(f"{record_path} names a {RunKind.parse(str(named), str(record_path)).writer} run, but {path} is "
                          f"a {found.writer} checkpoint: the two are of different runs; restore the run's own "
                          "config.json, or train the run again with --overwrite")
    return ValueError(f"{path} is a {found.writer} checkpoint, not a {expected.writer} run")


def check_run_file(path: str | os.PathLike[str]) -> None:
    """Refuses a run folder's file (:data:`RUN_FILES`) that is there but is no regular file, before it is opened: the
    open of a pipe waits for a writer for ever, and a device or a socket is no run's file. A file that is absent or
    cannot be looked at is left to the read that follows.

    Raises:
        ValueError: naming the file and what it is.
    """
    import stat

    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if stat.S_ISREG(mode):
        return
    what = ("a folder" if stat.S_ISDIR(mode) else "a pipe (FIFO)" if stat.S_ISFIFO(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "a device")
    name = Path(path).name
    raise ValueError(f"{path} is {what}, not a regular file: it is not the run's {name}; remove it, then restore the "
                     f"run's own {name} or train the run again")


def check_run_files(run_dir: str | os.PathLike[str]) -> None:
    """:func:`check_run_file` for each of ``run_dir``'s :data:`RUN_FILES`: a command that writes the run refuses one up
    front, not at its first write after the work."""
    for name in RUN_FILES:
        check_run_file(Path(run_dir) / name)


def _failed_checksum(path: Path) -> str | None:
    """The first entry of a checkpoint (torch writes a zip) whose bytes fail their CRC-32, or None. torch.load reads
    a changed tensor without checking it; this reads the file once more (about a second per GB)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as archive:
            return archive.testzip()
    except (zipfile.BadZipFile, OSError):  # not a zip (torch.load read it): nothing to check
        return None


def read_run_record(run_dir: str | os.PathLike[str]) -> tuple[dict[str, Any], str | None]:
    """A run's ``config.json``, and None; or ``{}`` and what is wrong with it ("is missing", "cannot be read (...)",
    "is not a run record (not a JSON object)").

    Raises:
        ValueError: ``config.json`` is a pipe, a device or a folder (:func:`check_run_file`).
    """
    path = Path(run_dir) / "config.json"
    check_run_file(path)
    try:
        payload = json.loads(path.read_text())
    except FileNotFoundError:
        return {}, "is missing"
    except (OSError, ValueError) as exc:
        return {}, f"cannot be read ({unreadable_record(exc)})"
    return (payload, None) if isinstance(payload, dict) else ({}, "is not a run record (not a JSON object)")


#: The settings that a ``--resume`` may change (the run's length and budget, and how its process runs): a run's
#: record and its checkpoint may hold different values of them (a resume stopped before its first checkpoint).
RESUMABLE_SETTINGS = frozenset({"steps", "epochs", "budget_steps", "max_minutes", "threads", "device"})


#: :func:`check_record_matches`'s fix where a resume without the record rebuilds it from the checkpoint.
RESTORE_OR_DELETE = "restore the record's values, or delete it to resume from the checkpoint's"


def check_record_matches(run_dir: str | os.PathLike[str], sections: Iterable[tuple[object, object]],
                         fix: str = RESTORE_OR_DELETE) -> None:
    """Refuses a run whose record (``config.json``) no longer describes the run its checkpoint holds: an edited
    record, or another run's checkpoint put in the folder. ``sections``: pairs of a section of the record and the same
    settings as the checkpoint holds them; the settings that both hold are compared, but for
    :data:`RESUMABLE_SETTINGS`. A resume trains on the checkpoint's settings, so an edit was lost without a word (a
    learning rate edited there, or a PlaNet run's free nats, which did train with the edited value).

    Raises:
        ValueError: naming config.json, each setting that differs with both values, and ``fix``.
    """
    def plain(value: Any) -> Any:  # as JSON holds it: the checkpoint's tuples (nested ones too) are lists there
        return json.loads(json.dumps(value, default=str))

    differ = [(name, ours[name], held[name]) for ours, held in sections if isinstance(ours, dict) and isinstance(held, dict)
              for name in ours if name in held and name not in RESUMABLE_SETTINGS and plain(held[name]) != plain(ours[name])]
    if differ:
        raise ValueError(f"{Path(run_dir) / 'config.json'} does not describe the run its checkpoint holds ("
                         + ", ".join(f"{name} {ours!r} there, {held!r} in the checkpoint" for name, ours, held in differ)
                         + f"): {fix}")


def recorded_path(path: str, folder: object) -> str:
    """A path that a run recorded as its command was given it, relative to ``folder`` (the folder that command ran in;
    None in the records of older runs, whose relative paths are left as they are), as a path from the current folder:
    as recorded from that folder, relative below it, absolute elsewhere (``../moved.h5`` recorded in
    ``elsewhere/deep`` is ``elsewhere/moved.h5`` from the folder that holds ``elsewhere``)."""
    if os.path.isabs(path) or not isinstance(folder, str) or not folder:
        return path
    here = os.getcwd()
    if os.path.normpath(folder) == here:
        return path
    full = os.path.normpath(os.path.join(folder, path))
    relative = os.path.relpath(full, here)
    return full if relative == os.pardir or relative.startswith(os.pardir + os.sep) else relative


def recorded_data_path(data: object) -> str | None:
    """The training file that a checkpoint's ``data`` entry names (its ``path``, relative to its ``folder``), as a path
    from the current folder (:func:`recorded_path`); None where it names none."""
    if not isinstance(data, dict) or not isinstance(data.get("path"), str) or not data["path"]:
        return None
    return recorded_path(data["path"], data.get("folder"))


def unreadable_record(exc: Exception) -> str:
    """Why a JSON record of a run cannot be read, in words: its JSON broken (where), its bytes not text, or the
    system's reason (no permission)."""
    if isinstance(exc, json.JSONDecodeError):
        return f"not valid JSON: it breaks off or goes wrong at line {exc.lineno}, column {exc.colno}"  # (not the
        # parser's own "expecting property name enclosed in double quotes")
    if isinstance(exc, UnicodeDecodeError):
        return "not text: its bytes are not UTF-8"
    return exc.strerror.lower() if isinstance(exc, OSError) and exc.strerror else _first_sentence(exc)


def require_piga_run(run_dir: str | os.PathLike[str], purpose: str) -> None:
    """Refuses a baseline's run folder where a ``piga-train-model`` run is needed, saying which it is.

    Args:
        purpose: what needs the piga run, e.g. "piga-diagnose diagnoses the identified physics".

    Raises:
        ValueError: ``run_dir`` is a planet or ddpg run (or of an unknown kind).
    """
    kind = run_kind(run_dir)
    if kind is not RunKind.PIGA:
        raise ValueError(f"{run_dir} is a {kind.writer} run; {purpose}, so it needs a run folder of piga-train-model")


def write_checkpoint(run_dir: str | os.PathLike[str], payload: dict[str, Any]) -> Path:
    """Writes ``payload`` to ``run_dir/checkpoint.pt`` atomically (a reader never sees half a file); returns the path.

    A baseline's payload names its kind (``payload["kind"]``, a :class:`RunKind` value); a piga run's has none.
    """
    from piga.io.atomic import atomic_output, torch_save

    path = Path(run_dir) / CHECKPOINT
    with atomic_output(path, overwrite=True) as tmp:
        torch_save(payload, tmp)
    return path


def _first_sentence(exc: Exception) -> str:
    return " ".join(str(exc).split()).split(". ")[0][:160]


#: The run folder of a piga-demo, inside its --out (:mod:`piga.cli.demo`).
DEMO_RUN = "model"


def is_demo_folder(folder: str | os.PathLike[str]) -> bool:
    """Whether ``folder`` looks like a piga-demo's ``--out``: its trained run in :data:`DEMO_RUN`, or the data and the
    frame strip that it writes before that run's first checkpoint (``pendulum.h5``, ``frames.png``)."""
    folder = Path(folder)
    return (folder / DEMO_RUN / CHECKPOINT).exists() or all((folder / name).exists()
                                                            for name in ("pendulum.h5", "frames.png"))


def read_checkpoint(run_dir: str | os.PathLike[str], kind: RunKind) -> dict[str, Any]:
    """The checkpoint of ``run_dir``, which must be a ``kind`` run's.

    Raises:
        FileNotFoundError: no checkpoint, asking whether ``run_dir`` is a ``kind`` run folder.
        ValueError: a truncated or foreign file (naming the file and the cause), or another kind's
            checkpoint (naming the kind found; for a baseline's without its ``config.json``, the missing record,
            which :func:`run_kind` reads the kind from).
    """
    import torch

    path = Path(run_dir) / CHECKPOINT
    if not path.exists():
        from piga.io.atomic import link_loop, loop_message
        from piga.io.lock import held_by

        if (loop := link_loop(path)) is not None:  # exists() is False for a link that loops
            raise FileNotFoundError(loop_message(path, loop))

        if (pid := held_by(run_dir)) is not None:  # a run started moments ago: its folder is not a wrong guess
            raise FileNotFoundError(f"{path}: no checkpoint yet: {run_dir} is being trained by another piga command "
                                    f"(PID {pid}); wait for its first checkpoint")
        if Path(run_dir).is_file():  # the checkpoint itself, or another file: the commands take the run's folder
            folder = Path(run_dir).parent if Path(run_dir).name == CHECKPOINT else None
            raise FileNotFoundError(f"{run_dir} is a file; give the run's folder" + (f" ({folder})" if folder else ""))
        if is_demo_folder(run_dir):  # its run is one level down
            demo_run = Path(run_dir) / DEMO_RUN
            if (demo_run / CHECKPOINT).exists():
                raise FileNotFoundError(f"{path}: no checkpoint: {run_dir} looks like a piga-demo folder, whose trained "
                                        f"run is {demo_run}; give that")
            raise FileNotFoundError(f"{path}: no checkpoint: {run_dir} looks like a piga-demo folder, whose run "
                                    f"{demo_run} has no checkpoint yet; continue the demo with piga-demo --out "
                                    f"{run_dir} --resume")
        if (Path(run_dir) / REPLACED_ASIDE / CHECKPOINT).is_file():
            raise FileNotFoundError(f"{path}: no checkpoint: a command given --overwrite was killed before its new run's "
                                    f"first checkpoint, and the run it replaced is in {Path(run_dir) / REPLACED_ASIDE}; "
                                    f"move those files back into {run_dir} (or rerun that command, which does it)")
        raise FileNotFoundError(f"{path}: no checkpoint (is {run_dir} a {kind.writer} run folder?)")
    check_run_file(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # a truncated or foreign file
        raise unreadable(path, kind, exc) from None
    if (damaged := _failed_checksum(path)) is not None:
        raise ValueError(f"{path}: a damaged {kind.label} checkpoint: its entry {damaged} fails its checksum (bytes "
                         "changed on disk or in a copy); restore it, or train the run again with --overwrite")
    if not isinstance(payload, dict):
        raise ValueError(f"{path}: not a readable {kind.label} checkpoint (it holds a {type(payload).__name__})")
    found = payload.get("kind", RunKind.PIGA.value)
    if found != kind.value:
        raise kind_mismatch(run_dir, RunKind.parse(str(found), str(path)), kind)
    return payload


def unreadable(path: Path, kind: RunKind, exc: Exception | str, what: str | None = None) -> ValueError:
    """The one-line error for a ``kind`` checkpoint that cannot be read: the file, and the cause in words (for an
    entry it lacks, the entry: the file was written by something else, not cut short; ``exc`` a string: the cause as
    the caller words it). ``what``: the file's name in the message, for another file of the run (default: "<kind>
    checkpoint"; e.g. "autoencoder of a latent DDPG run")."""
    what = what or f"{kind.label} checkpoint"
    # (torch's zip reader raises KeyError("filename 'storages' not found") for a damaged file: that is no entry's name)
    if isinstance(exc, KeyError) and exc.args and isinstance(exc.args[0], str) and exc.args[0].isidentifier():
        article = "an" if what[:1].lower() in "aeiou" else "a"
        return ValueError(f"{path}: not {article} {what}: it lacks the entry {exc.args[0]!r} that {kind.writer} "
                          "writes; restore the run's own file, or train the run again with --overwrite")
    cause = exc if isinstance(exc, str) else _unreadable_cause(path, kind, exc)
    return ValueError(f"{path}: not a readable {what} ({cause}); "
                      "it may be truncated (a full disk, an interrupted copy) or edited: restore it, or train the run "
                      "again with --overwrite")


def _unreadable_cause(path: Path, kind: RunKind, exc: Exception) -> str:
    """Why ``path`` could not be read, in words rather than the reader's own text (which quoted "[Errno 22] Invalid
    argument" for a checkpoint cut short, and a slice of the file's bytes for a text file): an empty file; a torch or
    pickle file cut short or damaged (its first bytes are a zip archive's, as torch.save and SB3 write, or a pickle's,
    as SB3's replay buffers are); a whole one whose entries are not ``kind``'s; another kind of file; or the system's
    reason (no permission)."""
    import zipfile

    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as err:
        return err.strerror.lower() if err.strerror else "it cannot be opened"
    if not head:
        return "it is empty"
    whole = {b"PK\x03\x04": lambda: zipfile.is_zipfile(path),  # the archive's directory, at its end, is there
             b"\x80": lambda: not isinstance(exc, (EOFError, pickle.UnpicklingError))}  # pickle protocol 2 or later
    for signature, complete in whole.items():
        if head.startswith(signature):
            return _payload_cause(kind, exc) if complete() else "it is cut short or damaged"
    return "its bytes are not a file of this kind"


def _payload_cause(kind: RunKind, exc: Exception) -> str:
    """What is wrong with the entries of a whole ``kind`` checkpoint, from the error that reading them raised: a
    setting too many or too few (a dataclass's TypeError), weights of another model (torch's state-dict check), or
    entries of another kind."""
    import re

    text = str(exc)
    if extra := re.search(r"unexpected keyword argument '(\w+)'", text):
        return f"it holds a setting {extra[1]!r} that {kind.writer} does not write"
    if missing := re.search(r"missing (\d+) required (?:\w+ )*arguments?: (.+)$", text):
        return f"it lacks the setting{'' if missing[1] == '1' else 's'} {missing[2]} that {kind.writer} writes"
    if "state_dict" in text:
        return "its weights are not those of the model its settings describe"
    return f"its entries are not those that {kind.writer} writes"


@contextlib.contextmanager
def resuming_from(path: Path, kind: RunKind) -> Iterator[None]:
    """Inside: a ``kind`` checkpoint's entries are read to continue its run; an entry missing or malformed (a field
    of another version, an optimiser state of another model) leaves as the one-line :func:`unreadable` error
    instead of an internal one. Only reading goes inside: a broad catch over a few lines of reading, not over
    training."""
    try:
        yield
    except Exception as exc:  # KeyError, TypeError (a field too many), ValueError (torch's state checks), ...
        raise unreadable(path, kind, exc) from None


def check_counts(path: Path, kind: RunKind, **counts: object) -> None:
    """Refuses a checkpoint whose counts (``step=...``, ``epoch=...``) are not whole numbers of at least 0: a run
    resumed from ``step -5`` would report nonsense.

    Raises:
        ValueError: naming the file and the count.
    """
    for name, value in counts.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"{path}: not a {kind.label} checkpoint that can continue: its {name} is {value!r}, not a "
                             "count; restore the run's own file, or train the run again with --overwrite")


#: The key of a run's record (config.json) that says the run diverged after a checkpoint, and why.
DIVERGED = "diverged"


def record_divergence(run_dir: str | os.PathLike[str], cause: str) -> None:
    """Writes ``cause`` (the divergence's line) into the record of the run in ``run_dir``, whose checkpoint this
    command wrote or resumed from: the commands that read the run say that it diverged (its checkpoint is the last
    good one, never checked for learning, and an exact --resume diverges again), not that it was interrupted. A record
    that cannot be read is left as it is."""
    from piga.io.atomic import write_json

    run_dir = Path(run_dir)
    if not (run_dir / CHECKPOINT).is_file():
        return
    record, why = read_run_record(run_dir)
    if why is not None:
        return
    with contextlib.suppress(OSError):  # (a full disk: the line of the divergence is still said)
        write_json(run_dir / "config.json", {**record, DIVERGED: cause})


def divergence_warning(run_dir: str | os.PathLike[str]) -> str | None:
    """The warning (without its "warning: ") for a run whose record says it diverged (:func:`record_divergence`),
    else None."""
    try:
        record, _ = read_run_record(run_dir)
    except ValueError:  # config.json is a pipe or a folder: the command that reads the run says so itself
        return None
    cause = record.get(DIVERGED)
    if not isinstance(cause, str):
        return None
    return (f"the run {run_dir} diverged ({cause}); this used its last good checkpoint, which was never checked for "
            "learning (--resume repeats the same steps exactly and diverges again: train the run anew with --overwrite "
            "and a lower learning rate)")
