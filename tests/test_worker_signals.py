"""Worker processes end on the pool's SIGTERM whichever thread receives it (pygame's SDL starts threads)."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import time

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")


def _caught_and_ignored() -> tuple[int, int]:
    """This process' signal masks from /proc: (caught, ignored), one bit per signal (bit n-1 for signal n)."""
    fields = dict(line.split(":\t") for line in open("/proc/self/status").read().splitlines()
                  if line.startswith(("SigCgt", "SigIgn")))
    return int(fields["SigCgt"], 16), int(fields["SigIgn"], 16)


def _render_then_wait(init_name: str, report: mp.Queue, tasks: mp.Queue) -> None:
    """A pool worker's life: its initializer, frames rendered (SDL starts), then blocked on the task queue."""
    from envs.pendulum import make_pixel_pendulum
    from piga.io import pool

    getattr(pool, init_name)()
    env = make_pixel_pendulum()
    env.reset(seed=0)
    env.step(env.action_space.sample())
    report.put(_caught_and_ignored())
    tasks.get()  # never comes: the parent terminates this worker here


def test_pool_worker_keeps_sigterm_default_and_dies_on_it() -> None:
    """After rendering, SIGTERM is neither caught (a Python handler runs only in the main thread, and
    SDL's handler turns it into an unread quit event) nor ignored, so the kernel ends the process
    even when it delivers the signal to SDL's thread; and the blocked worker does end on it."""
    ctx = mp.get_context("spawn")  # a fresh process: SDL starts after the initializer, as in a pool worker
    report, tasks = ctx.Queue(), ctx.Queue()
    worker = ctx.Process(target=_render_then_wait, args=("init_worker", report, tasks), daemon=True)
    worker.start()
    try:
        caught, ignored = report.get(timeout=120)
        assert not caught & (1 << (signal.SIGTERM - 1)), "SIGTERM has a handler in the worker"
        assert not ignored & (1 << (signal.SIGTERM - 1))
        assert ignored & (1 << (signal.SIGINT - 1)), "Ctrl-C is the parent's to handle"
        worker.terminate()  # SIGTERM, as Pool.terminate sends
        deadline = time.monotonic() + 10
        while worker.is_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert worker.exitcode == -signal.SIGTERM
    finally:
        if worker.is_alive():
            worker.kill()


def _terminated_before_its_set_up() -> None:
    """A pool worker whose parent's terminate lands between the fork and the worker's own signal set-up."""
    from piga.io.pool import init_worker

    os.kill(os.getpid(), signal.SIGTERM)
    init_worker()
    time.sleep(5)  # not reached: the held SIGTERM ends the worker as init_worker unblocks it


def test_a_sigterm_before_the_worker_set_up_still_ends_it() -> None:
    """With the parent's Python handler inherited (a command's), such a SIGTERM used to be dropped, and the pool's
    exit waited for the worker for ever; workers forked under sigterm_held end with SIGTERM's default."""
    from piga.io.worker_signals import sigterm_held

    old = signal.signal(signal.SIGTERM, lambda *_: None)  # the parent's own handler, inherited by the fork
    try:
        with sigterm_held():
            worker = mp.get_context("fork").Process(target=_terminated_before_its_set_up)
            worker.start()
        worker.join(30)
        assert worker.exitcode == -signal.SIGTERM
    finally:
        signal.signal(signal.SIGTERM, old)
