"""The shared job runner: any picklable function over job specs in worker processes, and resume from records."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import traceback
from pathlib import Path

import pytest

from piga.io.pool import (Backend, BackendError, JobFailed, JobRecords, RecordedJob, git_commit, job_name, run_pool,
                          run_recorded)

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
    with pytest.raises(JobFailed, match="job bad failed: RuntimeError: boom"):
        run_recorded(job, jobs, JobRecords(tmp_path), progress=False)
    assert [p.stem for p in tmp_path.glob("*.json")] == ["a"]


def _fails_at_two(x: int) -> int:
    if x == 2:
        raise ValueError(f"no square for {x}")
    return x * x


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_job_is_named_and_the_ended_ones_kept(workers: int) -> None:
    ended: list[int] = []
    with pytest.raises(JobFailed, match=r"^job case 2 failed: ValueError: no square for 2$") as info:
        run_pool(_fails_at_two, [0, 1, 2], workers=workers, progress=False, names=["case 0", "case 1", "case 2"],
                 on_result=lambda i, r: ended.append(i))
    assert isinstance(info.value.cause, ValueError) and info.value.job == "case 2"
    if workers == 1:
        assert ended == [0, 1]
    assert "_fails_at_two" in "".join(traceback.format_exception(info.value)), "the job's own traceback is lost"


def test_a_job_is_named_by_its_name_or_its_spec() -> None:
    assert job_name(RecordedJob("seed3", {}, None)) == "seed3"
    assert job_name({"case": 4, "effects": {}}) == "{'case': 4, 'effects': {}}"
    assert len(job_name("x" * 500)) == 80
    with pytest.raises(ValueError, match="2 names for 3 jobs"):
        run_pool(_square, [1, 2, 3], names=["a", "b"], progress=False)


@pytest.mark.parametrize("text, backend", [
    (None, Backend()),
    ("auto", Backend("ray", "auto")),
    ("10.0.0.5:6379", Backend("ray", "10.0.0.5:6379")),
    ("head", Backend("ray", "head")),
])
def test_the_ray_option_gives_a_backend(text: str | None, backend: Backend) -> None:
    assert Backend.from_option(text) == backend


@pytest.mark.parametrize("address", ["", ":6379", "host:0", "host:65536", "host:port", "ray://head:10001", "a b:1"])
def test_a_bad_ray_address_is_refused(address: str) -> None:
    with pytest.raises(ValueError, match="HOST:PORT"):
        Backend("ray", address)
    with pytest.raises(ValueError, match="kind must be one of"):
        Backend("dask")  # type: ignore[arg-type]


def test_without_ray_the_ray_backend_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    with pytest.raises(BackendError, match=r"^Ray is not installed: pip install -e '\.\[ray\]'$"):
        Backend("ray").connect()
    with pytest.raises(BackendError, match="not installed"):
        run_pool(_square, [1, 2], backend=Backend("ray", "10.0.0.5:6379"), progress=False)
    assert run_pool(_square, [1, 2], backend=Backend(), progress=False) == [1, 4]  # local needs no Ray


def _fails_in_a_bug(x: int) -> float:
    return 1 / (x - 2)


@pytest.mark.parametrize("function, code, needle", [
    (_fails_at_two, 1, "prog: error: job case 2 failed: no square for 2"),
    (_fails_in_a_bug, 70, "prog: internal error (JobFailed: job case 2 failed: ZeroDivisionError: division by zero)"),
])
def test_a_command_names_the_failed_job_in_its_one_line(function: object, code: int, needle: str,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    from tests.helpers import assert_one_line, run_in_process

    def main(argv: object) -> int:
        run_pool(function, [0, 1, 2, 3], workers=2, progress=False, names=[f"case {i}" for i in range(4)])  # type: ignore[arg-type]
        return 0

    exit_code, _, err = run_in_process("prog", main, capsys=capsys)
    assert assert_one_line(exit_code, err, status=code).startswith(needle), err


def test_a_job_that_ends_after_a_commit_records_both_commits(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A job starts a command that runs the code on disk: code committed while the jobs run reaches the later jobs,
    and their records say so instead of naming the first commit alone."""
    import piga.io.pool as pool

    heads = iter(["first", "first", "second"])  # the checkout's HEAD as each record is written
    monkeypatch.setattr(pool, "git_commit", lambda: "first")  # read as the jobs start
    monkeypatch.setattr(pool, "current_commit", lambda: next(heads))
    jobs = [RecordedJob(name, {"n": i}, name) for i, name in enumerate("abc")]
    out = run_recorded(lambda name: {"result": name}, jobs, JobRecords(tmp_path), progress=False)
    assert [out[n]["commit"] for n in "abc"] == ["first"] * 3
    assert "commit_at_end" not in out["a"] and "commit_at_end" not in out["b"] and out["c"]["commit_at_end"] == "second"
    assert json.loads((tmp_path / "c.json").read_text())["commit_at_end"] == "second"
