"""Benchmark: how piga stores frames, and training on a file larger than memory.

Three parts, each on files that the script makes in ``--work`` with piga's own commands:

- **codecs.** Each data file's frames are written again in every :data:`piga.data.schema.FrameCodec`
  (one sequence per chunk, as piga writes them) and measured: the file's size against the raw frames,
  the write speed, the speed of reading a split whole, and the cost of a window streamed from the file
  with a cold cache (every window reads its sequence) and over a pass in
  :class:`piga.data.windows.BlockShuffleSampler`'s order (each sequence read once per pass). Speeds are in MB of raw frames per second, medians over ``--repeats``.
- **throughput.** The fast preset trains one epoch of the pendulum file (``piga-train-model --epochs 1
  --threads 1``) with its frames loaded whole and streamed, from files of each codec. Steps per second of
  the training loop (metrics.json's seconds, without the start-up and the evaluation), medians over
  ``--repeats``, the runs interleaved, each repeat in its own seeded order, so that neither a drift in the
  machine's speed nor a run's place in the repeat falls on one reading.
- **memory.** Files of ``--big-sequences`` uncompressed sequences (the pendulum file's, repeated, their
  ``/states`` dropped), the largest more than 4x ``--cap-mb``, are each trained on for 1000 steps
  (``--window-stride 33``: one window per sequence, so every sequence is read once per epoch; the largest
  file's 1000 steps are one epoch) in a memory cgroup capped at
  ``--cap-mb``. Each run's peak resident memory (``wait4``'s maxrss), the cgroup's peak charge and its count of
  hits on the limit are recorded, against the file's size. It needs root
  (to make the cgroup), or skip it with ``--skip-memory``.

    python benchmarks/storage.py --work runs/storage --out results/storage

Writes ``OUT.json`` and ``OUT.md``. A part skipped (``--skip-throughput``, ``--skip-memory``) keeps its
rows from OUT.json's previous run, and the page names the command that measured each part.
"""

from __future__ import annotations

import importlib.util
import json
import os
import random
import shlex
import statistics
import subprocess
import sys
import time
import typing
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import torch
from torch.utils.data import RandomSampler

from common import machine, machine_words, out_prefix, work_folder
from piga.data.schema import FRAME_CODEC, DatasetWriter, FrameCodec, inspect_dataset, read_sequences
from piga.data.windows import BlockShuffleSampler, SequenceWindows
from piga.io.atomic import atomic_output, write_json, written_together
from piga.cli.common import ArgumentParser, PigaError, positive_int

CODECS: tuple[FrameCodec, ...] = typing.get_args(FrameCodec)
#: The files measured: name -> piga-collect's arguments (after --out).
SOURCES = {
    "pendulum": [],
    "spring": ["--system", "spring"],
    "dmc-pendulum": ["--env", "piga/DMCPendulum-v0", "--sequences", "100"],
}
#: Training runs of the throughput part: (label, codec, --data-loading).
RUNS = (("memory, gzip-4", "gzip-4", "memory"), ("stream, none", "none", "stream"), ("stream, gzip-1", "gzip-1", "stream"),
        ("stream, gzip-4", "gzip-4", "stream"), ("stream, lzf", "lzf", "stream"))
MB = 1e6


def run(command: list[str], **kwargs: Any) -> None:
    print("$", shlex.join(command), flush=True)
    subprocess.run(command, check=True, **kwargs)


def collect_sources(work: Path) -> dict[str, Path]:
    """The measured files, made with ``piga-collect`` when absent (dm_control's only where it is installed)."""
    files = {}
    for name, args in SOURCES.items():
        path = work / f"{name}.h5"
        if not path.exists():
            if name == "dmc-pendulum" and importlib.util.find_spec("dm_control") is None:
                print("dm_control is not installed: the dmc-pendulum file is skipped", file=sys.stderr)
                continue
            run(["piga-collect", "--out", str(path), "--quiet", *args])
        files[name] = path
    return files


def rewrite(source: Path, target: Path, codec: FrameCodec, with_states: bool = True, repeat: int = 1) -> float:
    """Writes ``source``'s file again with its frames in ``codec`` (``repeat`` times over, the split repeated
    too); returns the seconds that writing took (the source is read first, outside the timing)."""
    info = inspect_dataset(source)
    with h5py.File(source, "r") as f:
        frames, actions, split = f["frames"][()], f["actions"][()], f["split"][()]
        states = f["states"][()] if with_states and "states" in f else None
        rewards = f["rewards"][()] if "rewards" in f else None
    n = len(frames)
    attrs = {k: v for k, v in info.attrs.items() if not (k == "state_names" and states is None)}
    started = time.perf_counter()
    with DatasetWriter(target, n * repeat, info.steps, info.image_shape, info.action_dim,
                       None if states is None else states.shape[-1], attrs, overwrite=True, compression=codec,
                       rewards=rewards is not None) as writer:
        for r in range(repeat):
            for i in range(0, n, 50):
                j = min(i + 50, n)
                writer.write(r * n + i, frames[i:j], actions[i:j], None if states is None else states[i:j],
                             None if rewards is None else rewards[i:j])
        writer.set_split(np.tile(split, repeat))
    return time.perf_counter() - started


def window_cost(path: Path, block: bool, cache_bytes: int, count: int = 2000) -> float:
    """Microseconds per 12-frame window streamed from ``path``'s train split through a cache of ``cache_bytes``:
    ``count`` windows in random order, or with ``block`` a whole pass in :class:`BlockShuffleSampler`'s order
    (each sequence read once)."""
    windows = SequenceWindows(path, "train", window=12, in_memory=False, cache_bytes=cache_bytes)
    generator = torch.Generator().manual_seed(0)
    order = (BlockShuffleSampler(windows, windows.sequences_cached, generator) if block
             else RandomSampler(windows, generator=generator))
    items = list(order) if block else list(order)[:count]
    started = time.perf_counter()
    for item in items:
        windows[item]
    seconds = time.perf_counter() - started
    windows.close()
    return 1e6 * seconds / len(items)


def measure_codecs(files: dict[str, Path], work: Path, repeats: int) -> list[dict[str, Any]]:
    rows = []
    for name, source in files.items():
        info = inspect_dataset(source)
        sequence = info.sequence_bytes
        raw, train_raw = info.n_sequences * sequence, info.split_counts["train"] * sequence
        for codec in CODECS:
            target = work / "codecs" / f"{name}-{codec}.h5"
            target.parent.mkdir(parents=True, exist_ok=True)
            writes = [rewrite(source, target, codec) for _ in range(repeats)]
            size = target.stat().st_size
            reads = []
            for _ in range(repeats):
                started = time.perf_counter()
                read_sequences(target, "train")
                reads.append(time.perf_counter() - started)
            row = {"file": name, "codec": codec, "sequences": info.n_sequences, "raw_mb": raw / MB, "file_mb": size / MB,
                   "ratio": raw / size, "write_mb_s": raw / MB / statistics.median(writes),
                   "read_mb_s": train_raw / MB / statistics.median(reads),
                   "window_us_cold": statistics.median(window_cost(target, False, sequence) for _ in range(repeats)),
                   "window_us_block": statistics.median(window_cost(target, True, 256 * 2**20) for _ in range(repeats))}
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


def measure_throughput(pendulum: Path, work: Path, repeats: int) -> list[dict[str, Any]]:
    files = {codec: work / "codecs" / f"pendulum-{codec}.h5" for _, codec, _ in RUNS}
    for codec, path in files.items():
        if not path.exists():
            rewrite(pendulum, path, codec)
    seconds: dict[str, list[float]] = {label: [] for label, _, _ in RUNS}
    steps: dict[str, int] = {}
    for r in range(repeats):  # each repeat in its own seeded order, so that no reading always runs in one place
        for label, codec, loading in random.Random(r).sample(RUNS, len(RUNS)):
            out = work / "throughput" / f"{label.replace(', ', '-')}-{r}"
            run(["piga-train-model", str(files[codec]), "--out", str(out), "--epochs", "1", "--threads", "1",
                 "--data-loading", loading, "--quiet", "--overwrite"], stdout=subprocess.DEVNULL)
            metrics = json.loads((out / "metrics.json").read_text())
            seconds[label].append(metrics["training"]["seconds"])
            steps[label] = metrics["training"]["steps"]
    base = statistics.median(seconds[RUNS[0][0]]) / steps[RUNS[0][0]]
    return [{"run": label, "steps": steps[label], "seconds": seconds[label],
             "steps_per_s": steps[label] / statistics.median(seconds[label]),
             "relative": base / (statistics.median(seconds[label]) / steps[label])} for label, _, _ in RUNS]


def memory_cgroup(cap_bytes: int) -> Path:
    """A new memory cgroup (v1 or v2) limited to ``cap_bytes``, beside this process's own."""
    from piga.io.resources import _cgroup_folders

    folders = _cgroup_folders()
    if not folders:
        raise PigaError("no memory cgroup to make a capped one in; run with --skip-memory")
    group = folders[0] / f"piga-storage-{os.getpid()}"
    try:
        group.mkdir()
        v1 = (group / "memory.limit_in_bytes").exists()
        (group / ("memory.limit_in_bytes" if v1 else "memory.max")).write_text(str(cap_bytes))
        if v1 and (group / "memory.memsw.limit_in_bytes").exists():  # no swap either
            (group / "memory.memsw.limit_in_bytes").write_text(str(cap_bytes))
    except OSError as exc:
        raise PigaError(f"cannot make a capped memory cgroup ({exc}); run as root, or with --skip-memory")
    return group


def measure_memory(pendulum: Path, work: Path, cap_mb: int, sequences: int) -> dict[str, Any]:
    """One epoch of training on a file of (about) ``sequences`` uncompressed sequences in a cgroup capped at ``cap_mb``."""
    cap = cap_mb * 2**20
    info = inspect_dataset(pendulum)
    repeat = -(-sequences // info.n_sequences)
    big = work / f"big-{repeat * info.n_sequences}.h5"
    if not big.exists():
        rewrite(pendulum, big, "none", with_states=False, repeat=repeat)
    size = big.stat().st_size
    group = memory_cgroup(cap)
    out = work / f"memory-run-{repeat * info.n_sequences}"
    command = ["piga-train-model", str(big), "--out", str(out), "--window-stride", "33", "--budget-steps", "1000",
               "--threads", "1", "--quiet", "--overwrite"]
    print("$", shlex.join(command), f"(in a cgroup capped at {cap_mb} MiB)", flush=True)
    v1 = (group / "memory.limit_in_bytes").exists()
    started = time.monotonic()
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, text=True,
                            preexec_fn=lambda: (group / "cgroup.procs").write_text(str(os.getpid())))
    try:
        assert proc.stdout is not None
        output = proc.stdout.read()
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.monotonic() - started
        hits = (group / ("memory.failcnt" if v1 else "memory.events")).read_text().strip()
        peak_charged = (group / ("memory.max_usage_in_bytes" if v1 else "memory.peak"))
        charged = int(peak_charged.read_text()) if peak_charged.exists() else None
    finally:  # an interrupted benchmark leaves no run and no cgroup behind
        if proc.poll() is None:
            proc.terminate()
            proc.wait()
        group.rmdir()
    proc.returncode = os.waitstatus_to_exitcode(status)
    big.unlink()  # gigabytes of repeated frames
    metrics = json.loads((out / "metrics.json").read_text()) if (out / "metrics.json").exists() else {}
    reading = json.loads((out / "config.json").read_text())["train"] if (out / "config.json").exists() else {}
    print(output)
    return {"file_bytes": size, "file_sequences": repeat * info.n_sequences, "cap_bytes": cap, "file_over_cap": size / cap,
            "exit_code": proc.returncode, "peak_rss_bytes": usage.ru_maxrss * 1024, "limit_hits": hits,
            "peak_cgroup_bytes": charged, "wall_s": wall, "data_loading": reading.get("data_loading"),
            "stream_cache_mb": reading.get("stream_cache_mb"), "steps": metrics.get("training", {}).get("steps"),
            "parameters": metrics.get("parameters"), "command": shlex.join(command), "output": output.strip().splitlines()}


def markdown(result: dict[str, Any]) -> str:
    commands = result.get("commands", {})
    lines = ["# Storage: compressed frames, and training on files larger than memory", "",
             f"Machine: {machine_words(result['machine'])}.", "", f"Command: `{commands.get('codecs', result['command'])}`", ""]
    lines += [f"piga writes `/frames` as **{result['default_codec']}**, one sequence per chunk. Sizes are of the "
              "whole file (actions, states and rewards included) against the raw frames; speeds are MB of raw frames "
              f"per second, medians over {result['repeats']} repeats.", "",
              "## Codecs", "",
              "| file | codec | file MB | raw frames / file | write MB/s | read MB/s | window, cold cache (µs) | window, block order (µs) |",
              "|---|---|---|---|---|---|---|---|"]
    for row in result["codecs"]:
        lines.append(f"| {row['file']} ({row['sequences']} seq.) | {row['codec']} | {row['file_mb']:.2f} | {row['ratio']:.1f}x | "
                     f"{row['write_mb_s']:.0f} | {row['read_mb_s']:.0f} | {row['window_us_cold']:.0f} | {row['window_us_block']:.0f} |")
    if result.get("throughput"):
        lines += ["", "## Training throughput", "",
                  f"Command: `{commands.get('throughput', result['command'])}`", "",
                  "The fast preset, one epoch of the pendulum file, one torch thread. `memory`: the train split loaded "
                  "whole; `stream`: read through the 256 MiB cache in blocks. Relative: against the first row.", "",
                  "| frames | steps | steps/s, median (slowest, fastest run) | relative (medians) |", "|---|---|---|---|"]
        for row in result["throughput"]:
            rates = [row["steps"] / s for s in row["seconds"]]
            lines.append(f"| {row['run']} | {row['steps']} | {row['steps_per_s']:.2f} ({min(rates):.2f}, {max(rates):.2f}) | "
                         f"{row['relative']:.3f} |")
    if result.get("memory"):
        runs = result["memory"]
        cap = runs[0]["cap_bytes"]
        lines += ["", "## Files larger than memory", "", f"Command: `{commands.get('memory', result['command'])}`", "",
                  f"Each file holds uncompressed sequences (the pendulum file's, repeated). Each run trains 1000 steps "
                  f"with one window per sequence (every sequence read once per epoch), in a memory cgroup capped at "
                  f"{cap / 2**20:.0f} MiB, for example `{runs[-1]['command']}`.", "",
                  "| file | of the cap | exit code | reading | steps | g, a learned | peak resident memory | of the cap | "
                  "peak charged to the cgroup | hits on the limit | wall |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for m in runs:
            learned = ", ".join(f"{v:.4g}" for k, v in (m.get("parameters") or {}).items() if k in ("g", "a"))
            lines.append(f"| {m['file_sequences']} sequences, {m['file_bytes'] / 2**30:.2f} GiB | {m['file_over_cap']:.1f}x | "
                         f"{m['exit_code']} | {m['data_loading']} ({m['stream_cache_mb']} MiB cache) | {m['steps']} | {learned} | "
                         f"{m['peak_rss_bytes'] / 2**20:.0f} MiB | {m['peak_rss_bytes'] / cap:.0%} | "
                         + (f"{m['peak_cgroup_bytes'] / 2**20:.0f} MiB" if m.get("peak_cgroup_bytes") else "n/a")
                         + f" | {m['limit_hits']} | {m['wall_s'] / 60:.1f} min |")
        lines += ["", "The peak resident memory (the kernel's maxrss of the run) counts the shared libraries' pages "
                  "(torch's, about 250 MiB), which the cgroup does not charge when another process loaded them first; "
                  "the cgroup's charge counts the page cache of the file read, which the kernel reclaims at the limit."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--work", type=work_folder, required=True, help="folder for the data files and runs")
    p.add_argument("--out", type=out_prefix, required=True, help="writes OUT.json and OUT.md")
    p.add_argument("--repeats", type=positive_int, default=3, help="repeats of each timing (default %(default)s)")
    p.add_argument("--cap-mb", type=positive_int, default=1536, help="the memory cap of the memory part, MiB (default %(default)s)")
    p.add_argument("--big-sequences", type=positive_int, nargs="+", default=[10000, 20000, 40000],
                   help="sequences of the memory part's files, rounded up to whole copies (default %(default)s)")
    p.add_argument("--skip-throughput", action="store_true",
                   help="no training-throughput part (the page keeps the one of OUT.json's previous run, if any)")
    p.add_argument("--skip-memory", action="store_true",
                   help="no memory part, which needs root for its cgroup (the page keeps the previous run's, if any)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    args.work.mkdir(parents=True, exist_ok=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    files = collect_sources(args.work)
    command = shlex.join(["python", "benchmarks/storage.py", *(argv or sys.argv[1:])])
    result: dict[str, Any] = {"command": command, "machine": machine(), "default_codec": FRAME_CODEC, "repeats": args.repeats,
                              "codecs": measure_codecs(files, args.work, args.repeats)}
    # a part skipped keeps its rows from the page's previous run, with the command that measured them
    previous = json.loads(args.out.with_suffix(".json").read_text()) if args.out.with_suffix(".json").exists() else {}
    result["commands"] = {"codecs": command}
    for part, skip in (("throughput", args.skip_throughput), ("memory", args.skip_memory)):
        if skip and part in previous:
            result[part] = previous[part]
            result["commands"][part] = previous.get("commands", {}).get(part, previous.get("command"))
        elif not skip:
            result["commands"][part] = command
            result[part] = (measure_throughput(files["pendulum"], args.work, args.repeats) if part == "throughput" else
                            [measure_memory(files["pendulum"], args.work, args.cap_mb, n) for n in args.big_sequences])
    # the record last: a failed page keeps the previous rows
    with written_together([args.out.with_suffix(".json"), args.out.with_suffix(".md")]):
        with atomic_output(args.out.with_suffix(".md"), overwrite=True) as tmp:
            tmp.write_text(markdown(result))
        write_json(args.out.with_suffix(".json"), result)
    print(markdown(result))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
