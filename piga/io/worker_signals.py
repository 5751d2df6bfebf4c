"""Signals in worker processes (control pools, collection's vector-env workers).

A worker leaves Ctrl-C to its parent (which prints one line and cleans up) and ends at once, quietly,
when the parent terminates it with SIGTERM, or when the parent dies.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys


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


def die_with_parent() -> None:
    """Asks Linux to send this process SIGTERM when its parent ends (prctl PR_SET_PDEATHSIG); elsewhere nothing."""
    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
