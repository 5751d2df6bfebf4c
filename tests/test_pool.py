"""The shared job runner: any picklable function over job specs in worker processes, and resume from records."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from piga.io.pool import JobRecords, RecordedJob, git_commit, run_pool, run_recorded

ROOT = Path(__file__).resolve().parents[1]


def _square(x: int) -> int:
    time.sleep(0.05 * (x % 3))  # jobs end out of order
    return x * x


def test_results_come_in_the_order_of_the_specs_whichever_ends_first() -> None:
    ended: list[int] = []
    assert run_pool(_square, list(range(7)), workers=3, progress=False, on_result=lambda i, r: ended.append(i)) == [
        x * x for x in range(7)]
    assert sorted(ended) == list(range(7))
    assert run_pool(_square, [3, 2], workers=1, progress=False) == [9, 4]


def _one_thread(_: int) -> int:
    import torch

    return torch.get_num_threads()


def test_each_worker_runs_one_torch_thread() -> None:
    assert run_pool(_one_thread, [0, 1, 2], workers=2, progress=False) == [1, 1, 1]


def test_the_commit_is_the_checkouts_or_none(tmp_path: Path) -> None:
    inside = git_commit(ROOT)
    if (ROOT / ".git").exists():
        assert inside is not None and len(inside) == 40
    assert git_commit(tmp_path) is None


_SCRIPT = """
import os, sys, time
from pathlib import Path
from piga.io.pool import JobRecords, RecordedJob, run_recorded

folder, log = Path(sys.argv[1]), Path(sys.argv[2])

def job(name):
    with open(log, "a") as f:
        f.write(f"{name} {os.getpid()}\\n")
    if name == "stuck":
        time.sleep(600)  # the run is killed while this job runs
    return {"result": name.upper()}

jobs = [RecordedJob(name, {"n": i}, name) for i, name in enumerate(["a", "b", "stuck", "c"])]
print(run_recorded(job, jobs, JobRecords(folder), workers=2, progress=False))
"""


def test_a_killed_run_continues_without_redoing_finished_jobs(tmp_path: Path) -> None:
    script, folder, log = tmp_path / "run.py", tmp_path / "records", tmp_path / "log.txt"
    script.write_text(textwrap.dedent(_SCRIPT))
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, str(script), str(folder), str(log)], env=env)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (folder / "c.json").exists():
            time.sleep(0.1)
        assert (folder / "c.json").exists(), "the jobs after the stuck one did not finish"
    finally:
        proc.send_signal(signal.SIGKILL)  # no chance to clean up: what was written is all there is
        proc.wait(timeout=30)
    assert sorted(p.stem for p in folder.glob("*.json")) == ["a", "b", "c"]
    stuck = int(next(line.split()[1] for line in log.read_text().splitlines() if line.startswith("stuck")))
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and Path(f"/proc/{stuck}").exists():
        time.sleep(0.1)
    assert not Path(f"/proc/{stuck}").exists() or sys.platform != "linux", "a worker outlived its killed parent"
    record = json.loads((folder / "b.json").read_text())
    assert record == {"spec": {"n": 1}, "commit": git_commit(), "result": "B"}

    ran: list[str] = []
    jobs = [RecordedJob(name, {"n": i}, name) for i, name in enumerate(["a", "b", "stuck", "c"])]
    out = run_recorded(lambda name: ran.append(name) or {"result": "again"}, jobs, JobRecords(folder), progress=False)
    assert ran == ["stuck"]  # only the job without a record
    assert list(out) == ["a", "b", "stuck", "c"] and out["a"]["result"] == "A" and out["stuck"]["result"] == "again"
    assert json.loads((folder / "stuck.json").read_text())["spec"] == {"n": 2}

    changed = [RecordedJob("a", {"n": 99}, "a")]  # a setting changed: its record no longer counts
    assert run_recorded(lambda name: {"result": "new"}, changed, JobRecords(folder), progress=False)["a"]["result"] == "new"


def test_a_job_that_fails_keeps_the_records_of_those_that_ended(tmp_path: Path) -> None:
    def job(name: str) -> dict[str, str]:
        if name == "bad":
            raise RuntimeError("boom")
        return {"ok": name}

    jobs = [RecordedJob(name, {}, name) for name in ("a", "bad", "c")]
    with pytest.raises(RuntimeError, match="boom"):
        run_recorded(job, jobs, JobRecords(tmp_path), progress=False)
    assert [p.stem for p in tmp_path.glob("*.json")] == ["a"]
