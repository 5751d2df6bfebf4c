"""The benchmark scripts as commands: bad input is one line on stderr (exit 1, or argparse's 2), never a traceback,
and counts and seeds are checked as they are parsed, before any work."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ENV, benchmark_module, run_in_process

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p for p in BENCHMARKS.glob("*.py") if "__main__" in p.read_text())


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_every_script_runs_under_run_cli(script: Path) -> None:
    assert script.read_text().rstrip().endswith("run_script(main, __file__)"), \
        f"{script.name}: end with `run_script(main, __file__)` (piga.cli.common), so that its bad input is one line"


BAD_INPUT = [
    (["control.py", "--model", "nowhere", "--out", "OUT"], 1,
     "control.py: error: nowhere/checkpoint.pt: no checkpoint (is nowhere a piga-train-model run folder?)"),
    (["control.py", "--model", "nowhere", "--out", "/dev/null/x"], 1,  # refused before any job, not after an hour
     "control.py: error: argument --out: /dev/null is a file, not a folder, so /dev/null/x cannot be written there "
     "(see --help)"),
    # each trained or collected first, then failed "removed or moved while it ran?" (/proc) or "[Errno 17]" (a file)
    (["identify_time.py", "--out", "/proc/x/y"], 1, "identify_time.py: error: argument --out: /proc is on a file "
     "system that stores no files (as /proc and /sys are); write elsewhere (see --help)"),
    (["train_accuracy.py", "--work", "/dev/null"], 1, "train_accuracy.py: error: argument --work: /dev/null is a file, "
     "not a folder: give a folder for the data and runs (see --help)"),
    (["identify_time.py", "--out", "OUT", "--recipes", "budget-abc"], 1,
     "identify_time.py: error: --recipes budget-abc: budget-N takes a whole number of steps N >= 1"),
    (["identify_time.py", "--out", "OUT", "--threads", "-1"], 1, "identify_time.py: error: argument --threads: "
     "expected an integer in [0, MAX] (0: torch's choice; at most this machine's MAX CPUs), got -1 (see --help)"),
    (["storage.py", "--out", "OUT", "--work", "W", "--cap-mb", "0"], 1,
     "storage.py: error: argument --cap-mb: expected a positive integer, got 0 (see --help)"),
    (["dmc.py", "--out", "OUT", "--work", "W", "--control-seed", "-1"], 1,
     "dmc.py: error: argument --control-seed: expected an integer in [0, 2^63 - 1], got -1 (see --help)"),
    (["backends.py", "--model", "m", "--out", "OUT", "--work", "W", "--ray", "garbage"], 1,  # after the local sweep
     "backends.py: error: --ray garbage: no Ray cluster at garbage:6379: unknown host (Name or service not known)"),
    (["camera_stage_time.py", "run", "nowhere.h5"], 1, "camera_stage_time.py: error: nowhere.h5: no such file"),
    (["control.py", "--model", "nowhere", "--workers", "0"], 1,
     "control.py: error: argument --workers: expected a positive integer, got 0 (see --help)"),
    (["backends.py", "--bogus", "1"], 1,  # every bad argument was "--cluster-note: expected a value, got ''", its default
     "backends.py: error: the following arguments are required: --model, --work, --out (see --help)"),
    (["ablations.py", "--seeds", "-1", "--out", "OUT"], 1,
     "ablations.py: error: argument --seeds: expected an integer in [0, 2^63 - 1], got -1 (see --help)"),
    # a missing model was an internal error (TypeError) after the first case's data was collected
    (["diagnose_blind.py", "--model", "nowhere", "--cases", "1", "--out", "OUT", "--work", "W"], 1,
     "diagnose_blind.py: error: nowhere/checkpoint.pt: no checkpoint (is nowhere a piga-train-model run folder?)"),
    (["diagnose_recordings.py", "--model", "nowhere", "--out", "OUT", "--work", "W"], 1,  # was CalledProcessError, 2 lines
     "diagnose_recordings.py: error: nowhere/checkpoint.pt: no checkpoint (is nowhere a piga-train-model run folder?)"),
    (["dmc.py", "--work", "W", "--out", "OUT", "--variant", "bogus=1"], 1,  # was found after the first seed's hour
     "dmc.py: error: --variant bogus=1: --env-option bogus: unknown for piga/DMCPendulum-v0; known: action_repeat, "
     "camera, camera_distance, color, damping, flip, length, mass, shadows"),
    (["planet_plan_time.py", "--out", "OUT", "--threads", "0"], 1,  # was torch's RuntimeError, exit 70
     "planet_plan_time.py: error: argument --threads: expected a positive integer, got 0 (see --help)"),
]
#: The cases run as scripts (an interpreter each); the others run the script's main in this process, through the
#: same entry (:func:`piga.cli.common.script_entry`), which is what each case tests, without a torch import apiece.
AS_SCRIPTS = {0, 8}  # control.py as a script; backends.py's refusal of a Ray address after its local sweep


@pytest.mark.parametrize("case", range(len(BAD_INPUT)), ids=lambda i: f"argv{i}-{BAD_INPUT[i][0][0]}")
def test_bad_input_to_a_script_is_one_line(tmp_path: Path, case: int, capsys: pytest.CaptureFixture[str],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    argv, code, line = BAD_INPUT[case]
    argv = [a.replace("OUT", str(tmp_path / "out")) for a in argv]
    line = line.replace("MAX", str(os.cpu_count()))
    if case in AS_SCRIPTS:
        done = subprocess.run([sys.executable, str(BENCHMARKS / argv[0]), *argv[1:]], capture_output=True, text=True,
                              env=ENV, cwd=tmp_path, timeout=120)
        got, err = done.returncode, done.stderr
    else:
        from piga.cli.common import script_entry

        monkeypatch.chdir(tmp_path)
        monkeypatch.setattr(sys, "argv", argv)  # (for a main that reads sys.argv itself)
        with benchmark_module(argv[0].removesuffix(".py")) as module:
            got, _, err = run_in_process(argv[0], script_entry(module.main), *argv[1:], capsys=capsys)
    assert got == code and "Traceback" not in err, err
    assert err.strip().splitlines() == [line]  # (argparse's own parser would print its usage first)
    assert list(tmp_path.iterdir()) == []


def test_a_folder_where_a_page_goes_is_refused_before_the_work(tmp_path: Path) -> None:
    """speed_clip_bias.py wrote OUT.md, then failed on OUT.json (a folder): half a pair, after the work."""
    (tmp_path / "dd.json").mkdir()
    done = subprocess.run([sys.executable, str(BENCHMARKS / "speed_clip_bias.py"), "--out", "dd"], capture_output=True,
                          text=True, env=ENV, cwd=tmp_path, timeout=120)
    assert done.returncode == 1 and done.stderr.strip().splitlines() == [
        "speed_clip_bias.py: error: argument --out: dd.json is a folder, so the page dd.json cannot be written there "
        "(see --help)"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dd.json"]
