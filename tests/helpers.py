"""Helpers that several test modules share: running a command as a user does, and checking its errors."""

from __future__ import annotations

import contextlib
import importlib.util
import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from piga.cli.common import run_cli

#: The environment of a command run in a subprocess (no display needed for rendering).
ENV = {**os.environ, "SDL_VIDEODRIVER": "dummy"}


def run(*args: str, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Runs a command in a subprocess, as a user would: (return code, stdout, stderr) as text."""
    return subprocess.run(list(args), capture_output=True, text=True, env=env or ENV, cwd=cwd, timeout=timeout)


def run_in_process(prog: str, main: Callable[[Sequence[str] | None], int | None], *argv: str,
                   capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Runs a command's ``main`` in this process exactly as its script does (through ``run_cli``).

    Faster than a subprocess when the test does not need signals. Returns (exit code, stdout, stderr).
    """
    saved = signal.getsignal(signal.SIGTERM)
    try:
        with pytest.raises(SystemExit) as info:
            run_cli(prog, main, list(argv))
    finally:
        signal.signal(signal.SIGTERM, saved)
    out, err = capsys.readouterr()
    return int(info.value.code or 0), out, err


def completed_in_process(prog: str, main: Callable[[Sequence[str] | None], int | None], *argv: str,
                         capsys: pytest.CaptureFixture[str]) -> subprocess.CompletedProcess[str]:
    """:func:`run_in_process` as :func:`run` returns it, for :func:`assert_one_line_error`: a refusal checked
    without starting an interpreter (keep one run per command as a script)."""
    code, out, err = run_in_process(prog, main, *argv, capsys=capsys)
    return subprocess.CompletedProcess([prog, *argv], code, out, err)


def assert_one_line(code: int, err: str, *needles: str, status: int = 1) -> str:
    """A refused or failed command: exit ``status`` (1: refused input, usage errors too), exactly one line on stderr
    containing each needle, no traceback."""
    lines = err.strip().splitlines()
    assert code == status, f"expected exit status {status}, got {code}: {err}"
    assert len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def assert_sb3_run_finished(code: int, err: str) -> None:
    """A ``piga-baseline ddpg`` run that trained to its end: exit 0 (it learned), or exit 1 with the one line that says it
    did not (what a tiny run does); its outputs are kept either way."""
    if code != 0:
        assert code == 1, err
        assert_one_line(code, err, "the run did not learn: its evaluation return never reached", "its outputs are in")


def assert_planet_run_finished(code: int, err: str) -> None:
    """A ``piga-baseline planet`` run that trained to its end: exit 0, or exit 1 with the one line that says it did not
    learn (what a tiny run does: its reconstructions no better than the average frame); its outputs are kept."""
    if code != 0:
        assert code == 1, err
        assert_one_line(code, err, "the run did not learn: its ", "its outputs are in")


def assert_one_line_error(result: subprocess.CompletedProcess[str], *needles: str) -> str:
    """:func:`assert_one_line` for a subprocess result; returns the line."""
    return assert_one_line(result.returncode, result.stderr, *needles)


def train_tiny(data: Path, run_dir: Path, report: bool = True, **overrides: Any) -> Path:
    """A real run folder in seconds: the tiny-data recipe (batch 16, 4 predicted frames, one thread), with ``overrides`` of
    TrainConfig; with ``report``, finished as ``piga-train-model`` finishes it (metrics.json and its figures: a run
    without them was stopped before its end, and the commands that read it say so)."""
    from piga.training.report import write_run_report
    from piga.training.train import TrainConfig, train
    from piga.world.model import ModelConfig

    config = TrainConfig(**{"epochs": 1, "batch_size": 16, "warmup_fraction": 0.1, "curriculum_fraction": 0.1, "threads": 1, **overrides})
    model, state = train(data, run_dir, config, ModelConfig(rec_frames="input", pred_frames=4), progress=False)
    if report:
        write_run_report(model, state, data, run_dir)
    return run_dir


def copy_without(src: Path, dst: Path, dataset: str) -> Path:
    """A copy of the data file ``src`` at ``dst`` without ``/dataset`` (for example a file from before ``/rewards``)."""
    import shutil

    import h5py

    shutil.copyfile(src, dst)
    with h5py.File(dst, "a") as f:
        del f[dataset]
    return dst


def stateless_pendulum(path: Path, sequences: int, steps: int, seed: int, split: tuple[int, int, int]) -> Path:
    """A pendulum file collected at ``path`` whose /states were deleted: training cannot read them."""
    import h5py

    from piga.data.collect import CollectConfig, collect

    collect(CollectConfig(sequences=sequences, steps=steps, seed=seed, workers=1, split=split), path, progress=False, command="t")
    with h5py.File(path, "a") as f:
        del f["states"]
    return path


@contextlib.contextmanager
def benchmark_module(name: str, module_name: str | None = None) -> Iterator[Any]:
    """The script ``benchmarks/NAME.py`` imported as a module (``sys.modules[module_name or "bench_NAME"]`` while in use,
    as dataclasses look their module up there), with ``benchmarks/`` on the path for its sibling module ``common``."""
    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "benchmarks"))
    spec = importlib.util.spec_from_file_location(module_name or f"bench_{name}", root / "benchmarks" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
        sys.path.remove(str(root / "benchmarks"))


def once_per_run(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[], Any]) -> Any:
    """``make()``, computed once in a test run: pytest-xdist's workers each run a module's fixture for the tests they
    were dealt, so a costly one (a diagnosis of half a minute) ran in both; here the first computes and pickles it
    under the run's shared temporary folder, behind a file lock, and the others read it (the recipe of xdist's docs)."""
    import pickle

    from filelock import FileLock

    if os.environ.get("PYTEST_XDIST_WORKER") is None:  # one process: nothing to share
        return make()
    path = tmp_path_factory.getbasetemp().parent / f"{name}.pickle"  # the parent is common to the workers
    with FileLock(f"{path}.lock"):
        if path.is_file():
            return pickle.loads(path.read_bytes())
        value = make()
        path.write_bytes(pickle.dumps(value))
        return value


def moving_png_folder(folder: Path, frames: int = 12) -> Path:
    """``folder`` made and filled with ``frames`` 32x32 PNGs of a bright block sliding down a black picture (f0.png ...):
    a recording for ``piga-import``."""
    import imageio.v3 as iio

    folder.mkdir()
    for i in range(frames):
        frame = np.zeros((32, 32), np.uint8)
        frame[i : i + 6, 8:14] = 220
        iio.imwrite(folder / f"f{i}.png", frame)
    return folder
