"""Running jobs in worker processes or on a Ray cluster, and recording them so that a stopped run continues where it stopped.

:func:`run_pool` calls any picklable function on each of a list of job specs, on a :class:`Backend`:

- ``local`` (the default): in ``workers`` processes of this machine when more than one. Each worker
  runs one torch thread, leaves Ctrl-C to the parent (which terminates the pool), and ends at once,
  quietly, on the pool's SIGTERM and when its parent dies (:mod:`piga.io.worker_signals`).
- ``ray``: as tasks of a Ray cluster, one CPU and one torch thread each (:mod:`piga.io.ray_backend`;
  Ray is an optional extra, imported only there).

Either way the results come back in the order of the specs, ``on_result`` sees each in this process as
it ends, and a job that raises stops the run with :class:`JobFailed`, which names the job.
:func:`run_recorded` adds resume: each finished job's record is written at once to a folder of
:class:`JobRecords`, with the spec it was run with and the code's git commit, and a job whose record
holds the same spec is not run again.
"""

from __future__ import annotations

import functools
import multiprocessing as mp
import os
import subprocess
import sys
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple, TypeVar

from tqdm.auto import tqdm

from piga.io.atomic import write_json
from piga.io.choices import check_choices
from piga.io.worker_signals import die_with_parent, quiet_worker_signals, sigterm_held

Spec = TypeVar("Spec")
Result = TypeVar("Result")


#: Ray's default port of a cluster's head (``ray start --head``), for an address given without one.
RAY_DEFAULT_PORT = 6379


class BackendError(Exception):
    """A backend that cannot be used: Ray not installed, or no Ray cluster at the address (one line, the user's to fix)."""


class JobFailed(RuntimeError):
    """A job raised: its name, and what it raised (``cause``). Jobs that ended before it kept their results
    (``on_result`` saw them); those still running were stopped."""

    def __init__(self, job: str, cause: BaseException) -> None:
        message = " ".join(str(cause).split()) or "no message"
        super().__init__(f"job {job} failed: {cause.__class__.__name__}: {message[:500]}")
        self.job = job
        self.cause = cause


@dataclass(frozen=True)
class Backend:
    """Where :func:`run_pool` runs its jobs."""

    kind: Literal["local", "ray"] = "local"
    """"local": processes of this machine; "ray": tasks of a Ray cluster (``pip install -e '.[ray]'``)."""
    address: str = "auto"
    """For "ray": "auto" (join the Ray instance running on this machine, else start one) or HOST:PORT,
    the address of a cluster's head (``ray start --head`` prints it; HOST alone means port 6379)."""

    def __post_init__(self) -> None:
        check_choices(self)
        if self.kind == "ray" and self.address != "auto":
            host_port(self.address)

    @classmethod
    def from_option(cls, ray: str | None) -> Backend:
        """The backend of a ``--ray`` option: local when not given, else Ray at ``ray`` ("auto" or HOST[:PORT])."""
        return cls() if ray is None else cls("ray", ray.strip())

    def connect(self) -> None:
        """Checks that the backend can run jobs, and for Ray joins (or starts) its cluster now, so that a
        missing package or a wrong address is refused before any work (:class:`BackendError`)."""
        if self.kind == "ray":
            from piga.io.ray_backend import connect

            connect(self.address)

    def __str__(self) -> str:
        return "local processes" if self.kind == "local" else f"Ray ({self.address})"


def host_port(address: str) -> tuple[str, int]:
    """``address``'s host and port ("HOST:PORT", or "HOST" for :data:`RAY_DEFAULT_PORT`); a ValueError names a bad one."""
    host, colon, port = address.rpartition(":")
    if not colon:
        host, port = address, str(RAY_DEFAULT_PORT)
    if not host or not port.isdigit() or not 0 < int(port) < 65536 or any(c.isspace() or c == "/" for c in host):
        raise ValueError(f"a Ray address is 'auto' or HOST:PORT (e.g. 10.0.0.5:6379), got {address!r}")
    return host.strip("[]"), int(port)


def job_name(spec: Any) -> str:
    """What a failed job is called: its ``name`` attribute when it has one, else its spec as text, shortened."""
    name = getattr(spec, "name", None)
    if isinstance(name, str):
        return name
    text = " ".join(str(spec).split())
    return text if len(text) <= 80 else text[:77] + "..."


def init_worker() -> None:
    """A pool worker's start: it ends at once, quietly, on SIGTERM (the pool's terminate) and when its parent
    dies; Ctrl-C is the parent's to handle; one torch thread (small tensors, and the workers share the cores).

    torch is not imported here when the parent has not imported it (seconds per worker, for jobs that may not
    need it, such as drawing the scenes): ``OMP_NUM_THREADS=1`` gives a torch imported later its one thread."""
    quiet_worker_signals()
    die_with_parent()
    os.environ["OMP_NUM_THREADS"] = "1"
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


class _Failure(NamedTuple):
    """What a pool worker sends back for a job that raised: the exception and its traceback, as text."""

    error: BaseException
    traceback: str


class WorkerTraceback(Exception):
    """A worker's traceback, as text: the cause of the error it sent back (as multiprocessing chains it)."""

    def __str__(self) -> str:
        return f"\n{self.args[0]}"


def _indexed(function: Callable[[Spec], Result], item: tuple[int, Spec]) -> tuple[int, Result | _Failure]:
    try:
        return item[0], function(item[1])
    except Exception as exc:
        return item[0], _Failure(exc, traceback.format_exc())


def run_pool(function: Callable[[Spec], Result], specs: Sequence[Spec], workers: int = 1, progress: bool = True,
             desc: str = "jobs", on_result: Callable[[int, Result], None] | None = None,
             backend: Backend | None = None, names: Sequence[str] | None = None) -> list[Result]:
    """``function(spec)`` for each of ``specs``; the results in the order of ``specs``. ``on_result(i, result)``
    is called in this process as each job ends (in the order they end), so that a result can be saved before
    the others are done.

    ``backend`` (default local): local runs ``workers`` processes when > 1, else this process; Ray runs
    every job as a task of one CPU, as many at once as the cluster has free CPUs (``workers`` is not used).
    A job that raises stops the run with :class:`JobFailed` naming it (``names[i]``, by default
    :func:`job_name`); the jobs still running are stopped, those that ended kept their ``on_result``.

    On KeyboardInterrupt (Ctrl-C, or SIGTERM turned into it by :func:`piga.cli.common.run_cli`) the
    pool terminates its workers (Ray: cancels the tasks) before the exception propagates; a local worker
    whose parent is killed ends too.
    """
    if names is not None and len(names) != len(specs):
        raise ValueError(f"run_pool: {len(names)} names for {len(specs)} jobs")
    name = (lambda i: names[i]) if names is not None else (lambda i: job_name(specs[i]))
    if backend is not None and backend.kind == "ray":
        from piga.io.ray_backend import run_ray

        return run_ray(function, specs, [name(i) for i in range(len(specs))], progress, desc, on_result, backend.address)
    results: list[Any] = [None] * len(specs)
    if workers <= 1 or len(specs) <= 1:
        for i, spec in enumerate(tqdm(specs, desc=desc, disable=not progress)):
            try:
                results[i] = function(spec)
            except Exception as exc:
                raise JobFailed(name(i), exc) from exc
            if on_result is not None:
                on_result(i, results[i])
        return results
    # fork, as torch's DataLoader does: with spawn, torch's import makes the resource tracker warn
    # about leaked semaphores. The parent has rendered nothing; each child sets one torch thread.
    method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
    with sigterm_held():  # the workers and the pool's threads start with SIGTERM held, until init_worker
        pool = mp.get_context(method).Pool(min(workers, len(specs)), initializer=init_worker)
    with pool:  # exit: terminate
        done = pool.imap_unordered(functools.partial(_indexed, function), enumerate(specs))
        for i, result in tqdm(done, total=len(specs), desc=desc, disable=not progress):
            if isinstance(result, _Failure):  # the pool's exit terminates the jobs still running
                result.error.__cause__ = WorkerTraceback(result.traceback)
                raise JobFailed(name(i), result.error) from result.error
            results[i] = result
            if on_result is not None:
                on_result(i, result)
    return results


@functools.cache
def git_commit(path: Path = Path(__file__).parent) -> str | None:
    """The commit checked out where ``path`` is (by default piga's own code), or None outside a git checkout; read
    once per process (:func:`current_commit` reads it again)."""
    return current_commit(path)


def current_commit(path: Path = Path(__file__).parent) -> str | None:
    """:func:`git_commit`, read now."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=path, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return (out.stdout.strip() or None) if out.returncode == 0 else None


@dataclass(frozen=True)
class JobRecords:
    """A folder of job records, ``NAME.json`` per job, each a JSON object with the ``spec`` the job was run with.

    A record counts for a job only while its spec is the job's (:meth:`kept`): change a setting and the job runs again.
    """

    folder: Path
    """Where the records are."""

    def path(self, name: str) -> Path:
        """Job ``name``'s record file."""
        return self.folder / f"{name}.json"

    def kept(self, name: str, spec: dict[str, Any]) -> dict[str, Any] | None:
        """Job ``name``'s record if one was kept for ``spec`` (JSON types), else None."""
        import json

        path = self.path(name)
        if not path.exists():
            return None
        record = json.loads(path.read_text())
        return record if record.get("spec") == spec else None

    def write(self, name: str, record: dict[str, Any]) -> None:
        """Writes job ``name``'s record atomically."""
        self.folder.mkdir(parents=True, exist_ok=True)
        write_json(self.path(name), record)


@dataclass(frozen=True)
class RecordedJob:
    """One job of :func:`run_recorded`: its name (its record's file name), its spec (what its record must
    match to be kept, JSON types) and what the job function is called with."""

    name: str
    spec: dict[str, Any]
    args: Any


def run_recorded(function: Callable[[Any], dict[str, Any]], jobs: Sequence[RecordedJob], records: JobRecords,
                 workers: int = 1, progress: bool = True, desc: str = "jobs",
                 backend: Backend | None = None) -> dict[str, dict[str, Any]]:
    """Every job's record, by name: kept ones as they are; the others run in the given order, ``workers`` at a
    time (:func:`run_pool`, on ``backend``), with ``function(job.args)`` returning the record's fields. Each
    record is written as its job ends, as ``{"spec": job.spec, "commit": git_commit(), **fields}``, so that a
    run stopped at any point keeps every finished job, and the next run does only the others. A job that ends
    after the checkout moved to another commit (code committed while the jobs ran: a job that starts a command
    runs whatever code is on disk then) also records ``commit_at_end``, so that its record does not pass for the
    first commit's alone."""
    out = {job.name: kept for job in jobs if (kept := records.kept(job.name, job.spec)) is not None}
    todo = [job for job in jobs if job.name not in out]
    commit = git_commit()

    def save(i: int, fields: dict[str, Any]) -> None:
        record = {"spec": todo[i].spec, "commit": commit, **fields}
        if (now := current_commit()) != commit:
            record["commit_at_end"] = now
        records.write(todo[i].name, record)
        out[todo[i].name] = record

    run_pool(function, [job.args for job in todo], workers, progress, desc, on_result=save, backend=backend,
             names=[job.name for job in todo])
    return {job.name: out[job.name] for job in jobs}


__all__ = ["Backend", "BackendError", "JobFailed", "JobRecords", "RecordedJob", "current_commit", "git_commit", "host_port",
           "init_worker", "job_name", "run_pool", "run_recorded"]
