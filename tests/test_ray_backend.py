"""The Ray backend of the job runner: a tiny farm on a local Ray instance (one for the module, 2 CPUs) gives the
local backend's results, in order; a failing or dying job is named; a wrong address is refused in one line."""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="Ray is not installed (the ray extra: pip install -e '.[ray]')")

from piga.control.jobs import ControlJob, run_split  # noqa: E402
from piga.io.pool import Backend, BackendError, JobFailed, run_pool  # noqa: E402
from piga.io.ray_backend import _local_instance, check_ray_head  # noqa: E402
from tests.test_episodes import EPISODES, MPC, RECORDED, _without_timing  # noqa: E402

RAY = Backend("ray")


@pytest.fixture(scope="module", autouse=True)
def local_ray() -> object:
    """A new Ray instance of this process, whatever else runs on the machine ("local": never a running cluster)."""
    import logging

    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level=logging.WARNING)
    yield
    ray.shutdown()


def _square(x: int) -> tuple[int, int]:
    import torch

    time.sleep(0.1 * (x % 3))  # jobs end out of order
    return x * x, torch.get_num_threads()


@pytest.mark.slow
def test_a_farm_gives_the_local_results_in_order_one_thread_each() -> None:
    ended: list[int] = []
    on_ray = run_pool(_square, list(range(6)), progress=False, backend=RAY, on_result=lambda i, r: ended.append(i))
    assert on_ray == run_pool(_square, list(range(6)), workers=2, progress=False) == [(x * x, 1) for x in range(6)]
    assert sorted(ended) == list(range(6))


@pytest.mark.slow  # Ray's workers import piga's control stack: 2 s alone, 17-25 s beside a second xdist worker;
# by default test_a_farm_gives_the_local_results_in_order_one_thread_each checks Ray's results against the local
# backend's, and tests/test_episodes.py::test_a_batch_split_over_workers_is_the_recorded_one the split episodes
def test_control_episodes_split_over_ray_tasks_are_the_recorded_ones() -> None:
    assert _without_timing(run_split(ControlJob("oracle", EPISODES, MPC), workers=2, progress=False, backend=RAY)) == \
        RECORDED["oracle"]


def _fails(x: float) -> float:
    if x < 0:
        raise ValueError(f"no root of {x}")
    if x == 99:
        os._exit(3)  # the worker process dies
    time.sleep(x)
    return x


@pytest.mark.slow  # Ray restarts a worker that died (10-30 s beside a second xdist worker); by default
# tests/test_pool.py::test_a_failing_job_is_named_and_the_ended_ones_kept checks the pool's handling of a failing job
def test_a_failing_job_is_named_the_ended_ones_kept_and_the_others_stopped() -> None:
    ended: list[int] = []
    started = time.monotonic()
    with pytest.raises(JobFailed, match=r"^job case 2 failed: ValueError: no root of -1\.0$") as info:
        run_pool(_fails, [0.0, 0.0, -1.0, 60.0], progress=False, backend=RAY, names=[f"case {i}" for i in range(4)],
                 on_result=lambda i, r: ended.append(i))
    assert isinstance(info.value.cause, ValueError)
    assert time.monotonic() - started < 30, "the 60-second job was waited for, not stopped"
    assert set(ended) <= {0, 1}
    with pytest.raises(JobFailed, match=r"^job 99\.0 failed: .*(died|crash|exit)"):
        run_pool(_fails, [99.0], progress=False, backend=RAY)
    assert run_pool(_square, [3], progress=False, backend=RAY) == [(9, 1)]  # the caller's instance is left running


def test_an_address_without_a_ray_head_is_refused_at_once() -> None:
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    started = time.monotonic()
    with pytest.raises(BackendError, match=f"^no Ray cluster at 127.0.0.1:{port}: Connection refused$"):
        check_ray_head("127.0.0.1", port)
    with pytest.raises(BackendError, match="unknown host"):
        check_ray_head("no-such-host.invalid", 6379)
    with socket.socket() as other:  # a server of another kind: it accepts, and closes
        other.bind(("127.0.0.1", 0))
        other.listen()
        threading.Thread(target=lambda: [other.accept()[0].close() for _ in range(2)], daemon=True).start()
        with pytest.raises(BackendError, match="something answers there, but not a Ray head"):
            check_ray_head("127.0.0.1", other.getsockname()[1])
    assert time.monotonic() - started < 15


def test_a_head_that_asks_for_a_token_this_machine_lacks_is_refused(monkeypatch: pytest.MonkeyPatch,
                                                                   tmp_path: Path) -> None:
    host, port = ray.get_runtime_context().gcs_address.rsplit(":", 1)
    check_ray_head(host, int(port))  # this machine holds the token of the instance it started
    if os.environ.get("RAY_AUTH_MODE") != "token":
        pytest.skip("the local Ray instance runs without token authentication")
    monkeypatch.setenv("HOME", str(tmp_path))
    for name in ("RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(BackendError, match="asks for an authentication token"):
        check_ray_head(host, int(port))


def _where() -> str:
    return os.getcwd()


def test_a_job_runs_in_the_folder_the_run_was_started_in(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # relative paths in a job mean what they mean here, on any node
    assert run_pool(lambda _: _where(), [0, 1], progress=False, backend=RAY) == [str(tmp_path)] * 2


def test_auto_starts_an_instance_when_the_one_ray_start_recorded_is_gone(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ray's own "auto" would retry an instance stopped without `ray stop` for minutes; piga starts its own."""
    import ray._private.services as services

    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        gone = f"127.0.0.1:{free.getsockname()[1]}"
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr(services, "find_bootstrap_address", lambda temp_dir: gone)
    assert _local_instance() == "local"
    live = ray.get_runtime_context().gcs_address
    monkeypatch.setattr(services, "find_bootstrap_address", lambda temp_dir: live)
    assert _local_instance() == live
    monkeypatch.setenv("RAY_ADDRESS", "10.0.0.5:6379")  # the user's own choice is kept, and checked when joining
    assert _local_instance() == "10.0.0.5:6379"
