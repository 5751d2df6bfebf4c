"""What every piga command shares: one-line errors, no tracebacks, and clean interruption."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn


from piga.atomic import OutputExistsError
from piga.data import DataFormatError


class PigaError(Exception):
    """An error a user can fix; the command prints its message as one line."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse that reports a usage error as a single line on stderr (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


#: Exceptions that are the user's to fix; any other exception is a bug and keeps its traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (
    PigaError,
    DataFormatError,
    OutputExistsError,
    FileNotFoundError,
    PermissionError,
    IsADirectoryError,
    NotADirectoryError,
    ValueError,
)


def command_line(prog: str, argv: Sequence[str] | None) -> str:
    """The command as typed, for records: ``prog`` and ``argv`` (default: this process's arguments)."""
    import shlex

    return shlex.join([prog, *(sys.argv[1:] if argv is None else argv)])


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def run_cli(prog: str, main: Callable[[Sequence[str] | None], int | None], argv: Sequence[str] | None = None) -> NoReturn:
    """Runs ``main(argv)`` and exits; user errors become ``prog: error: ...`` on stderr.

    SIGTERM is turned into KeyboardInterrupt, so that ``finally`` blocks run. That is how a partly
    written output file gets removed.
    """
    signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        code = main(argv)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted; nothing was written", file=sys.stderr)
        sys.exit(130)
    except USER_ERRORS as exc:
        message = " ".join(str(exc).split()) or exc.__class__.__name__
        print(f"{prog}: error: {message}", file=sys.stderr)
        sys.exit(1)
    except OSError as exc:  # h5py and friends: disk full, unreadable files
        print(f"{prog}: error: {exc.__class__.__name__}: {' '.join(str(exc).split())}", file=sys.stderr)
        sys.exit(1)
    sys.exit(code or 0)


def _number_type(convert: Callable[[str], float], ok: Callable[[float], bool], what: str) -> Callable[[str], Any]:
    """An argparse type that converts with ``convert`` and accepts values for which ``ok`` holds."""

    def parse(text: str) -> Any:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not ok(value):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
        return value

    parse.__name__ = what  # argparse names the type in some messages
    return parse


positive_int = _number_type(int, lambda v: v >= 1, "a positive integer")
"""argparse type: an integer >= 1."""
nonnegative_int = _number_type(int, lambda v: v >= 0, "an integer >= 0")
"""argparse type: an integer >= 0."""
positive_float = _number_type(float, lambda v: 0 < v < float("inf"), "a finite number > 0")
"""argparse type: a finite number > 0 (NaN is rejected too)."""


def split_type(text: str) -> tuple[float, float, float]:
    """argparse type: train,valid,test as three numbers, fractions (0.8,0.1,0.1) or counts (5000,500,500)."""
    parts = text.replace(":", ",").split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers like 0.8,0.1,0.1 or 5000,500,500, got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers (train,valid,test), got {text!r}")
    return values  # type: ignore[return-value]


__all__ = ["ArgumentParser", "PigaError", "run_cli", "positive_int", "nonnegative_int", "positive_float", "split_type"]
