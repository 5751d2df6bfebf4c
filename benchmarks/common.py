"""What the benchmark scripts share: a record of the machine the numbers were measured on, the options passed
through to ``piga-diagnose``, and for the scripts that farm jobs ``--ray``, the commands their jobs run, and
the one line that a failed job ends the script with."""

from __future__ import annotations

import argparse
import functools
import inspect
import os
import platform
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import torch

from piga.cli.common import PigaError, add_ray_option, connect_backend, seed_int
from piga.io.pool import Backend, BackendError, JobFailed
from piga.io.worker_signals import die_with_parent

__all__ = ["ALGO_LABELS", "add_diagnose_options", "add_ray_option", "add_training_options", "check_record", "diagnose_options", "farm_main",
           "is_learning_curve", "is_number", "job_command", "logged_command", "machine", "machine_words", "ray_backend", "signed"]

Main = TypeVar("Main", bound=Callable[..., Any])

#: The model-free baselines' algorithms (a record's ``algo``) as the tables, the figures and the summaries name them.
ALGO_LABELS = {"ddpg": "DDPG", "sac": "SAC", "drqv2": "DrQ-v2"}


def machine() -> dict[str, object]:
    """Where the numbers were measured."""
    cpu, family, model = "unknown", "?", "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            key, value = key.strip(), value.strip()
            if key == "model name" and cpu == "unknown":
                cpu = value
            elif key == "cpu family" and family == "?":
                family = value
            elif key == "model" and model == "?":
                model = value
    except OSError:
        pass
    # "AMD EPYC" names several generations, of different speeds (family 23 model 1 is Zen 1); family/model tells them apart
    return {"cpu": cpu, "cpu_family_model": f"{family}/{model}", "cores": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
            "python": platform.python_version(), "platform": platform.platform()}


def score_cells(scores: dict[str, Any] | None, missing: str = "no record", x14_episodes: bool = True) -> str:
    """Three table cells of one run scored at x1.0 and x1.4 (``x1``/``x1.4``, piga.control.episodes' summaries):
    success at x1.0 (episodes), mean return at x1.0, success at x1.4 (with its episodes unless ``x14_episodes`` is
    False); ``missing`` and two empty cells where ``scores`` is None."""
    if scores is None:
        return f"{missing} | |"
    x1, x14 = scores["x1"], scores["x1.4"]
    tail = f" ({x14['episodes']})" if x14_episodes else ""
    return (f"{100 * x1['success_rate']:.0f}% ({x1['episodes']}) | {x1['mean_return']:.1f} | "
            f"{100 * x14['success_rate']:.0f}%{tail}")


def change_cells(before: dict[str, Any] | None, after: dict[str, Any]) -> str:
    """Three table cells of one run scored twice (``x1`` and ``x1.4``, piga.control.episodes' summaries; ``before``
    None when it has no earlier record): success at x1.0 (episodes), mean return at x1.0, success at x1.4
    (episodes), each as "before → after"."""

    def cell(key: str, was: dict[str, Any] | None, now: dict[str, Any], fmt: str) -> str:
        scale = 100 if key == "success_rate" else 1
        return f"{'—' if was is None else format(was[key] * scale, fmt)} → {format(now[key] * scale, fmt)}"

    before = before or {}
    x1, x14 = after["x1"], after["x1.4"]
    return (f"{cell('success_rate', before.get('x1'), x1, '.0f')}% ({x1['episodes']}) | "
            f"{cell('mean_return', before.get('x1'), x1, '.1f')} | "
            f"{cell('success_rate', before.get('x1.4'), x14, '.0f')}% ({x14['episodes']})")



def process_memory_kib(field: str) -> int:
    """A memory field of this process (``VmRSS``, ``VmHWM``) in KiB, from Linux's /proc/self/status."""
    fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    return int(fields[field].split()[0])


def peak_memory_readable(script: str) -> bool:
    """Whether this machine lets a memory benchmark read its peak (Linux's /proc/self/status and clear_refs); prints
    ``script``'s one-line error where it does not."""
    if Path("/proc/self/clear_refs").exists():
        return True
    print(f"{script}: error: needs Linux's /proc/self/status and clear_refs to read peak memory", file=sys.stderr)
    return False


def _put_result(measure: Callable[..., Any], args: tuple, queue: Any) -> None:
    queue.put(measure(*args))


def measured_in_fresh_process(measure: Callable[..., Any], args: tuple, script: str, what: str) -> Any:
    """``measure(*args)`` in a fresh (spawned) process, so that its peak memory is its own; its result, or None after
    ``script``'s one-line error naming ``what`` where the process failed (killed for memory, say)."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    child = context.Process(target=_put_result, args=(measure, args, queue))
    child.start()
    child.join()  # (the result is a few numbers: the queue never blocks the child's exit)
    if child.exitcode != 0:
        print(f"{script}: error: measuring {what} failed (exit {child.exitcode}; killed for memory?)", file=sys.stderr)
        return None
    return queue.get(timeout=60)


def write_page(out: Path, record: dict[str, Any], page: str) -> None:
    """Writes ``OUT.json`` (the record) and ``OUT.md`` (the page), both or neither, and says so."""
    from piga.io.atomic import atomic_output, write_json, written_together

    with written_together([out.with_suffix(".json"), out.with_suffix(".md")]):  # no record without its page
        # the page first: a failed record write then removes only the new page, and a record that a script reads back
        # (to continue a stopped run) stays; written the other way, a failed page removed the only copy of the record
        with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
            Path(tmp).write_text(page, encoding="utf-8")
        write_json(out.with_suffix(".json"), record, overwrite=True)
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.json')}")


def check_page_target(out: Path, *suffixes: str) -> None:
    """Fails, before any work, where :func:`write_page` (``OUT.json``, ``OUT.md``) or a figure ``OUT{suffix}`` could not
    be written (a missing folder, a file where a folder goes): the pages are written after the jobs, which took
    minutes to learn what a path could have said at once."""
    from piga.io.atomic import check_writable_target

    for suffix in (".json", ".md", *suffixes):
        check_writable_target(out.with_name(out.name + suffix) if suffix.startswith("-") else out.with_suffix(suffix),
                              overwrite=True)


def out_prefix(text: str) -> Path:
    """argparse type of a benchmark's ``--out``, the prefix of the pages (OUT.json, OUT.md, figures) written after its
    jobs: refused at once where they could not be written (an unwritable folder, a file where a folder goes, /proc),
    which the scripts found out only after hours, as "removed or moved while it ran?"."""
    path = Path(text)
    if not text.strip() or path.name in ("", ".", ".."):
        raise argparse.ArgumentTypeError(f"expected a file prefix such as results/name, got {text!r}")
    existing = _writable_folder_above(path.parent, f", so {text} cannot be written there")
    import shutil

    if shutil.disk_usage(existing).total == 0:  # /proc, /sys
        raise argparse.ArgumentTypeError(f"{existing} is on a file system that stores no files (as /proc and /sys "
                                         "are); write elsewhere")
    for page in (path.with_suffix(".json"), path.with_suffix(".md")):  # a folder there failed after the work
        if page.is_dir():
            raise argparse.ArgumentTypeError(f"{page} is a folder, so the page {page.name} cannot be written there")
    return path


def work_folder(text: str) -> Path:
    """argparse type of a benchmark's ``--work`` (its data and runs, kept for a rerun): a folder, or a path where one
    can be made (a file there gave "[Errno 17] File exists")."""
    path = Path(text)
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder such as runs/name, got ''")
    _writable_folder_above(path, ": give a folder for the data and runs")
    return path


def _writable_folder_above(path: Path, after_file: str) -> Path:
    """``path`` or its nearest existing parent, which must be a writable folder (the folders below it are made
    later); a file there is refused with ``after_file`` ending the line."""
    existing = next((p for p in (path, *path.parents) if p.exists()), Path("."))
    if not existing.is_dir():
        raise argparse.ArgumentTypeError(f"{existing} is a file, not a folder{after_file}")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"folder {existing} is not writable")
    return existing


def is_number(value: Any) -> bool:
    """Whether a JSON record's ``value`` is a finite real number (a boolean is not)."""
    import math

    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def is_learning_curve(curve: Any) -> bool:
    """Whether ``curve`` is an SB3 run's learning curve as its checkpoint and learning_curve.py's record hold it: a list
    of points, each a ``step`` (an integer) and an ``eval_mean_return`` (a finite number)."""
    return isinstance(curve, list) and all(isinstance(r, dict) and isinstance(r.get("step"), int)
                                           and is_number(r.get("eval_mean_return")) for r in curve)


def check_record(path: Path, condition: bool, what: str) -> None:
    """Refuses a record read from ``path`` that is not of the shape a script reads (a list where an object is
    expected, text where a number is): ValueError naming the file and ``what`` it must hold, the one line the script
    ends with (it was an internal error deep inside, a TypeError or a KeyError)."""
    if not condition:
        raise ValueError(f"{path}: {what}")


def signed(x: float, digits: int = 1) -> str:
    """A number with a typographic minus, as the README and the results pages write them."""
    return f"{x:.{digits}f}".replace("-", "\u2212")


def machine_words(m: dict[str, object]) -> str:
    """A :func:`machine` record in words, for a results page: "AMD EPYC (family/model 25/17), 2 cores; ..."."""
    threads = m.get("torch_threads")
    plural = "" if threads == 1 else "s"
    return (f"{m.get('cpu', 'unknown')} (family/model {m.get('cpu_family_model', '?')}), {m.get('cores', '?')} cores; "
            f"torch {m.get('torch', '?')} on {threads} thread{plural}, Python {m.get('python', '?')}")


#: The diagnosis' readings that the benchmarks running ``piga-diagnose`` pass through: (flag, help).
#: Both are on by default in ``piga-diagnose``; ``--no-FLAG`` reproduces the pages run without them.
DIAGNOSE_OPTIONS = (("--fit-starts", "pass --fit-starts or --no-fit-starts to piga-diagnose (default: its own)"),
                    ("--matched-angles", "pass --matched-angles or --no-matched-angles to piga-diagnose "
                                         "(default: its own)"))


def add_diagnose_options(parser: argparse.ArgumentParser, help_suffix: dict[str, str] | None = None) -> None:
    """Adds :data:`DIAGNOSE_OPTIONS` to a benchmark's parser (each ``None`` unless given), ``help_suffix`` by flag."""
    for flag, text in DIAGNOSE_OPTIONS:
        parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=None,
                            help=text + (help_suffix or {}).get(flag, ""))


def diagnose_options(args: object) -> tuple[str, ...]:
    """The ``piga-diagnose`` flags of :data:`DIAGNOSE_OPTIONS` that ``args`` gave, either way."""
    flags = []
    for flag, _ in DIAGNOSE_OPTIONS:
        value = getattr(args, flag[2:].replace("-", "_"))
        if value is not None:
            flags.append(flag if value else "--no-" + flag[2:])
    return tuple(flags)


@dataclass(frozen=True)
class TrainingBenchConfig:
    """The settings every benchmark that trains ``piga-train-model`` runs on collected scene data shares (each
    benchmark's ``BenchConfig`` adds its own rows, and may give other defaults)."""

    seeds: tuple[int, ...] = (0,)
    budget_steps: int = 1650
    """Optimiser steps of every run (``piga-train-model --budget-steps``; the scenes' fast recipe's): the same for
    every run it compares."""
    sequences: int = 100
    """Sequences per data set (``piga-collect --sequences``), split 80/10/10."""
    data_seed: int = 100
    jobs: int = 1
    """Runs trained at once, each in its own process with one torch thread."""


def add_training_options(parser: argparse.ArgumentParser, defaults: Any, sequences_help: str) -> None:
    """The options of a benchmark that trains ``piga-train-model`` runs on collected data, with the defaults of its
    ``BenchConfig`` (``defaults``: ``seeds``, ``budget_steps``, ``sequences``, ``jobs``): ``--seeds``,
    ``--budget-steps``, ``--sequences`` (``sequences_help``), ``--jobs`` and ``--ray``."""
    from piga.cli.common import int_at_least, positive_int

    parser.add_argument("--seeds", nargs="+", type=seed_int, default=list(defaults.seeds),
                        help="training seeds (default %(default)s)")
    parser.add_argument("--budget-steps", type=positive_int, default=defaults.budget_steps,
                        help="optimiser steps of every run (default %(default)s)")
    parser.add_argument("--sequences", type=int_at_least(10, "the test split is a tenth of them"), default=defaults.sequences,
                        help=f"{sequences_help} (default %(default)s)")
    parser.add_argument("--jobs", type=positive_int, default=defaults.jobs,
                        help="runs trained at once, each in its own process with one torch thread (default %(default)s)")
    add_ray_option(parser, "the training runs (OUT_runs/ shared by every machine)")


def ray_backend(parser: argparse.ArgumentParser, args: argparse.Namespace) -> Backend:
    """The backend that ``args.ray`` asks for (the option of :func:`add_ray_option`, the commands' own), connected
    before any work; Ray missing or no Ray cluster at the address ends the script with one line (exit 1)."""
    try:
        return connect_backend(args.ray)
    except PigaError as exc:
        parser.exit(1, f"{parser.prog}: error: {exc}\n")


def farm_main(main: Main) -> Main:
    """Decorates a benchmark's ``main`` that farms jobs (:func:`piga.io.pool.run_pool`): a job that failed
    (:class:`~piga.io.pool.JobFailed`) or a backend that cannot be used (:class:`~piga.io.pool.BackendError`)
    ends the script with one line on stderr, ``SCRIPT: error: job NAME failed: ...``, and exit status 1,
    instead of a traceback. The jobs that ended before it kept their records (each script saves them as they
    end), so the same command continues. Ctrl-C is left as it was."""
    script = Path(inspect.getfile(main)).name

    @functools.wraps(main)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        try:
            return main(*args, **kwargs)
        except (JobFailed, BackendError) as exc:
            print(f"{script}: error: {' '.join(str(exc).split())}", file=sys.stderr)
            raise SystemExit(1) from None

    return wrapped  # type: ignore[return-value]


def job_command(command: list[str], **kwargs: Any) -> subprocess.CompletedProcess:
    """``subprocess.run(command, **kwargs)`` for a job: the command ends (SIGTERM, which piga's commands turn
    into their clean interruption) when the process that runs the job ends. A job in a worker of the runner
    (which leaves Ctrl-C to the parent, and is terminated by it) would otherwise leave its command running."""
    return subprocess.run(command, preexec_fn=die_with_parent, **kwargs)


def logged_command(command: list[str], log: Path) -> int:
    """Runs a job's piga command as a user would (:func:`job_command`), its line and output appended to ``log``;
    its exit status."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("a") as f:
        f.write("$ " + " ".join(command) + "\n")
        f.flush()
        return job_command(command, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode


def checked_command(command: list[str]) -> None:
    """Runs one piga command as a user would (:func:`job_command`, its output dropped); its failure ends the script
    with the command's own one line (a CalledProcessError was an internal error, its second line)."""
    done = job_command(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    if done.returncode:
        said = done.stderr.strip().splitlines()
        raise PigaError(said[-1] if said else f"{command[0]} failed (exit {done.returncode})")


def check_piga_model(run_dir: str) -> None:
    """``--model``: a piga run folder whose model loads, checked before any work (a missing one failed only after the
    first case's data was made)."""
    from piga.io.runs import load_model

    load_model(run_dir)
