"""tqdm bars that leave no trace of a failed command: a bar closed while an error or an interrupt propagates is
cleared rather than left standing (``collect spring: 92%| 11/12``) on the line above the command's one error line."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from typing import Any

from tqdm.auto import tqdm


def close_bar(bar: tqdm) -> None:
    """Closes ``bar``: kept on screen after work that ended, cleared when called while an exception propagates (from
    a ``finally`` block or an ``except`` clause), so that the error is the only line the command leaves."""
    if sys.exc_info()[0] is not None:
        bar.leave = False
    bar.close()


@contextlib.contextmanager
def progress_bar(**kwargs: Any) -> Iterator[tqdm]:
    """``with tqdm(**kwargs) as bar``, but closed by :func:`close_bar`."""
    bar = tqdm(**kwargs)
    try:
        yield bar
    finally:
        close_bar(bar)


__all__ = ["close_bar", "progress_bar"]
