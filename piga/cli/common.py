"""What every piga command shares: one-line errors, no tracebacks, and clean interruption."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn


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


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def nonnegative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {value}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


__all__ = ["ArgumentParser", "PigaError", "run_cli", "positive_int", "nonnegative_int", "positive_float"]
