"""What every piga command shares: one-line errors, no tracebacks, and clean interruption."""

from __future__ import annotations

import argparse
import contextlib
import errno
import functools
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, NoReturn


from envs.dmc import MissingExtraError
from piga.io.atomic import OutputExistsError, missing_folders, remove_empty_folders
from piga.io.device import MAX_THREADS
from piga.io.lock import release_run_folders
from piga.io.pool import Backend, BackendError, JobFailed, host_port
from piga.data.schema import MAX_SEED, DataFormatError


class PigaError(Exception):
    """An error a user can fix; the command prints its message as one line."""


class Interrupted(KeyboardInterrupt):
    """An interruption after which something was kept; its message says what (``run_cli`` prints it)."""


#: The long flag of each option of the parsers that parsed this command line, by its dest (``lr`` -> ``--lr``).
_FLAGS: dict[str, str] = {}


def with_flags(message: str) -> str:
    """A config's message in the command line's words: ``TrainConfig.lr must be ...`` -> ``--lr must be ...``,
    ``TrainConfig: warmup_fraction + curriculum_fraction ...`` -> ``--warmup-fraction + --curriculum-fraction ...``.
    Only the fields of the options this command parsed are renamed; other words stay."""
    def flag(match: re.Match[str]) -> str:  # the field is the last group
        return _FLAGS.get(match.group(match.lastindex or 0), match.group(0))

    named = re.sub(r"\b\w+Config\.([a-z]\w*)\b", flag, message)
    named = re.sub(r"(?<![\w./'-])([a-z][a-z0-9]*(?:_[a-z0-9]+)+)(?![\w/'-]|\.\w)", flag, named)
    if named != message:  # "PixelPendulumConfig: gravity x --gravity-mult = ..." -> "--gravity x --gravity-mult = ..."
        named = re.sub(r"^\w+Config: ([a-z]\w*)\b", flag, named)
        named = re.sub(r"^\w+Config: ", "", named)
    return re.sub(r"(--[\w-]+) \(\1\)", r"\1", named)  # "--free-nats (free_nats)" named both


class ArgumentParser(argparse.ArgumentParser):
    """argparse that reports a usage error as a single line on stderr, with exit status 1 as any other refused input
    (argparse's own 2 made ``--image-size 0``, refused by its type, exit 2 and ``--image-size 1``, refused after
    parsing, exit 1).

    Abbreviations are off (``allow_abbrev=False``): ``--gravity 14`` must not silently mean
    ``--gravity-mult 14``; an option is taken only as spelt in full. Subparsers inherit this class.

    A value that starts with a minus and a digit (``-1,1,1``, ``-1e3``), or is a negative infinity or
    NaN as Python spells them (``-inf``, ``-nan``), is read as a value, not as an unknown option, so that
    its own type check names what is wrong with it.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\.?\d|(inf|infinity|nan)$)", re.IGNORECASE)

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        """As argparse's; a text value (no ``type``, no ``choices``) may not be empty: ``--out ''`` is refused,
        rather than read as the current folder or taken for an option not given."""
        if "type" not in kwargs and "choices" not in kwargs and kwargs.get("action", "store") in ("store", "append"):
            kwargs["type"] = nonempty_text
        return super().add_argument(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        given = list(getattr(self, "_given_args", ()))
        ended = given.index("--") if "--" in given else len(given)  # "--" ends the options: names follow it
        if message.startswith("the following arguments are required:"):
            # argparse says a required option is missing before it names an unknown one: "--ou x.h5" was refused as
            # "required: --out", with no word that --ou is no option (abbreviations are off)
            required = _required_flags(self)
            for flag in (token.split("=", 1)[0] for token in given[:ended]):
                full = sorted({name for name in required if name.startswith(flag) and name != flag})
                if flag.startswith("--") and full:
                    message = (f"unrecognized argument {flag}: options are taken only as spelt in full; give "
                               f"{' or '.join(full)}")
                    break
            else:
                message = self._after_the_end(given, ended, required) or message
        elif message.startswith("unrecognized arguments:"):  # options after "--": taken as names, then left over
            message = (self._after_the_end(given, ended, list(self._option_string_actions))
                       or self._positional_as_option(given[:ended]) or message)
        self.exit(1, f"{self.prog}: error: {message} (see --help)\n")

    def _positional_as_option(self, given: list[str]) -> str | None:
        """The line for a positional argument written as an option (``piga-baseline planet --data d.h5``: "unrecognized
        arguments: --data", with no word that the file goes by its place); None where none is."""
        parsers, positionals = [self], {}
        while parsers:  # this parser's positional arguments, and those of the subcommand given
            parser = parsers.pop()
            names = [action for action in parser._actions  # noqa: SLF001  (argparse lists a parser's arguments only
                     if not action.option_strings and action.dest != argparse.SUPPRESS]  # there)
            usage = " ".join([parser.prog, *(str(action.metavar or action.dest) for action in names
                                             if not isinstance(action, argparse._SubParsersAction))])  # noqa: SLF001
            for action in names:
                if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
                    parsers += [sub for name, sub in action.choices.items() if name in given]
                else:
                    positionals[action.dest] = (str(action.metavar or action.dest), usage)
        for flag in (token.split("=", 1)[0] for token in given if token.startswith("--")):
            found = positionals.get(flag[2:].replace("-", "_"))
            if found is not None:
                shown, usage = found
                return f"unrecognized argument {flag}: {shown} is given without a flag, by its place ({usage} ...)"
        return None

    @staticmethod
    def _after_the_end(given: list[str], ended: int, options: list[str]) -> str | None:
        """The line for ``options`` written after the ``--`` at ``given[ended]``, which ends the options; None where
        none is."""
        after = [token.split("=", 1)[0] for token in given[ended + 1:]]
        if not (moved := sorted(set(after) & set(options))):
            return None
        return (f"{' and '.join(moved)} {'comes' if len(moved) == 1 else 'come'} after '--', which ends the options "
                "(what follows it is taken as file names); give the options before '--'")

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                         namespace: argparse.Namespace | None = None) -> tuple[argparse.Namespace, list[str]]:
        """As argparse's, but an option that holds one value, written twice, is a :class:`PigaError` (one line, exit 1)
        rather than the last one silently winning (``--dt 0.05 --dt 0.1``). Options meant to repeat (``append``,
        ``extend``, ``count``) may. Each parser (a subcommand's too) checks its own options."""
        self._given_once: dict[argparse.Action, list[str]] = {}
        self._given_args = list(sys.argv[1:] if args is None else args)  # for error(): the options as written
        for action in self._actions:  # config fields named in a config's ValueError are shown as these flags
            longs = [s for s in action.option_strings if s.startswith("--")]
            if longs and action.dest not in ("help", argparse.SUPPRESS):
                _FLAGS[action.dest] = longs[0]
        return super().parse_known_args(args, namespace)

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> Any:
        # argparse converts each occurrence of an option here, with the text as written (``--dt=0.1`` too)
        if action.option_strings and isinstance(action, ONCE_ACTIONS):
            if (first := self._given_once.get(action)) is not None:
                flag = "/".join(action.option_strings) if isinstance(action, argparse.BooleanOptionalAction) \
                    else max(action.option_strings, key=len)
                values = f" ({' '.join(first)}, then {' '.join(arg_strings)})" if arg_strings else ""
                raise PigaError(f"{flag} is given twice{values}: give it once")
            self._given_once[action] = list(arg_strings)
        return super()._get_values(action, arg_strings)


#: The kinds of option that hold one value (store, store_const, store_true/false, --x/--no-x); written twice, the
#: last would silently win. ``append``, ``extend`` and ``count`` are meant to repeat.
ONCE_ACTIONS: tuple[type[argparse.Action], ...] = (
    argparse._StoreAction, argparse._StoreConstAction, argparse.BooleanOptionalAction)  # noqa: SLF001


def nonempty_text(text: str) -> str:
    """argparse type: any text but the empty one (a path, a run folder, a range)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a value, got {text!r}")
    return text


def file_path(text: str) -> str:
    """argparse type: the path of a file to write. One that ends in a separator names a folder, which the
    file system would otherwise quietly drop (``x.h5/`` would write ``x.h5``)."""
    text = nonempty_text(text)
    if text.endswith(("/", os.sep)) or Path(text).name in ("", ".", ".."):  # ".", "..": folders too
        raise argparse.ArgumentTypeError(f"expected a file name, got the folder {text!r}; name the file to write in it")
    return text


def stem_path(text: str) -> str:
    """argparse type: the stem of a set of files to write (``piga-control --out OUT``: OUT.json, OUT.md), a
    :func:`file_path`; an existing folder is refused, as by :func:`h5_path`: its files would be written beside it."""
    text = file_path(text)
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; name the files to write in it without their suffix "
                                         f"(such as {os.path.join(text, 'results')})")
    return text


#: The suffixes of an HDF5 file a command writes (``piga-collect --out``, ``piga-import --out``), in any case.
H5_SUFFIXES = (".h5", ".hdf5")


def h5_path(text: str) -> str:
    """argparse type: the path of an HDF5 file to write (:func:`file_path`), ending in one of :data:`H5_SUFFIXES`; a
    folder, a path without the suffix (``o``) or with another (``o.txt``) is refused before anything is written."""
    text = file_path(text)
    accepted = " or ".join(H5_SUFFIXES)
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; name the {accepted} file to write in it")
    if Path(text).suffix.lower() not in H5_SUFFIXES:
        raise argparse.ArgumentTypeError(f"expected an HDF5 file ending in {accepted}, got {text!r}")
    return text


#: Exceptions that are the user's to fix; any other exception is a bug, and ``run_cli`` writes its
#: traceback to a log file (:func:`log_folder`).
USER_ERRORS: tuple[type[BaseException], ...] = (
    PigaError,
    DataFormatError,
    OutputExistsError,
    FileNotFoundError,
    FileExistsError,
    PermissionError,
    IsADirectoryError,
    NotADirectoryError,
    ValueError,
    MissingExtraError,
    BackendError,
)


def command_line(prog: str, argv: Sequence[str] | None) -> str:
    """The command as typed, for records: ``prog`` and ``argv`` (default: this process's arguments).

    Under a non-UTF-8 locale (``LC_ALL=C`` with ``PYTHONUTF8=0``) Python holds the bytes of a non-ASCII argument as
    lone surrogates, which no UTF-8 record (an HDF5 attribute, JSON) can store; they are turned back into the bytes
    typed and read as UTF-8 (a byte that is not UTF-8 becomes U+FFFD), so ``lc_ü.h5`` is recorded as typed."""
    import shlex

    words = [prog, *(sys.argv[1:] if argv is None else argv)]
    return shlex.join(typed_text(w) for w in words)


def typed_text(text: str) -> str:
    """A name as the user typed it, for records, pages and figures: under a non-UTF-8 locale (``LC_ALL=C`` with
    ``PYTHONUTF8=0``) Python holds a non-ASCII name's bytes as lone surrogates, which neither UTF-8 text nor
    matplotlib's fonts take; they are read back as UTF-8 (a byte that is not UTF-8 becomes U+FFFD)."""
    return os.fsencode(text).decode("utf-8", "replace")


def warn_if_unconverged(prog: str, run_dir: str | os.PathLike[str]) -> None:
    """Prints one warning line when the run's metrics.json says it did not converge (:func:`piga.io.runs.convergence_warning`),
    or when another command still trains it (:func:`piga.io.lock.held_by`): its checkpoint is then the last saved."""
    from piga.io.runs import convergence_warning

    if not warn_if_still_training(prog, run_dir) and (warning := convergence_warning(run_dir)) is not None:
        print(f"{prog}: {warning}", file=sys.stderr)


def warn_if_still_training(prog: str, run_dir: str | os.PathLike[str]) -> bool:
    """Prints one warning line, and returns True, when another command still trains the run
    (:func:`piga.io.lock.held_by`): what its records say is of its last checkpoint, not of its end."""
    from piga.io.lock import held_by

    if (pid := held_by(run_dir)) is None:
        return False
    print(f"{prog}: warning: the run {run_dir} is still being trained (PID {pid}); this used its last checkpoint, "
          "not its final model", file=sys.stderr)
    return True


def _in_import(frame: Any) -> bool:
    """Whether ``frame`` (a Python frame) runs inside an import: importlib's frames are in its stack."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


#: The last signal that interrupted the command's work (:func:`_raise_interrupt`); SIGINT for a KeyboardInterrupt
#: raised otherwise (Python's own handler).
_SIGNALLED = [int(signal.SIGINT)]

#: Set while an interrupt waits for an import to end (:func:`_raise_interrupt`).
_DEFERRED = threading.Event()


def _raise_interrupt(signum: int, frame: Any) -> None:
    """SIGINT and SIGTERM during a command's work: KeyboardInterrupt, so that ``finally`` blocks run, except inside an
    import. A library's import runs Python code from C++ (torch's, through pybind11), where a KeyboardInterrupt cannot
    pass: the process aborted ("terminate called after throwing an instance of 'pybind11::error_already_set'"), or
    Python marked the interrupt unhandled and, after the command's own line, ended by SIGINT (exit -2, not 130). There
    the interrupt waits for the import to end (a thread looks every 5 ms; imports take at most a second or two) and is
    raised then. Python's signal module offers no deferral of its own; masking the signal would also hold it back
    from the blocking calls that it should interrupt."""
    _SIGNALLED[0] = signum  # the exit code says which signal ended the command (128 + its number, as a shell's)
    if not _in_import(frame):
        raise KeyboardInterrupt
    if _DEFERRED.is_set():  # one is already waiting
        return
    _DEFERRED.set()
    main = threading.main_thread().ident

    def deliver() -> None:
        import time

        while _in_import(sys._current_frames().get(main)):
            time.sleep(0.005)
        _DEFERRED.clear()
        if _RUNNING.is_set() and main is not None:  # (the work may have ended meanwhile: nothing left to stop)
            signal.pthread_kill(main, signum)  # a signal, not _thread.interrupt_main: it wakes a blocking call too

    threading.Thread(target=deliver, name="piga-deferred-interrupt", daemon=True).start()


def _exit_quietly_on_late_signals(finished: str | None = None) -> None:
    """SIGINT and SIGTERM from now on end the process at once (128 + the signal), with the line ``finished`` where the
    command finished its work (a report complete, yet exit 130 and no word looked like a lost run), quietly where it
    had already said why it ended. The command's work is over; an interrupt raised in the interpreter's shutdown
    (torch's atexit hooks) printed a 10-line traceback."""
    said = (finished + "\n").encode("utf-8", "replace") if finished else b""

    def end(number: int, frame: object) -> None:
        if said:
            with contextlib.suppress(OSError):
                os.write(2, said)
        os._exit(128 + number)

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, end)


#: Set by :func:`work_finished` while a command runs: its outputs are complete.
_FINISHED = threading.Event()

#: The late line of a command whose outputs are complete (:func:`work_finished`, :func:`run_cli`).
_FINISHED_LINE = "{prog}: interrupted after it finished its work; its outputs are complete"


def held_run_error(run_dir: Path, kind: Any) -> PigaError:
    """The refusal of ``run_dir``, which already holds a run, for a command that writes runs of ``kind`` (a
    :class:`~piga.io.checkpoint.RunKind`) without --resume or --overwrite: --resume where the run is of that kind;
    where it is another's (its record says), another --out, since --resume would refuse it. It lists every output of
    any kind of run that the folder holds (:data:`~piga.io.checkpoint.RUN_OUTPUTS`), not only this command's."""
    import zipfile

    from piga.io.checkpoint import CHECKPOINT, RUN_OUTPUTS, held_kind

    files = ", ".join(name for name in RUN_OUTPUTS if (run_dir / name).exists())
    other = held_kind(run_dir)
    if other is not None and other is not kind:
        return PigaError(f"{run_dir} already holds a {other.writer} run ({files}); give another --out, or --overwrite "
                         "to replace it")
    if not zipfile.is_zipfile(run_dir / CHECKPOINT):  # torch writes a zip; cut short, its end is missing: no --resume
        return PigaError(f"{run_dir} already holds a run ({files}) whose {CHECKPOINT} cannot be read (not a whole "
                         "checkpoint: cut short or damaged), so --resume cannot continue it; pass --overwrite to start "
                         "it again, or give another --out")
    return PigaError(f"{run_dir} already holds a run ({files}); pass --resume to continue it or --overwrite to replace "
                     "it")


def check_not_demo_folder(run_dir: Path) -> None:
    """Refuses a piga-demo's folder as the --out of a command that writes a run, with or without --overwrite: the run
    would sit among the demo's files, or replace them in part, and piga-demo would then refuse the folder."""
    from piga.io.checkpoint import DEMO_RUN, is_demo_folder

    if is_demo_folder(run_dir):
        raise PigaError(f"--out {run_dir} is a piga-demo's folder (its run is {run_dir / DEMO_RUN}); a run of your own "
                        "goes in a folder of its own: give another --out")


def resume_option(overwrite: bool) -> str:
    """The option that continues an interrupted run, as its line names it: ``--resume``, or for a command given
    --overwrite, which refuses --resume beside it, ``--resume in place of --overwrite``."""
    return "--resume in place of --overwrite" if overwrite else "--resume"


def work_finished() -> None:
    """Called by a command once its outputs are complete (before what it prints about them): a signal from then on
    says so, and in the command's own process ends it at once (128 + the signal). Between a command's last write and
    its return, an interrupt said "nothing was written" beside a complete output set."""
    _FINISHED.set()
    if _OWN_PROG:
        _exit_quietly_on_late_signals(_FINISHED_LINE.format(prog=_OWN_PROG[0]))


#: The command's name while it runs in its own process (``run_cli`` with ``argv=None``).
_OWN_PROG: list[str] = []


def _ignore_signals_at_exit() -> None:
    """The last of a command's ``atexit`` hooks: SIGINT and SIGTERM are ignored while the interpreter shuts down.
    Python sets their handlers back to the default there, so a Ctrl-C at that moment killed a command that had
    already said why it ended (its error line, then exit -2 for its 1). Python keeps an ignored signal ignored."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)


#: Set while a command's ``main`` runs (:func:`run_cli`): an interrupt delivered again then still has work to stop.
_RUNNING = threading.Event()


def _interrupt_again(previous: Callable[[Any], object], unraisable: Any) -> None:
    """``sys.unraisablehook`` during a command: an interrupt that landed in a callback Python cannot raise from (a
    weakref's, during garbage collection) printed "Exception ignored in ... Traceback ... KeyboardInterrupt" and was
    lost. It is delivered again a moment later, from another thread (delivered from here, Python would raise it
    inside this hook), so that it is raised where the command's code runs; once the command's work is done, there is
    nothing left for it to stop, and it is dropped."""
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        def deliver() -> None:
            if _RUNNING.is_set():
                import _thread

                _thread.interrupt_main()

        if _RUNNING.is_set():
            threading.Timer(0.01, deliver).start()
        return
    previous(unraisable)  # anything else as before


def run_cli(prog: str, main: Callable[[Sequence[str] | None], int | None], argv: Sequence[str] | None = None) -> NoReturn:
    """Runs ``main(argv)`` and exits; user errors become ``prog: error: ...`` on stderr (exit 1).

    An unexpected exception (a bug) prints one line that names a log file in :func:`log_folder`
    holding the traceback, and exits with :data:`INTERNAL_ERROR`. A job of a farm that failed
    (:class:`~piga.io.pool.JobFailed`) is judged by its own error, and the line names the job.

    SIGTERM is turned into KeyboardInterrupt, so that ``finally`` blocks run. That is how a partly
    written output file gets removed.
    """
    signal.signal(signal.SIGTERM, _raise_interrupt)
    _SIGNALLED[0] = int(signal.SIGINT)
    _FINISHED.clear()
    _OWN_PROG[:] = [prog] if argv is None else []
    if argv is None:  # the command's own process; registered first, so run last (atexit runs its hooks in reverse)
        import atexit

        atexit.register(_ignore_signals_at_exit)
    from piga.cli import _early_interrupt

    if signal.getsignal(signal.SIGINT) is _early_interrupt:  # the libraries are loaded: Ctrl-C stops the work
        signal.signal(signal.SIGINT, _raise_interrupt)
    unraisablehook = sys.unraisablehook
    sys.unraisablehook = functools.partial(_interrupt_again, unraisablehook)
    _open_closed_standard_streams()
    try:  # torch's MKL cannot load in a deleted folder (a fatal exit, no Python error), and relative paths mean nothing
        os.getcwd()
    except FileNotFoundError:
        print(f"{prog}: error: the current folder no longer exists (it was deleted or moved); cd to a folder that "
              "exists and run the command again", file=sys.stderr)
        sys.exit(1)
    _writable_matplotlib_folder()
    import tqdm  # its monitor thread, started with the first bar, warned in 3 lines where no thread could start

    tqdm.tqdm.monitor_interval = 0
    stdout, sys.stdout = sys.stdout, _GuardedStream(sys.stdout)
    # (stderr too: progress bars onto a full disk, `2> log`, stopped collect and training, their files removed, exit 1)
    stderr, sys.stderr = sys.stderr, _GuardedStream(sys.stderr)
    _FLAGS.clear()  # this command's parsers fill it
    excepthook, threading.excepthook = threading.excepthook, _thread_errors_to_log(prog, argv)
    code: int | str | None
    finished = "; the command itself finished and its outputs are complete"
    returned = False
    try:
        _RUNNING.set()
        code = main(argv)
        returned = True
        _RUNNING.clear()
        sys.stdout.flush()
    except SystemExit as exc:  # argparse's own exits (--help, a usage error): what it printed may have failed too
        code, finished = exc.code, ""
        sys.stdout.flush()
    except KeyboardInterrupt as exc:
        kept = str(exc) if isinstance(exc, Interrupted) else "nothing was written"
        _close_progress_bars()
        print(_FINISHED_LINE.format(prog=prog) if _FINISHED.is_set() else f"{prog}: interrupted; {kept}", file=sys.stderr)
        sys.exit(128 + _SIGNALLED[0])  # 130 for Ctrl-C, 143 for SIGTERM
    except Exception as exc:
        _exit_on_error(prog, argv, exc)
    finally:
        _RUNNING.clear()
        if argv is None:  # the command's own process, its work over and its exit code decided
            _exit_quietly_on_late_signals(_FINISHED_LINE.format(prog=prog) if returned else None)
        guard, sys.stdout, sys.stderr = sys.stdout, stdout, stderr
        threading.excepthook, sys.unraisablehook = excepthook, unraisablehook
        release_run_folders()  # a command run in-process (a test, a notebook) releases its run folder as it returns
    if isinstance(guard, _GuardedStream) and guard.failed is not None:
        # The work is done and its files are complete; only the report was lost. Exit 1 all the same
        # (as coreutils do), so that a script notices, but say that a rerun is not needed. A command that
        # failed on its own (a usage error, a run that did not converge) keeps its own code.
        reason = guard.failed.strerror or guard.failed.__class__.__name__
        with contextlib.suppress(OSError):  # stderr failed too: the exit code alone says it
            print(f"{prog}: error: could not write to standard output ({reason}){finished}", file=sys.stderr)
        sys.exit(code if isinstance(code, int) and code != 0 else 1)
    sys.exit(code or 0)


def run_script(main: Callable[..., int | None], path: str) -> NoReturn:
    """A benchmark script's entry (``if __name__ == "__main__": run_script(main, __file__)``): :func:`run_cli`
    under the script's file name, so that its bad input is one line too; ``main`` with or without ``argv``."""
    run_cli(Path(path).name, script_entry(main))


def script_entry(main: Callable[..., int | None]) -> Callable[[Sequence[str] | None], int | None]:
    """A benchmark script's ``main`` as :func:`run_cli` runs it (:func:`run_script`): with ``argv`` where it takes
    it (else it reads ``sys.argv``), and an interrupt said as a farm's."""
    import inspect

    takes_argv = bool(inspect.signature(main).parameters)

    def script(argv: Sequence[str] | None) -> int | None:
        try:
            return main(argv) if takes_argv else main()
        except KeyboardInterrupt:  # a farm keeps the records of the jobs that ended: not "nothing was written"
            raise Interrupted("what finished before is kept (each script keeps its jobs' records as they end); run "
                              "the same command to continue") from None

    return script


def _writable_matplotlib_folder() -> None:
    """matplotlib keeps its settings and font cache in ``MPLCONFIGDIR``, else under ``~/.config`` and ``~/.cache``;
    where it cannot write there (a read-only or missing HOME) it made a temporary folder and said so in two warnings
    on stderr. piga gives it a temporary folder first, quietly, removed at exit. Nothing is created to find out."""
    def writable(folder: Path) -> bool:  # the folder, or the nearest existing folder it would be made in
        existing = next((p for p in (folder, *folder.parents) if p.exists()), None)
        if existing is None or not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
            return False
        try:  # /proc and /sys pass os.access as root, yet take no new folder
            return existing == folder or shutil.disk_usage(existing).total > 0
        except OSError:
            return False

    if "MPLCONFIGDIR" in os.environ:
        folders = [Path(os.environ["MPLCONFIGDIR"])]
    else:
        try:
            home = Path.home()
        except (RuntimeError, KeyError):  # no HOME and no user entry
            home = None
        folders = [Path(os.environ[var]) / "matplotlib" if os.environ.get(var) else
                   (home / sub / "matplotlib" if home is not None else None)
                   for var, sub in (("XDG_CONFIG_HOME", ".config"), ("XDG_CACHE_HOME", ".cache"))]
    if all(folder is not None and writable(folder) for folder in folders):
        return
    import atexit

    try:
        folder = tempfile.mkdtemp(prefix="piga-matplotlib-")
    except OSError:  # no temporary folder either: matplotlib says what it can
        return
    os.environ["MPLCONFIGDIR"] = folder
    atexit.register(shutil.rmtree, folder, True)


def _open_closed_standard_streams() -> None:
    """Started with stdin, stdout or stderr closed (``>&-``), Python has ``None`` for it, and the next file
    opened would take its descriptor, so that a library's write to "stdout" would land in a data file. Each
    closed one is opened on the null device, as daemons do: what it would have shown is dropped. So is a stdout or
    stderr open for reading only (closed by ``2>&-`` under a launcher that then opened a file, as pyenv's shim
    opens its script): the first write to it failed, and the command with it."""
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        if not _usable(fd, mode):
            _null_onto(fd)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, mode, closefd=False))  # noqa: SIM115 (for the process's life)
    with contextlib.suppress(AttributeError, ValueError):  # under LC_ALL=C (ASCII), '--help' has θ and ·: escape them
        sys.stdout.reconfigure(errors="backslashreplace")


def _usable(fd: int, mode: str) -> bool:
    """Whether descriptor ``fd`` is open, and, for ``mode`` "w", open for writing (POSIX's access mode; elsewhere,
    being open is all that can be asked)."""
    try:
        import fcntl
    except ImportError:
        fcntl = None  # type: ignore[assignment]
    try:
        if fcntl is None:
            os.fstat(fd)
            return True
        access = fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE  # raises for a closed descriptor
    except OSError:
        return False
    return mode != "w" or access != os.O_RDONLY


def _null_onto(fd: int) -> None:
    """Points file descriptor ``fd`` at the null device (what was written to it is dropped)."""
    null = os.open(os.devnull, os.O_RDWR)
    if null != fd:
        os.dup2(null, fd)
        os.close(null)


class _GuardedStream:
    """``sys.stdout`` or ``sys.stderr`` during a command: a failed write (``> /dev/full``, ``2> log`` on a full
    disk, a closed pipe) must not stop a command whose files are being written, nor leave it half done. The first
    failure is kept in :attr:`failed`, later output is dropped, and ``run_cli`` reports a failed stdout after the
    command finished (on stderr; a failed stderr has nowhere to be said, and the exit code is the command's own).

    Python's own stream objects have no such mode; their buffers would raise again at exit, so the stream's file
    descriptor is pointed at the null device once a write failed.
    """

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self.failed: OSError | None = None

    def write(self, text: str) -> int:
        if self.failed is None:
            try:
                return self._stream.write(text)
            except OSError as exc:
                self._fail(exc)
        return len(text)

    def flush(self) -> None:
        if self.failed is None:
            try:
                self._stream.flush()
            except OSError as exc:
                self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        self.failed = exc
        with contextlib.suppress(OSError, ValueError, AttributeError):  # no descriptor (a test's capture)
            _null_onto(self._stream.fileno())

    def __getattr__(self, name: str) -> Any:  # isatty, encoding, fileno, ...: the stream's own
        return getattr(self._stream, name)


def _close_progress_bars() -> None:
    """Closes tqdm's bars still open (an error or an interrupt left their loop), so that the command's last line is
    not written into a bar's line, nor a bar redrawn after it when the bar is collected."""
    from tqdm import tqdm

    # tqdm keeps its open bars in the class's _instances (what its own tqdm.write uses); it has no public list
    for bar in list(getattr(tqdm, "_instances", ())):
        with contextlib.suppress(Exception):  # a bar half built, or its stream gone: nothing more to show
            bar.leave = False  # cleared, not left standing above the error line
            bar.close()


def _exit_on_error(prog: str, argv: Sequence[str] | None, exc: Exception) -> NoReturn:
    """Prints the one line of the exception being handled and exits: 1 for the user's errors (and out of memory or
    disk), :data:`INTERNAL_ERROR` for a bug (its traceback in a log file)."""
    _close_progress_bars()
    error: BaseException = exc.cause if isinstance(exc, JobFailed) else exc
    job = f"job {exc.job} failed: " if isinstance(exc, JobFailed) else ""
    if isinstance(error, FileNotFoundError) and error.errno == errno.ENOENT and error.filename is not None:
        # the OS's own words ("[Errno 2] No such file or directory: b'run/tensorboard/...'"): a folder removed or
        # moved while the command wrote in it, most often
        print(f"{prog}: error: {job}{os.fsdecode(error.filename)}: no such file or folder (was a folder the command "
              "writes in removed or moved while it ran?); run the command again", file=sys.stderr)
    elif isinstance(error, FileNotFoundError) and error.errno == errno.ENOENT and \
            (opened := re.search(r"unable to open file: name = '(.*?)', errno = 2", str(error))):
        # h5py's: the file's name inside HDF5's message, not in ``filename``; a file checked at the start is gone
        print(f"{prog}: error: {job}{opened.group(1)}: no such file (removed or moved while it ran?); put it back, and "
              "run the command again", file=sys.stderr)
    elif isinstance(error, USER_ERRORS):
        message = " ".join(str(error).split()) or error.__class__.__name__
        if isinstance(error, ValueError) and not isinstance(error, DataFormatError):  # a config's check
            message = with_flags(message)
        print(f"{prog}: error: {job}{message}", file=sys.stderr)
    elif isinstance(error, OSError) and error.errno == errno.ENOSPC:  # wherever the disk filled up
        where = f"{error.filename}: " if error.filename else ""
        print(f"{prog}: error: {job}{where}the disk is full (no space left on device); free some space, or write "
              "elsewhere, and run the command again", file=sys.stderr)
    elif isinstance(error, OSError):  # h5py and friends: unreadable files
        print(f"{prog}: error: {job}{error.__class__.__name__}: {' '.join(str(error).split())}", file=sys.stderr)
    elif isinstance(error, MemoryError):
        print(f"{prog}: error: {job}out of memory ({' '.join(str(error).split()) or 'MemoryError'})", file=sys.stderr)
    elif isinstance(error, RuntimeError) and (wanted := _failed_allocation(error)) is not None:
        print(f"{prog}: error: {job}out of memory (an array of {wanted} did not fit); choose smaller sizes", file=sys.stderr)
    else:  # a bug: one line, and the traceback in a log file
        _internal_error(prog, argv, exc)
    sys.exit(1)


def _internal_error(prog: str, argv: Sequence[str] | None, exc: BaseException) -> NoReturn:
    """Prints the one line of a bug, writes the traceback of the exception being handled to a log file, and exits."""
    message = " ".join(str(exc).split())[:200]
    log = _write_traceback(prog, argv)
    where = f"the traceback is in {log}" if log else "the traceback could not be written to a log file"
    print(f"{prog}: internal error ({exc.__class__.__name__}: {message}); {where}; please report it", file=sys.stderr)
    sys.exit(INTERNAL_ERROR)


def _failed_allocation(exc: RuntimeError) -> str | None:
    """The size torch's CPU allocator could not get ("... you tried to allocate 120000000000 bytes"), as
    text such as "112 GiB"; None for any other RuntimeError."""
    from piga.io.resources import format_bytes

    found = re.search(r"can't allocate memory: you tried to allocate (\d+) bytes", str(exc))
    return None if found is None else format_bytes(float(found.group(1)))


def _required_flags(parser: argparse.ArgumentParser) -> list[str]:
    """The long names of the required options of ``parser`` and of its subcommands (their error reaches the parent's)."""
    flags = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            flags += [flag for sub in action.choices.values() for flag in _required_flags(sub)]
        elif action.required:
            flags += [flag for flag in action.option_strings if flag.startswith("--")]
    return flags


def check_model_folder(model: str, writers: str = "piga-train-model or piga-baseline") -> None:
    """Refuses a ``--model`` that is no folder (missing, a file, a link that loops) in one line; a run just started
    has no folder yet, and is said by the checkpoint's loader. ``writers``: the commands whose runs the caller takes."""
    from piga.io.atomic import link_loop, loop_message
    from piga.io.checkpoint import CHECKPOINT
    from piga.io.lock import held_by

    if Path(model).is_dir() or held_by(model) is not None:
        return
    if (loop := link_loop(model)) is not None:
        raise PigaError(loop_message(model, loop, "--model"))
    what = "is a file, not a run folder" if Path(model).exists() else "does not exist"
    raise PigaError(f"--model {model} {what} (give the folder that {writers} wrote its {CHECKPOINT} in)")


@contextlib.contextmanager
def made_folder(folder: str | os.PathLike[str]) -> Iterator[Path]:
    """Makes ``folder`` (and missing parents) for a command's outputs, and removes the folders it
    made again if the command fails or is interrupted while they are still empty: a refused or
    interrupted run leaves no empty folder behind. Folders that existed are never removed."""
    path = Path(folder)
    missing = missing_folders(path)
    path.mkdir(parents=True, exist_ok=True)
    try:
        yield path
    except BaseException:
        remove_empty_folders(missing)
        raise


def remove_outputs(run_dir: Path, names: Sequence[str], ignore_errors: bool = False) -> None:
    """Deletes the files and folders ``names`` of a run in ``run_dir`` that exist (a run's own outputs,
    before it is run again or after it was abandoned); nothing else in the folder is touched.
    ``ignore_errors``: a folder that cannot be removed stays (while another error is being raised)."""
    for name in names:
        path = run_dir / name
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=ignore_errors)
        elif path.exists():
            path.unlink()


#: Exit status of an unexpected internal error (BSD's EX_SOFTWARE); refused input, usage errors too, exits 1.
INTERNAL_ERROR = 70
#: Exit status of a training run that finished and saved its model but did not converge (its parameters still
#: moved at the end, or it stopped before its plan ended): the warning line says why, ``--resume`` continues it.
#: Not 0, so that a script cannot take it for an identification; not 1, so that it can tell it from a refusal.
NOT_CONVERGED = 3


def log_folder() -> Path:
    """Where internal errors leave their tracebacks: ``piga-logs`` in the system's temporary folder
    (``$TMPDIR``, else /tmp on Linux)."""
    return Path(tempfile.gettempdir()) / "piga-logs"


def _write_traceback(prog: str, argv: Sequence[str] | None) -> Path | None:
    """Writes the exception being handled, with the command line, to a new log file; returns its path."""
    import time
    import traceback

    from piga.io.atomic import atomic_output

    path = log_folder() / f"{prog}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path, overwrite=True) as tmp:
            tmp.write_text(f"{command_line(prog, argv)}\n\n{traceback.format_exc()}", encoding="utf-8",
                           errors="backslashreplace")  # (an ASCII locale's default cannot write ü)
    except OSError:
        return None
    return path


def _thread_errors_to_log(prog: str, argv: Sequence[str] | None) -> Callable[[Any], None]:
    """``threading.excepthook`` for a command: a library's background thread that fails (TensorBoard's event writer
    when its folder was moved away) would print its traceback on stderr beside the command's own line; it goes to a
    log file in :func:`log_folder` instead. What the failure means for the command, the command says itself."""

    def hook(args: Any) -> None:
        if args.exc_type is SystemExit:
            return
        import time
        import traceback

        path = log_folder() / f"{prog}-thread-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
        text = "".join(traceback.format_exception(args.exc_type, args.exc_value, args.exc_traceback))
        name = args.thread.name if args.thread is not None else "?"
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with path.open("a") as f:  # a thread's last words: appended, not atomic (several threads may fail)
                f.write(f"{command_line(prog, argv)}\n\nin thread {name}:\n{text}\n")
        except OSError:
            pass

    return hook


def number_type(convert: Callable[[str], float], ok: Callable[[float], bool], what: str) -> Callable[[str], Any]:
    """An argparse type that converts with ``convert`` and accepts values for which ``ok`` holds."""

    def parse(text: str) -> Any:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        value = value + 0  # -0.0 is 0.0: a range of -0 to 0 was "high - low < 0" in numpy
        if not ok(value):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
        return value

    parse.__name__ = what  # argparse names the type in some messages
    return parse


positive_int = number_type(int, lambda v: v >= 1, "a positive integer")
"""argparse type: an integer >= 1."""
nonnegative_int = number_type(int, lambda v: v >= 0, "an integer >= 0")
"""argparse type: an integer >= 0."""


def int_up_to(limit: int, why: str, least: int = 1) -> Callable[[str], Any]:
    """argparse type: an integer in [``least``, ``limit``]; ``why`` says what the limits are for."""
    return number_type(int, lambda v: least <= v <= limit, f"an integer in [{least}, {limit}] ({why})")


def int_at_least(limit: int, why: str) -> Callable[[str], Any]:
    """argparse type: an integer >= ``limit``; ``why`` says what the limit is for."""
    return number_type(int, lambda v: v >= limit, f"an integer >= {limit} ({why})")


positive_float = number_type(float, lambda v: 0 < v < float("inf"), "a finite number > 0")
"""argparse type: a finite number > 0 (NaN is rejected too)."""
any_float = number_type(float, lambda v: True, "a number")
"""argparse type: any float, -0 read as 0 (a range the config checks, with its own words)."""
nonnegative_float = number_type(float, lambda v: 0 <= v < float("inf"), "a finite number >= 0")
"""argparse type: a finite number >= 0 (NaN is rejected too)."""
unit_fraction = number_type(float, lambda v: 0 <= v < 1, "a number in [0, 1)")
"""argparse type: a fraction in [0, 1) (NaN is rejected too)."""
seed_int = number_type(int, lambda v: 0 <= v <= MAX_SEED, "an integer in [0, 2^63 - 1]")
"""argparse type: a seed, an integer in [0, 2^63 - 1]."""
thread_count = number_type(int, lambda v: 0 <= v <= MAX_THREADS, f"an integer in [0, {MAX_THREADS}] (0: torch's choice; "
                                                                  f"at most this machine's {MAX_THREADS} CPUs)")
"""argparse type: torch CPU threads, 0 (torch's choice) up to this machine's CPU count (more only slows it down,
and a huge count makes torch's thread pool crash)."""


#: What ``--ray`` does, in every command and benchmark that farms jobs (each adds what its jobs are).
RAY_HELP = ("run them as tasks of a Ray cluster, one CPU each, as many at once as it has free CPUs, instead of local "
            "processes: 'auto' joins the Ray instance running on this machine or starts one, HOST:PORT joins the "
            "cluster whose head is there (ray start --head prints it); the same results as local processes; needs "
            "pip install -e '.[ray]' (default: local processes)")


def ray_address(text: str) -> str:
    """argparse type of ``--ray``: "auto" or HOST:PORT (HOST alone: Ray's port 6379)."""
    text = text.strip()
    if text.lower() == "local":  # Ray's own word for a new instance, taken as a host name and run undocumented
        raise argparse.ArgumentTypeError("'local' is not a Ray address here: give 'auto' (the Ray instance running on "
                                         "this machine, or a new one) or HOST:PORT")
    if text != "auto":
        try:
            host_port(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def add_ray_option(parser: argparse.ArgumentParser, what: str) -> argparse.Action:
    """Adds ``--ray auto|HOST:PORT`` (default None: local processes), its help ``what`` (the jobs) and :data:`RAY_HELP`."""
    return parser.add_argument("--ray", type=ray_address, metavar="auto|HOST:PORT", help=f"{what}: {RAY_HELP}")


def connect_backend(ray: str | None) -> Backend:
    """The job backend of a ``--ray`` value (None: local processes), connected now, before any work: Ray not
    installed or no Ray cluster at the address is a :class:`PigaError` (one line)."""
    backend = Backend.from_option(ray)
    try:
        backend.connect()
    except BackendError as exc:
        raise PigaError(f"--ray {ray}: {exc}") from None
    return backend


def record_resume(record: dict[str, Any], command: str) -> None:
    """Adds a ``--resume`` invocation to a run's record (its ``config.json``): the command, and the commit of the code
    that continues it (``resumed_commits``, in step; None outside a git checkout), beside the ``commit`` it started at.
    A divergence that the record names goes (this resume's first checkpoint writes the record without it)."""
    from piga.io.checkpoint import DIVERGED
    from piga.io.pool import git_commit

    record.pop(DIVERGED, None)
    record.setdefault("resumed", []).append(command)
    record.setdefault("resumed_commits", []).append(git_commit())


def started_record(command: str, **fields: Any) -> dict[str, Any]:
    """A new run's record (its ``config.json``): the command, the commit of the code that runs it (None outside a git
    checkout) and ``fields``."""
    from piga.io.pool import git_commit

    return {"command": command, "commit": git_commit(), **fields}


def given_options(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> set[str]:
    """The destinations of ``parser``'s options (its subcommands' included) written in ``argv`` (None: the command
    line), whatever their values: an option given at its default value is given (the parsers take no abbreviations,
    so a flag is spelt whole)."""
    words = sys.argv[1:] if argv is None else list(argv)
    parsers, given = [parser], set()
    while parsers:  # the parser's options and its subcommands' (argparse has no public list of a parser's options;
        for action in parsers.pop()._actions:  # noqa: SLF001  _actions is the one every argparse extension reads)
            if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
                parsers.extend(action.choices.values())
            elif any(word == flag or word.startswith(flag + "=") for flag in action.option_strings for word in words):
                given.add(action.dest)
    return given


def recorded_options(parser: argparse.ArgumentParser, command: Any) -> dict[str, Any] | None:
    """The options written in the command that started a run (its record's ``command``, written by
    :func:`command_line`), as ``parser`` reads them now: what a ``--resume`` may repeat at the same values (an option
    the command did not write is not among them, even at its default). None where there is no command, or where it
    no longer parses (edited, from another version, or naming a file that is gone): then every recipe option given
    counts as a change."""
    import io
    import shlex

    if not isinstance(command, str):
        return None
    try:
        words = shlex.split(command)[1:]
        with contextlib.redirect_stderr(io.StringIO()):  # argparse's usage lines are not the user's error here
            parsed = vars(parser.parse_args(words))
    except (ValueError, SystemExit):
        return None
    written = given_options(parser, words)
    return {name: value for name, value in parsed.items() if name in written}


def format_default(value: Any) -> str:
    """A default as help text shows it: 1e-3 as 0.001, (0.8, 0.1, 0.1) as 0.8,0.1,0.1, True as on."""
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (tuple, list)):
        return ",".join(format_default(v) for v in value)
    return str(value)


def add_preset_option(parser: argparse.ArgumentParser, *flags: str, default: Any, help: str,  # noqa: A002
                      shown: str | None = None, **kwargs: Any) -> argparse.Action:
    """An option whose value, when not given, comes from a preset or a dataclass default.

    argparse's default stays None, so that the caller can tell a given value from a missing one
    (an explicit option overrides a preset). The default that applies without a preset is named in
    the help, from ``default``, and recorded on the action as ``documented_default`` (the README
    test reads it through :func:`documented_default`). ``shown`` replaces the value in the help
    (e.g. "no limit").
    """
    action = parser.add_argument(*flags, default=None, help=f"{help} (default {shown or format_default(default)})", **kwargs)
    action.documented_default = default  # type: ignore[attr-defined]
    return action


def add_device_option(parser: argparse.ArgumentParser, default: str) -> argparse.Action:
    """``--device {auto,cpu,cuda}`` (:mod:`piga.io.device`), defaulting to ``default``, the command's config
    dataclass's. A bad choice is argparse's one-line usage error; ``cuda`` without a GPU is refused when resolved."""
    from piga.io.device import DEVICE_HELP, DEVICES

    return parser.add_argument("--device", choices=DEVICES, default=default,
                               help=f"{DEVICE_HELP} (default %(default)s)")


def documented_default(action: argparse.Action) -> Any:
    """The default an option documents: the preset's (see :func:`add_preset_option`) or argparse's."""
    return getattr(action, "documented_default", action.default)


def split_type(text: str) -> tuple[float, float, float]:
    """argparse type: train,valid,test as three numbers, fractions (0.8,0.1,0.1) or counts (5000,500,500)."""
    parts = text.replace(":", ",").split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers like 0.8,0.1,0.1 or 5000,500,500, got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers (train,valid,test), got {text!r}")
    if any(not v >= 0 or v == float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"expected three finite numbers >= 0 (train,valid,test), got {text!r}")
    return values  # type: ignore[return-value]


__all__ = ["ArgumentParser", "PigaError", "RAY_HELP", "add_ray_option", "connect_backend", "ray_address", "run_cli", "run_script", "positive_int", "nonnegative_int", "seed_int", "thread_count", "positive_float", "nonnegative_float",
           "split_type", "add_preset_option", "documented_default", "format_default", "Interrupted", "made_folder",
           "missing_folders", "remove_empty_folders", "check_model_folder", "remove_outputs", "add_device_option", "file_path", "stem_path", "h5_path",
           "H5_SUFFIXES"]
