"""The commands as a user runs them (subprocess): output, bad input, and interrupted writes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from piga.data import inspect_dataset
from tests.helpers import ENV, assert_one_line_error, run



def test_collect_then_show(tmp_path: Path) -> None:
    out = tmp_path / "d.h5"
    result = run("piga-collect", "--out", str(out), "--sequences", "4", "--steps", "5", "--workers", "1",
                 "--gravity", "6", "--actuation-gain", "1.5", "--seed", "2", "--split", "2,1,1", "--quiet")
    assert result.returncode == 0, result.stderr
    info = inspect_dataset(out)
    assert info.params["g"] == 6 and info.params["actuation_gain"] == 1.5
    assert info.split_counts == {"train": 2, "valid": 1, "test": 1}
    assert info.attrs["command"].startswith("piga-collect --out")
    png = tmp_path / "s.png"
    assert run("piga-show", str(out), "--out", str(png), "--frames", "3").returncode == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert_one_line_error(run("piga-show", str(out), "--out", str(png)), "--overwrite")


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--sequences", "0"], "--sequences"),
        (["--sequences", "-3"], "--sequences"),
        (["--sequences", "many"], "--sequences"),
        (["--steps", "1"], "steps"),
        (["--gravity", "0"], "--gravity"),
        (["--gravity", "-9.8"], "--gravity"),
        (["--gravity-mult", "0"], "--gravity-mult"),
        (["--actuation-gain", "-1"], "--actuation-gain"),
        (["--workers", "0"], "--workers"),
        (["--split", "0.5,0.5"], "--split"),
        (["--split", "0.5,0.4,0.4"], "split"),
        (["--split", "a,b,c"], "--split"),
        (["--preset", "huge"], "--preset"),
        (["--max-speed", "9"], "max_speed"),
        (["--seed", "-1"], "--seed"),
        (["--bogus"], "--bogus"),
    ],
)
def test_collect_bad_input(tmp_path: Path, args: list[str], needle: str) -> None:
    out = tmp_path / "d.h5"
    assert_one_line_error(run("piga-collect", "--out", str(out), "--sequences", "2", "--steps", "3", *args), needle)
    assert not out.exists()


def test_collect_bad_paths(tmp_path: Path) -> None:
    assert_one_line_error(run("piga-collect", "--sequences", "2"), "--out")
    assert_one_line_error(run("piga-collect", "--out", str(tmp_path / "nope" / "d.h5")), "does not exist")
    assert_one_line_error(run("piga-collect", "--out", str(tmp_path)), "folder")
    if os.geteuid() != 0:  # root writes anywhere; a read-only folder only stops other users
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o500)
        assert_one_line_error(run("piga-collect", "--out", str(ro / "d.h5")), "not writable")
    existing = tmp_path / "mine.h5"
    existing.write_text("precious")
    assert_one_line_error(run("piga-collect", "--out", str(existing), "--sequences", "2"), "--overwrite")
    assert existing.read_text() == "precious"


def test_show_bad_input(tmp_path: Path) -> None:
    assert_one_line_error(run("piga-show", str(tmp_path / "absent.h5"), "--out", str(tmp_path / "x.png")), "no such file")
    junk = tmp_path / "junk.h5"
    junk.write_text("junk")
    assert_one_line_error(run("piga-show", str(junk), "--out", str(tmp_path / "x.png")), "HDF5")


def _start_long_collect(out: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        ["piga-collect", "--out", str(out), "--sequences", "400", "--steps", "40", "--workers", "1", "--quiet", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
    )


def _wait_for_partial(folder: Path, proc: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + 60
    while not any(p.name.startswith(".") and ".partial-" in p.name for p in folder.iterdir()):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no partial file appeared"
        time.sleep(0.05)
    time.sleep(0.5)  # now inside the write loop


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL])
def test_interrupted_collect_leaves_no_target(tmp_path: Path, sig: signal.Signals) -> None:
    out = tmp_path / "d.h5"
    proc = _start_long_collect(out)
    _wait_for_partial(tmp_path, proc)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode != 0
    assert not out.exists()
    if sig != signal.SIGKILL:  # a catchable signal also removes the partial file, with one line
        assert list(tmp_path.iterdir()) == []
        assert "interrupted" in err and "Traceback" not in err


def test_killed_overwrite_keeps_the_old_file(tmp_path: Path) -> None:
    out = tmp_path / "d.h5"
    assert run("piga-collect", "--out", str(out), "--sequences", "2", "--steps", "3", "--workers", "1").returncode == 0
    before = out.read_bytes()
    proc = _start_long_collect(out, "--overwrite")
    _wait_for_partial(tmp_path, proc)
    proc.kill()
    proc.communicate(timeout=60)
    assert out.read_bytes() == before
    with h5py.File(out, "r") as f:
        assert f["frames"].shape[:2] == (2, 3)


def test_demo_runs_the_chain(tmp_path: Path) -> None:
    result = run("piga-demo", "--out", str(tmp_path / "demo"), "--sequences", "10", "--epochs", "1", "--episodes", "1",
                 "--control-steps", "5")
    assert result.returncode == 0, result.stderr
    assert "summary: g: learned" in result.stdout and "a: learned" in result.stdout
    assert "summary: upright, gravity x1.4: success" in result.stdout
    for name in ("frames.png", "pendulum.h5", "model/metrics.json", "model/rollout.png", "goal.png", "control.md"):
        assert (tmp_path / "demo" / name).exists(), name
    assert_one_line_error(run("piga-demo", "--out", str(tmp_path / "demo")), "--overwrite")


def test_module_entry_points_importable_without_torch() -> None:
    code = "import sys, piga.cli.collect, piga.cli.show; print('torch' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV).stdout.strip() == "False"
