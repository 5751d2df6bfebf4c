"""Benchmark: the memory an SB3 run's checkpoint takes to write and to read back, by where its replay buffer goes.

A DrQ-v2 run on the DMC pendulum holds a replay buffer of 100,000 stacks of three 64x64 frames, observations and
next observations: 2.5 GB. Its checkpoint used to carry the buffer as bytes inside ``checkpoint.pt``: SB3 pickled
the buffer into memory, the bytes were copied out, and torch pickled them again into its own in-memory record and
copied that. One such run was killed by the kernel's out-of-memory killer at 16.9 GB resident while it
checkpointed, on a 24 GB machine. ``piga-baseline ddpg`` now streams the buffer into a file of its own
(``replay_buffers/STEP.pkl``, SB3's ``save_replay_buffer`` to an open file) and ``checkpoint.pt`` names it
(:func:`agents.sb3.train._save`).

For each way, in a fresh process: builds the run's DrQ-v2 model as ``piga-baseline ddpg --algo drqv2`` does with
a buffer of ``--buffer-size`` transitions, fills the buffer (every slot, constant frames: a pickle's size does not
depend on the values), then writes the checkpoint, and reads it back into a new model as ``--resume`` does. It
reports the resident memory before, the peak (the process's high-water mark) over it during the write and during
the read, and the seconds each took.

    python benchmarks/checkpoint_memory.py --out results/checkpoint_memory

Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import io
import shlex
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import (machine, machine_words, measured_in_fresh_process, out_prefix, peak_memory_readable,
                    process_memory_kib, write_page)
from piga.cli.common import ArgumentParser, positive_int

#: The ways compared: the buffer as bytes inside checkpoint.pt (as before), or streamed into its own file (piga's).
WAYS = ("bytes", "file")


def _rss_gb() -> tuple[float, float]:
    """This process's resident memory now and its high-water mark, in GB (Linux's /proc/self/status)."""
    return process_memory_kib("VmRSS") / 1e6, process_memory_kib("VmHWM") / 1e6


def _reset_peak() -> None:
    """Resets the high-water mark to the resident memory now (Linux: writing 5 to /proc/self/clear_refs)."""
    Path("/proc/self/clear_refs").write_text("5")


def measure(way: str, buffer_size: int) -> dict[str, float]:
    """One way in this process: memory and seconds of the write and of the read."""
    import torch

    from agents.sb3.config import SB3Config
    from agents.sb3.train import _load_replay_buffer, _save, _vec_env, new_model
    from piga.io.checkpoint import CHECKPOINT, write_checkpoint

    torch.set_num_threads(1)
    config = SB3Config(algo="drqv2", obs="pixels", buffer_size=buffer_size, steps=10_000, eval_every=1000, device="cpu")
    venv = _vec_env(config, None, 0, episode_seed=0)
    model = new_model(config, venv, torch.device("cpu"))
    buffer = model.replay_buffer
    buffer.observations[:] = 7
    buffer.next_observations[:] = 9
    buffer.full = True
    out: dict[str, float] = {"buffer_gb": (buffer.observations.nbytes + buffer.next_observations.nbytes) / 1e9}
    with tempfile.TemporaryDirectory() as folder:
        run = Path(folder)
        _reset_peak()
        before, _ = _rss_gb()
        start = time.perf_counter()
        if way == "bytes":  # as the checkpoint was written before: the buffer pickled into memory, then into torch's
            policy, pickled = io.BytesIO(), io.BytesIO()
            model.save(policy)
            model.save_replay_buffer(pickled)
            write_checkpoint(run, {"model_zip": policy.getvalue(), "replay_buffer": pickled.getvalue()})
            del pickled
        else:
            _save(run, model, config, 1, [], 0.0)
        out["write_seconds"] = time.perf_counter() - start
        _, peak = _rss_gb()
        out.update(resident_gb=before, write_peak_over_gb=peak - before)
        model.replay_buffer = None  # the read fills a new model's buffer, as --resume does
        del buffer
        fresh = new_model(config, venv, torch.device("cpu"))
        _reset_peak()
        before, _ = _rss_gb()
        start = time.perf_counter()
        ckpt = torch.load(run / CHECKPOINT, map_location="cpu", weights_only=False)
        _load_replay_buffer(fresh, run, ckpt)
        out["read_seconds"] = time.perf_counter() - start
        _, peak = _rss_gb()
        out["read_peak_over_gb"] = peak - before
        out["checkpoint_gb"] = sum(p.stat().st_size for p in run.rglob("*") if p.is_file()) / 1e9
    venv.close()
    return out


def markdown(record: dict[str, Any]) -> str:
    rows = record["ways"]
    lines = [
        "# An SB3 run's checkpoint: memory to write and to read back",
        "",
        f"From `{record['command']}` on {machine_words(record['machine'])}.",
        "",
        f"A DrQ-v2 model as `piga-baseline ddpg --algo drqv2` builds it, its replay buffer of {record['buffer_size']:,} "
        f"transitions full ({rows['file']['buffer_gb']:.2f} GB of frames); each way in a fresh process. Peak: the "
        "process's high-water mark over its resident memory just before (Linux's VmHWM, reset there). The seconds are "
        "as the machine ran (a guide, not a speed claim: time it alone for one); the memory is the measure.",
        "",
        "| replay buffer | resident before (GB) | write: peak over it (GB) | write s | read: peak over it (GB) | read s | "
        "on disk (GB) |",
        "|---|---|---|---|---|---|---|",
    ]
    names = {"bytes": "bytes inside checkpoint.pt (before)", "file": "its own file, streamed (piga's)"}
    for way in WAYS:
        r = rows[way]
        lines.append(f"| {names[way]} | {r['resident_gb']:.2f} | {r['write_peak_over_gb']:.2f} | {r['write_seconds']:.1f} | "
                     f"{r['read_peak_over_gb']:.2f} | {r['read_seconds']:.1f} | {r['checkpoint_gb']:.2f} |")
    ratio = rows["bytes"]["write_peak_over_gb"] / max(rows["file"]["write_peak_over_gb"], 1e-9)
    lines += ["", f"Writing through bytes took {rows['bytes']['write_peak_over_gb'] / rows['bytes']['buffer_gb']:.1f} times "
              f"the buffer's size in extra memory; streamed, {rows['file']['write_peak_over_gb'] / rows['file']['buffer_gb']:.2f} "
              f"times ({ratio:.0f}x less).", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.md and OUT.json")
    p.add_argument("--buffer-size", type=positive_int, default=30_000,
                   help="transitions in the replay buffer (DrQ-v2's runs: 100000, 2.5 GB) (default %(default)s)")
    args = p.parse_args(argv)
    if not peak_memory_readable("checkpoint_memory.py"):
        return 1
    ways = {}
    for way in WAYS:
        if (row := measured_in_fresh_process(measure, (way, args.buffer_size), "checkpoint_memory.py", f"'{way}'")) is None:
            return 1
        ways[way] = row
        print(f"{way}: {ways[way]}")
    command = shlex.join(["python", "benchmarks/checkpoint_memory.py", *(sys.argv[1:] if argv is None else argv)])
    record = {"command": command, "machine": machine(), "buffer_size": args.buffer_size, "ways": ways}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
