"""Shared fixtures: tiny data files made once per session."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

# A shell starts background jobs (`pytest &`) with SIGINT ignored, and the commands that the tests
# start would inherit that and never see the Ctrl-C the interrupt tests send. A handler, unlike
# SIG_IGN, is reset to the default in a started command.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """12 pendulum sequences x 16 frames, seed 3 (split 8/2/2)."""
    from piga.data.collect import CollectConfig, collect

    path = tmp_path_factory.mktemp("data") / "tiny.h5"
    collect(CollectConfig(sequences=12, steps=16, seed=3, workers=1, split=(8, 2, 2)), path, progress=False, command="test")
    return path
