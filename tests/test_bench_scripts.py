"""The benchmark scripts as commands: bad input is one line on stderr (exit 1, or argparse's 2), never a traceback,
and counts and seeds are checked as they are parsed, before any work."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ENV

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p for p in BENCHMARKS.glob("*.py") if "__main__" in p.read_text())


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_every_script_runs_under_run_cli(script: Path) -> None:
    assert script.read_text().rstrip().endswith("run_script(main, __file__)"), \
        f"{script.name}: end with `run_script(main, __file__)` (piga.cli.common), so that its bad input is one line"


@pytest.mark.parametrize("argv, code, line", [
    (["control.py", "--model", "nowhere", "--out", "OUT"], 1,
     "control.py: error: nowhere/checkpoint.pt: no checkpoint (is nowhere a piga-train-model run folder?)"),
    (["control.py", "--model", "nowhere", "--out", "/dev/null/x"], 1,  # refused before any job, not after an hour
     "control.py: error: /dev/null is a file, not a folder, so /dev/null/x.json cannot be written there"),
    (["control.py", "--model", "nowhere", "--workers", "0"], 2,
     "control.py: error: argument --workers: expected a positive integer, got 0 (see --help)"),
    (["backends.py", "--bogus", "1"], 2,  # every bad argument was "--cluster-note: expected a value, got ''", its default
     "backends.py: error: the following arguments are required: --model, --work, --out (see --help)"),
    (["ablations.py", "--seeds", "-1", "--out", "OUT"], 2,
     "ablations.py: error: argument --seeds: expected an integer in [0, 2^63 - 1], got -1 (see --help)"),
    # a missing model was an internal error (TypeError) after the first case's data was collected
    (["diagnose_blind.py", "--model", "nowhere", "--cases", "1", "--out", "OUT", "--work", "W"], 1,
     "diagnose_blind.py: error: nowhere/checkpoint.pt: no checkpoint (is nowhere a piga-train-model run folder?)"),
    (["diagnose_recordings.py", "--model", "nowhere", "--out", "OUT", "--work", "W"], 1,  # was CalledProcessError, 2 lines
     "diagnose_recordings.py: error: nowhere/checkpoint.pt: no checkpoint (is nowhere a piga-train-model run folder?)"),
    (["dmc.py", "--work", "W", "--out", "OUT", "--variant", "bogus=1"], 1,  # was found after the first seed's hour
     "dmc.py: error: --variant bogus=1: --env-option bogus: unknown for piga/DMCPendulum-v0; known: action_repeat, "
     "camera, camera_distance, color, damping, flip, length, mass, shadows"),
    (["planet_plan_time.py", "--out", "OUT", "--threads", "0"], 2,  # was torch's RuntimeError, exit 70
     "planet_plan_time.py: error: argument --threads: expected a positive integer, got 0 (see --help)"),
])
def test_bad_input_to_a_script_is_one_line(tmp_path: Path, argv: list[str], code: int, line: str) -> None:
    argv = [a.replace("OUT", str(tmp_path / "out")) for a in argv]
    done = subprocess.run([sys.executable, str(BENCHMARKS / argv[0]), *argv[1:]], capture_output=True, text=True,
                          env=ENV, cwd=tmp_path, timeout=120)
    assert done.returncode == code and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.strip().splitlines() == [line]  # (argparse's own parser would print its usage first)
    assert list(tmp_path.iterdir()) == []
