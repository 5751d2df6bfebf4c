"""Running jobs in worker processes, and recording them so that a stopped run continues where it stopped.

:func:`run_pool` calls any picklable function on each of a list of job specs, in ``workers``
processes when more than one: each worker runs one torch thread, leaves Ctrl-C to the parent (which
terminates the pool), and ends at once, quietly, on the pool's SIGTERM and when its parent dies
(:mod:`piga.io.worker_signals`). :func:`run_recorded` adds resume: each finished job's record is
written at once to a folder of :class:`JobRecords`, with the spec it was run with and the code's git
commit, and a job whose record holds the same spec is not run again.
"""

from __future__ import annotations

import functools
import multiprocessing as mp
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from tqdm.auto import tqdm

from piga.io.atomic import write_json
from piga.io.worker_signals import die_with_parent, quiet_worker_signals

Spec = TypeVar("Spec")
Result = TypeVar("Result")


def init_worker() -> None:
    """A pool worker's start: it ends at once, quietly, on SIGTERM (the pool's terminate) and when its parent
    dies; Ctrl-C is the parent's to handle; one torch thread (small tensors, and the workers share the cores)."""
    quiet_worker_signals()
    die_with_parent()
    import torch

    torch.set_num_threads(1)


def _indexed(function: Callable[[Spec], Result], item: tuple[int, Spec]) -> tuple[int, Result]:
    return item[0], function(item[1])


def run_pool(function: Callable[[Spec], Result], specs: Sequence[Spec], workers: int = 1, progress: bool = True,
             desc: str = "jobs", on_result: Callable[[int, Result], None] | None = None) -> list[Result]:
    """``function(spec)`` for each of ``specs``, in ``workers`` processes when > 1 (else in this process); the
    results in the order of ``specs``. ``on_result(i, result)`` is called in this process as each job ends
    (in the order they end), so that a result can be saved before the others are done.

    On KeyboardInterrupt (Ctrl-C, or SIGTERM turned into it by :func:`piga.cli.common.run_cli`) the
    pool terminates its workers before the exception propagates; a worker whose parent is killed ends too.
    """
    results: list[Any] = [None] * len(specs)
    if workers <= 1 or len(specs) <= 1:
        for i, spec in enumerate(tqdm(specs, desc=desc, disable=not progress)):
            results[i] = function(spec)
            if on_result is not None:
                on_result(i, results[i])
        return results
    # fork, as torch's DataLoader does: with spawn, torch's import makes the resource tracker warn
    # about leaked semaphores. The parent has rendered nothing; each child sets one torch thread.
    method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
    with mp.get_context(method).Pool(min(workers, len(specs)), initializer=init_worker) as pool:  # exit: terminate
        done = pool.imap_unordered(functools.partial(_indexed, function), enumerate(specs))
        for i, result in tqdm(done, total=len(specs), desc=desc, disable=not progress):
            results[i] = result
            if on_result is not None:
                on_result(i, result)
    return results


@functools.cache
def git_commit(path: Path = Path(__file__).parent) -> str | None:
    """The commit checked out where ``path`` is (by default piga's own code), or None outside a git checkout."""
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
                 workers: int = 1, progress: bool = True, desc: str = "jobs") -> dict[str, dict[str, Any]]:
    """Every job's record, by name: kept ones as they are; the others run in the given order, ``workers`` at a
    time (:func:`run_pool`), with ``function(job.args)`` returning the record's fields. Each record is written as
    its job ends, as ``{"spec": job.spec, "commit": git_commit(), **fields}``, so that a run stopped at any point
    keeps every finished job, and the next run does only the others."""
    out = {job.name: kept for job in jobs if (kept := records.kept(job.name, job.spec)) is not None}
    todo = [job for job in jobs if job.name not in out]
    commit = git_commit()

    def save(i: int, fields: dict[str, Any]) -> None:
        record = {"spec": todo[i].spec, "commit": commit, **fields}
        records.write(todo[i].name, record)
        out[todo[i].name] = record

    run_pool(function, [job.args for job in todo], workers, progress, desc, on_result=save)
    return {job.name: out[job.name] for job in jobs}


__all__ = ["JobRecords", "RecordedJob", "git_commit", "init_worker", "run_pool", "run_recorded"]
