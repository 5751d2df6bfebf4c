"""Signals in worker processes (control pools, collection's vector-env workers).

A worker leaves Ctrl-C to its parent (which prints one line and cleans up) and ends at once, quietly,
when the parent terminates it with SIGTERM, or when the parent dies.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
from collections.abc import Iterator


def quiet_worker_signals() -> None:
    """Call first in a worker, before anything renders: SIGINT ignored, SIGTERM at its default action.

    SIGTERM keeps the kernel's default, which ends the whole process whichever of its threads the
    signal is delivered to. A Python handler does not: it runs only in the main thread, between
    bytecodes. pygame starts SDL's timer thread at the first render, and a SIGTERM delivered to that
    thread while the main thread sat blocked on the pool's task queue was never acted on, so
    ``Pool.terminate`` waited for the worker forever (seen once in a long benchmark).

    SDL is told to leave the default alone (its hint ``SDL_NO_SIGNAL_HANDLERS``, read from the
    environment when SDL starts): without it, SDL takes over a default SIGTERM and turns it into a
    quit event that nobody reads.
    """
    os.environ["SDL_NO_SIGNAL_HANDLERS"] = "1"
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):  # a SIGTERM held since the fork (see sigterm_held) ends the worker now
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})


@contextlib.contextmanager
def sigterm_held() -> Iterator[None]:
    """Holds SIGTERM back from this thread while workers are forked, then delivers any that came.

    A forked worker starts with its parent's SIGTERM handler (a command's, which raises KeyboardInterrupt) until
    :func:`quiet_worker_signals` sets the default. A SIGTERM from ``Pool.terminate`` in that gap was marked
    pending for the parent's Python handler, found the default there when Python looked, and was dropped: the
    worker lived on, blocked on the task queue, and the pool's exit waited for it for ever (seen in the suite,
    when a job failed at once). Workers forked while SIGTERM is blocked inherit the block (so do the pool's
    threads, which fork replacements), and :func:`quiet_worker_signals` unblocks it after setting the default.
    """
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def die_with_parent() -> None:
    """Asks Linux to send this process SIGTERM when its parent ends (prctl PR_SET_PDEATHSIG); elsewhere nothing."""
    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
