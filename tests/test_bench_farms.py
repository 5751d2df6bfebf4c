"""The seed farms of benchmarks/systems.py and benchmarks/dmc.py on the job runner: the same records in processes as in
this one, and a failed job ends the script with one line (:func:`common.farm_main`), keeping what finished.
Training and the commands are stand-ins: the farms are what is tested, not the benchmarks' numbers."""

from __future__ import annotations

import importlib.util
import json
import os
import stat
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str) -> Any:
    spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # NamedTuples and dataclasses look their module up there (and pickle by it)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def benchmarks():
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts import their sibling module common
    try:
        yield {name: _load(name) for name in ("systems", "dmc")}
    finally:
        for name in ("systems", "dmc"):
            sys.modules.pop(f"bench_{name}", None)
        sys.path.remove(str(ROOT / "benchmarks"))


#: The committed runs of systems.py, by (case, seed): what the stand-in training returns.
COMMITTED = {(r["system"], r["seed"]): r for r in json.loads((ROOT / "results" / "systems.json").read_text())["runs"]}


def _systems_stand_ins(systems: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fail: tuple[str, int] | None = None) -> None:
    """No data collected; a run is the committed one (its rollout a stand-in file), or raises for ``fail``."""
    monkeypatch.setattr(systems, "_data", lambda system, folder: folder / f"{system}.h5")

    def run(case: str, seed: int, data: Path, folder: Path, overrides: Any = None, name: Any = None) -> dict[str, Any]:
        if (case, seed) == fail:
            raise ValueError(f"{folder}/{case}-seed{seed} was trained with another recipe")
        run_dir = folder / f"{case}-seed{seed}"
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "rollout.png").write_bytes(b"png")
        return {**COMMITTED[(case, seed)], "run": str(run_dir)}

    monkeypatch.setattr(systems, "_run", run)


def test_systems_runs_in_processes_give_the_page_of_one_process(benchmarks, tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    systems = benchmarks["systems"]
    _systems_stand_ins(systems, tmp_path, monkeypatch)
    pages = {}
    for jobs in ("2", "1"):
        out = tmp_path / f"out{jobs}" / "systems"
        argv = ["--out", str(out), "--work", str(tmp_path / "work"), "--systems", "spring", "gravity", "--seeds", "0", "1",
                "--jobs", jobs]
        assert systems.main(argv) == 0
        record = json.loads(out.with_suffix(".json").read_text())
        pages[jobs] = {key: record[key] for key in ("runs", "summary")}
        assert (out.parent / "systems-rollout-gravity.png").read_bytes() == b"png"
    assert [(r["system"], r["seed"]) for r in pages["1"]["runs"]] == [("spring", 0), ("spring", 1), ("gravity", 0),
                                                                      ("gravity", 1)]
    assert pages["2"] == pages["1"]


def test_a_systems_run_that_raises_ends_with_one_line_and_keeps_the_runs_before(
        benchmarks, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    systems = benchmarks["systems"]
    _systems_stand_ins(systems, tmp_path, monkeypatch, fail=("spring", 1))
    out, work = tmp_path / "systems", tmp_path / "work"
    with pytest.raises(SystemExit) as info:
        systems.main(["--out", str(out), "--work", str(work), "--systems", "spring", "--seeds", "0", "1", "2"])
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert err == f"systems.py: error: job spring seed 1 failed: ValueError: {work}/spring-seed1 was trained with another recipe\n"
    assert [(r["system"], r["seed"]) for r in json.loads(out.with_suffix(".json").read_text())["runs"]] == [("spring", 0)]


def test_a_dmc_command_that_fails_ends_with_one_line_naming_the_case(benchmarks, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """dmc.py's cases are jobs: a piga command that fails (here piga-collect, a stand-in that exits 1) raises in its
    job, and the benchmark ends with one line naming the case and the command's log (it used to exit from inside)."""
    folder = tmp_path / "bin"
    folder.mkdir()
    collect = folder / "piga-collect"
    collect.write_text(f"#!{sys.executable}\nimport sys\nprint('piga-collect: error: no', file=sys.stderr)\nsys.exit(1)\n")
    collect.chmod(collect.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{folder}{os.pathsep}{os.environ['PATH']}")
    work, out = tmp_path / "work", tmp_path / "dmc"
    monkeypatch.setattr(sys, "argv", ["dmc.py", "--work", str(work), "--out", str(out), "--seeds", "3", "--jobs", "2",
                                      "--variant", "mass=1.5"])
    with pytest.raises(SystemExit) as info:
        benchmarks["dmc"].main()
    assert info.value.code == 1
    line = capsys.readouterr().err
    assert line.count("\n") == 1 and line.startswith("dmc.py: error: job seed3")
    assert "failed: PigaError: 'piga-collect --env ...' failed (exit 1); see " in line
    log = Path(line.split("; see ")[1].strip())
    assert log.parent.parent == work and "piga-collect: error: no" in log.read_text()
    assert not out.with_suffix(".json").exists()


def test_a_jobs_command_ends_with_the_process_that_runs_the_job(tmp_path: Path) -> None:
    """A pool worker that is terminated (or any process running a job that dies) takes the command of
    :func:`common.job_command` with it: the command gets SIGTERM rather than running on, orphaned."""
    import signal
    import subprocess
    import time

    pid_file = tmp_path / "pid"
    command = tmp_path / "command.py"
    command.write_text(f"import os, time\nopen({str(pid_file)!r}, 'w').write(str(os.getpid()))\ntime.sleep(60)\n")
    job = tmp_path / "job.py"
    job.write_text(f"import sys\nsys.path.insert(0, {str(ROOT / 'benchmarks')!r})\nfrom common import job_command\n"
                   f"job_command([sys.executable, {str(command)!r}])\n")
    parent = subprocess.Popen([sys.executable, str(job)], env={**os.environ, "PYTHONPATH": str(ROOT)})
    deadline = time.monotonic() + 60
    while not (pid_file.exists() and pid_file.read_text()) and time.monotonic() < deadline:
        time.sleep(0.05)
    pid = int(pid_file.read_text())
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        if Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z":  # ended, not yet reaped by init
            return
        time.sleep(0.05)
    os.kill(pid, signal.SIGKILL)
    pytest.fail("the job's command outlived the process that ran it")
