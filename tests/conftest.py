"""Shared fixtures: tiny data files made once per session."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

# Under pytest-xdist the tests share the cores: one torch thread per worker, and for the commands the
# tests start (two processes with torch's default threads on 2 cores ran 15-20x slower than one each).
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)

# A shell starts background jobs (`pytest &`) with SIGINT ignored, and the commands that the tests
# start would inherit that and never see the Ctrl-C the interrupt tests send. A handler, unlike
# SIG_IGN, is reset to the default in a started command.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _internal_error_logs_stay_in_the_tests_folders(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch,
                                                   tmp_path_factory: pytest.TempPathFactory) -> None:
    """The tests that provoke an internal error (exit 70) left its log in the machine's own piga-logs folder on every
    run: a test's logs go to its tmp_path (the folder the real one names, where a test points the temporary folder
    there), or else to the session's temporary folder."""
    from piga.cli import common

    folder = (request.getfixturevalue("tmp_path") if "tmp_path" in request.fixturenames
              else tmp_path_factory.getbasetemp()) / "piga-logs"
    monkeypatch.setattr(common, "log_folder", lambda: folder)


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """12 pendulum sequences x 16 frames, seed 3 (split 8/2/2)."""
    from piga.data.collect import CollectConfig, collect

    path = tmp_path_factory.mktemp("data") / "tiny.h5"
    collect(CollectConfig(sequences=12, steps=16, seed=3, workers=1, split=(8, 2, 2)), path, progress=False, command="test")
    return path


@pytest.fixture(scope="session")
def tiny_run(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-epoch piga-train-model run on ``tiny_data`` (seconds), trained once per session (per xdist worker) for
    every module that reads it; a test that writes into a run copies it first."""
    from tests.helpers import train_tiny

    return train_tiny(tiny_data, tmp_path_factory.mktemp("tiny_run") / "run")
