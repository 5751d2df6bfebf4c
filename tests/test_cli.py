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

from piga.data.schema import inspect_dataset
from tests.helpers import ENV, assert_one_line, assert_one_line_error, completed_in_process, run, run_in_process



def in_process(capsys: pytest.CaptureFixture[str], prog: str, *argv: str) -> subprocess.CompletedProcess[str]:
    """``piga-collect`` or ``piga-show`` run in this process."""
    from piga.cli import collect, show

    main = {"piga-collect": collect.main, "piga-show": show.main}[prog]
    return completed_in_process(prog, main, *argv, capsys=capsys)


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
        (["--max-speed", "9"], "--max-speed=9 is out of range (--max-speed in"),
        (["--seed", "-1"], "--seed"),
        (["--bogus"], "--bogus"),
    ],
)
def test_collect_bad_input(tmp_path: Path, args: list[str], needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "d.h5"
    argv = ("--out", str(out), "--sequences", "2", "--steps", "3", *args)
    assert_one_line_error(in_process(capsys, "piga-collect", *argv), needle)
    assert not out.exists()


def test_collect_bad_paths(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert_one_line_error(run("piga-collect", "--sequences", "2"), "--out")  # once as a script
    assert_one_line_error(in_process(capsys, "piga-collect", "--out", str(tmp_path / "nope" / "d.h5")),
                          "does not exist")
    assert_one_line_error(in_process(capsys, "piga-collect", "--out", str(tmp_path)), "folder")
    if os.geteuid() != 0:  # root writes anywhere; a read-only folder only stops other users
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o500)
        assert_one_line_error(in_process(capsys, "piga-collect", "--out", str(ro / "d.h5")), "not writable")
    existing = tmp_path / "mine.h5"
    existing.write_text("precious")
    assert_one_line_error(in_process(capsys, "piga-collect", "--out", str(existing), "--sequences", "2"), "--overwrite")
    assert existing.read_text() == "precious"


def test_show_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert_one_line_error(run("piga-show", str(tmp_path / "absent.h5"), "--out", str(tmp_path / "x.png")), "no such file")
    junk = tmp_path / "junk.h5"
    junk.write_text("junk")
    assert_one_line_error(in_process(capsys, "piga-show", str(junk), "--out", str(tmp_path / "x.png")), "HDF5")


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
        assert proc.returncode == 128 + sig  # as a shell reports it: 130 for Ctrl-C, 143 for SIGTERM (it was 130)


@pytest.mark.slow  # a collect with two env workers, killed: about 5 s
def test_workers_end_quietly_with_a_parent_killed_outright(tmp_path: Path) -> None:
    """SIGKILL of collect's main process alone (the OOM killer's way) left its two env workers printing 66 lines of
    pipe tracebacks for a second or more; they now end with it."""
    out = tmp_path / "d.h5"
    proc = subprocess.Popen(["piga-collect", "--out", str(out), "--sequences", "3000", "--workers", "2", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, start_new_session=True)
    _wait_for_partial(tmp_path, proc)
    proc.kill()  # the main process only: the workers are left to notice
    _, err = proc.communicate(timeout=60)
    time.sleep(2)  # what the workers would print comes through the same stderr, until they end
    assert err == "", err
    assert subprocess.run(["pgrep", "-f", str(out)], capture_output=True).returncode == 1, "a worker outlived it"


def test_ctrl_c_with_two_workers_prints_one_line(tmp_path: Path) -> None:
    """Ctrl-C reaches the whole process group: the env workers must stay quiet."""
    out = tmp_path / "d.h5"
    proc = subprocess.Popen(["piga-collect", "--out", str(out), "--sequences", "3000", "--workers", "2", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, start_new_session=True)
    _wait_for_partial(tmp_path, proc)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.strip() == "piga-collect: interrupted; nothing was written", err
    assert list(tmp_path.iterdir()) == []


def test_stale_partial_files_are_removed_by_the_next_run(tmp_path: Path) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        stale, busy = tmp_path / f".d.h5.partial-{dead.pid}", tmp_path / f".d.h5.partial-{alive.pid}"
        stale.write_text("left by a SIGKILL")
        busy.write_text("being written by a live process")
        result = run("piga-collect", "--out", str(tmp_path / "d.h5"), "--sequences", "2", "--steps", "3", "--workers", "1")
        assert result.returncode == 0, result.stderr
        assert not stale.exists() and busy.exists()
    finally:
        alive.kill()
        alive.wait()


@pytest.mark.parametrize("args", [["--steps", "1000000000"], ["--image-size", "1024", "--sequences", "200000"], ["--sequences", "1000000000"]])
def test_sizes_that_cannot_fit_are_refused_before_allocating(tmp_path: Path, args: list[str],
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import collect as cli

    out = tmp_path / "d.h5"
    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(out), "--workers", "1", *args, capsys=capsys)
    line = assert_one_line(code, err, "needs ")
    assert "needs about" in line and "of memory, but" in line and "available" in line \
        or "needs up to" in line and "of disk as it writes" in line and "free" in line
    assert list(tmp_path.iterdir()) == []


def test_existing_output_is_refused_before_any_setup(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import gymnasium as gym

    from piga.io.atomic import OutputExistsError
    from piga.data.collect import CollectConfig, collect

    def no_envs(*args: object, **kwargs: object) -> None:
        raise AssertionError("envs were made before the output was checked")

    monkeypatch.setattr(gym.vector, "AsyncVectorEnv", no_envs)
    monkeypatch.setattr(gym.vector, "SyncVectorEnv", no_envs)
    out = tmp_path / "d.h5"
    out.write_text("precious")
    with pytest.raises(OutputExistsError):
        collect(CollectConfig(sequences=2, steps=3), out)
    assert out.read_text() == "precious"


def test_split_with_a_negative_number_is_named(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from piga.cli import collect as cli

    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(tmp_path / "d.h5"), "--split", "-1,1,1", capsys=capsys)
    assert code == 1 and "expected one argument" not in err
    assert_one_line(code, err, "--split", ">= 0", "'-1,1,1'")


def test_internal_error_is_one_line_naming_a_log(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    import tempfile

    from piga.cli.common import INTERNAL_ERROR

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))

    def buggy(argv: object) -> int:
        return {}["missing"]  # a bug, not a user error

    code, _, err = run_in_process("piga-x", buggy, "--flag", capsys=capsys)
    line = assert_one_line(code, err, "piga-x: internal error (KeyError: 'missing')", "please report it",
                           status=INTERNAL_ERROR)
    logs = list((tmp_path / "piga-logs").iterdir())
    assert len(logs) == 1 and str(logs[0]) in line
    text = logs[0].read_text()
    assert text.startswith("piga-x --flag") and "Traceback" in text and 'KeyError: \'missing\'' in text


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


@pytest.mark.slow  # the whole chain: collect, show, train, control
def test_demo_runs_the_chain(tmp_path: Path) -> None:
    result = run("piga-demo", "--out", str(tmp_path / "demo"), "--sequences", "10", "--epochs", "1", "--episodes", "1",
                 "--control-steps", "20")
    # one epoch of 6 steps is too short to judge: the chain runs to its end and exits 3, as piga-train-model does
    assert result.returncode == 3 and "piga-demo: warning: not converged" in result.stderr, result.stderr
    # its advice is the demo's own way to train longer, not piga-train-model's options
    assert "run the demo again with --resume and a larger --epochs" in result.stderr, result.stderr
    assert "--max-minutes" not in result.stderr and "(options of piga-train-model" not in result.stderr, result.stderr
    assert "summary: g: learned" in result.stdout and "a: learned" in result.stdout
    assert "summary: upright, gravity x1.4: success" in result.stdout
    for name in ("frames.png", "pendulum.h5", "model/metrics.json", "model/rollout.png", "goal.png", "control.md"):
        assert (tmp_path / "demo" / name).exists(), name
    assert_one_line_error(run("piga-demo", "--out", str(tmp_path / "demo")), "--overwrite")


def test_module_entry_points_importable_without_torch() -> None:
    code = "import sys, piga.cli.collect, piga.cli.show; print('torch' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV).stdout.strip() == "False"


def test_show_cuts_a_long_title(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A file's attributes are any text: a 100,000-character system name took matplotlib 18 s to lay out."""
    import h5py

    from piga.cli import show
    from piga.evaluation import plots

    data = tmp_path / "d.h5"
    assert in_process(capsys, "piga-collect", "--out", str(data), "--sequences", "2", "--steps", "3", "--workers", "1",
                      "--split", "2,0,0", "--quiet").returncode == 0
    with h5py.File(data, "a") as f:
        f.attrs["system"] = "pendulum" + "x" * 100_000
    titles = []
    real = plots.frame_strip
    monkeypatch.setattr(plots, "frame_strip", lambda *a: titles.append(a[3]) or real(*a))  # show imports it in main
    assert in_process(capsys, "piga-show", str(data), "--out", str(tmp_path / "s.png"), "--frames", "2").returncode == 0
    assert len(titles[0]) == show.MAX_TITLE and titles[0].endswith("...")


def test_a_configs_field_names_are_shown_as_the_flags_of_this_command() -> None:
    """A config's ValueError names its fields; the command's one line names the flags a user types instead."""
    from piga.cli.common import _FLAGS, with_flags

    _FLAGS.clear()
    _FLAGS.update(lr="--lr", warmup_fraction="--warmup-fraction", curriculum_fraction="--curriculum-fraction")
    assert with_flags("TrainConfig.lr must be in (0, 10], got 20.0") == "--lr must be in (0, 10], got 20.0"
    assert (with_flags("TrainConfig: warmup_fraction + curriculum_fraction must leave")
            == "--warmup-fraction + --curriculum-fraction must leave")
    # other words, file names and fields of options this command does not have stay as they are
    for text in ("my_lr.h5 holds lr_x", "runs/warmup_fraction/x.h5", "DecoderConfig.coord_dim must be 1"):
        assert with_flags(text) == text
    _FLAGS.clear()
