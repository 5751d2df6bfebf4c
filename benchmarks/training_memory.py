"""Benchmark: the memory that piga-train-model takes, against what its memory check counts.

``piga-train-model`` refuses, before it builds the model, a run whose parameters and batch do not fit in memory
(:mod:`piga.training.memory`): per parameter the weights, gradients, Adam's moments and step, an averaged copy and the
backward pass's temporaries; per window twice the activations that autograd saves (measured on torch's meta device,
:func:`piga.world.variants.activation_bytes`); and the process's own memory. This checks that count against the
processes' own memory, two ways, each in a fresh process with one torch thread:

- whole runs: ``piga-train-model`` (fast preset, ``--budget-steps 4``) on a small collected file of frames of that
  side, its peak resident memory (``getrusage``'s ``ru_maxrss`` of the finished command) against the check's whole
  count; a size whose count exceeds the memory available is refused by the command, and said so;
- one pass: builds the model, runs one forward and backward pass on random frames and reads how much the process's
  high-water mark of resident memory rose over it (Linux's VmHWM, reset just before), against the count for the same
  pass (the gradients and temporaries, 8 bytes per parameter, and the batch's activations).

    python benchmarks/training_memory.py --out results/training_memory

Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path
from typing import Any

from common import (machine, machine_words, measured_in_fresh_process, out_prefix, peak_memory_readable,
                    process_memory_kib, write_page)
from piga.cli.common import ArgumentParser

#: (frame side, batch) measured by default: the default 64 px run, and larger frames where the check matters (at
#: 1024x1024 a whole run needs more than this machine's memory: the command's refusal is recorded).
CASES = ((64, 32), (256, 2), (512, 2), (1024, 1))


def _peak_gib() -> float:
    return process_memory_kib("VmHWM") * 1024 / 2**30


def measure(size: int, batch: int) -> dict[str, float]:
    """One step at frames of ``size`` px and a batch of ``batch``, in this process: measured and counted GiB."""
    from dataclasses import replace

    import torch

    from piga.training.memory import ALLOCATOR_SLACK, BACKWARD_BYTES_PER_PARAMETER, training_need
    from piga.training.train import PRESETS
    from piga.world.variants import activation_bytes, build_model, parameter_count

    torch.set_num_threads(1)
    config = replace(PRESETS["fast"].model, image_size=size)
    parameters, activations = parameter_count(config), activation_bytes(config) or 0
    model = build_model(config)
    frames = torch.randint(0, 256, (batch, config.window, size, size), dtype=torch.uint8)  # (B, L+T, H, W)
    actions = torch.randn(batch, config.window, config.action_dim)  # (B, L+T, A)
    Path("/proc/self/clear_refs").write_text("5")  # the high-water mark from here
    before = _peak_gib()
    model(frames, actions).loss.backward()
    measured = _peak_gib() - before
    _, batched = training_need(parameters, activations, batch, averaged=False)
    # gradients, temporaries and activations, with the allocator's slack
    counted = (ALLOCATOR_SLACK * parameters * (4 + BACKWARD_BYTES_PER_PARAMETER) + batched) / 2**30
    return {"size": size, "batch": batch, "parameters": parameters, "activations_mib": activations / 2**20,
            "measured_gib": measured, "counted_gib": counted}


def measure_run(size: int, batch: int) -> dict[str, Any]:
    """A whole piga-train-model run at frames of ``size`` px and a batch of ``batch`` (four steps), started from this
    process: its peak resident memory against the check's count, or the command's refusal where the count does not
    fit the memory available."""
    import resource
    import subprocess
    import tempfile
    from dataclasses import replace

    from envs.pendulum import PixelPendulumConfig
    from piga.data.collect import CollectConfig, collect
    from piga.io import resources
    from piga.training.memory import training_need
    from piga.training.train import PRESETS
    from piga.world.variants import activation_bytes, parameter_count

    config = replace(PRESETS["fast"].model, image_size=size)
    fixed, batched = training_need(parameter_count(config), activation_bytes(config) or 0, batch, averaged=True)
    available = resources.available_memory()
    with tempfile.TemporaryDirectory() as folder:
        data = Path(folder) / "frames.h5"  # enough training windows for the batch, in sequences of 20 frames
        sequences = max(4, -(-batch // (20 - config.window + 1)) + 2)
        collect(CollectConfig(sequences=sequences, steps=20, seed=0, workers=1, split=(sequences - 2, 1, 1),
                              env=PixelPendulumConfig(image_size=size)), data, progress=False, command="benchmarks/training_memory.py")
        run = subprocess.run([sys.executable, "-c", RUN_TRAIN_MODEL, str(data), "--out", str(Path(folder) / "run"),
                              "--preset", "fast", "--budget-steps", "4", "--batch-size", str(batch), "--threads", "1",
                              "--quiet"], capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024 / 2**30  # (kB on Linux) its one child's
    refused = run.returncode == 1 and "needs about" in run.stderr
    if run.returncode not in (0, 3) and not refused:  # 3: finished, too short to converge (four steps)
        raise RuntimeError(f"piga-train-model at {size} px exited {run.returncode}: {run.stderr.strip()}")
    return {"size": size, "batch": batch, "counted_gib": (fixed + batched) / 2**30,
            "available_gib": None if available is None else available / 2**30,
            "measured_gib": None if refused else peak, "refused": run.stderr.strip() if refused else None}


#: piga-train-model as its script runs it, for a child whose peak memory is its own.
RUN_TRAIN_MODEL = "import sys; from piga.cli.common import run_cli; from piga.cli.train import PROG, main; " \
                  "run_cli(PROG, main, sys.argv[1:])"


def markdown(record: dict[str, Any]) -> str:
    from piga.io.resources import TRAINING_BYTES_PER_PARAMETER
    from piga.training import memory

    per_parameter = (TRAINING_BYTES_PER_PARAMETER + memory.BACKWARD_BYTES_PER_PARAMETER
                     + memory.OPTIMISER_STEP_BYTES_PER_PARAMETER + memory.AVERAGE_BYTES_PER_PARAMETER)
    slack = f"{memory.ALLOCATOR_SLACK:g}"
    lines = ["# piga-train-model's memory check against its runs", "",
             f"From `{record['command']}` on {machine_words(record['machine'])}.", "",
             "## Whole runs", "",
             "`piga-train-model` with the fast preset, `--budget-steps 4`, one torch thread, on a small collected file "
             "of frames of each side, in a fresh process. Measured: the command's peak resident memory (`getrusage`). "
             "Counted: what `piga.training.memory` counts before it builds the model (per parameter: weights, "
             f"gradients, Adam's moments and step, the averaged copy and the backward pass's temporaries, "
             f"{per_parameter} bytes; per window of the batch: {memory.ACTIVATION_FACTOR} times the activations "
             f"autograd saves, measured on torch's meta device; and {memory.PROCESS_BYTES / 2**30:g} GiB for the "
             f"process itself; all of it times {slack}, the allocator's slack). A size whose count is over the memory "
             "available is refused by the command before it builds anything.", "",
             "| frames | batch | counted | measured | counted / measured |", "|---|---|---|---|---|"]
    for r in record["runs"]:
        if r["measured_gib"] is None:
            lines.append(f"| {r['size']}x{r['size']} | {r['batch']} | {r['counted_gib']:.2f} GiB | refused: "
                         f"{r['available_gib']:.1f} GiB available | - |")
        else:
            lines.append(f"| {r['size']}x{r['size']} | {r['batch']} | {r['counted_gib']:.2f} GiB | "
                         f"{r['measured_gib']:.2f} GiB | {r['counted_gib'] / r['measured_gib']:.2f} |")
    lines += ["", "## One forward and backward pass", "",
              "The fast preset's model, one pass in a fresh process with one torch thread. Measured: the rise of the "
              "process's high-water mark of resident memory over the pass (Linux's VmHWM). Counted: the part of the "
              "check's count that one pass allocates (gradients and the backward pass's temporaries, "
              f"{4 + memory.BACKWARD_BYTES_PER_PARAMETER} bytes per parameter, and {memory.ACTIVATION_FACTOR} times "
              f"the activations autograd saves per window; times {slack}).", "",
              "| frames | batch | parameters | saved activations per window | measured | counted | counted / measured |",
              "|---|---|---|---|---|---|---|"]
    for r in record["cases"]:
        lines.append(f"| {r['size']}x{r['size']} | {r['batch']} | {r['parameters'] / 1e6:.1f}M | "
                     f"{r['activations_mib']:.1f} MiB | {r['measured_gib']:.2f} GiB | {r['counted_gib']:.2f} GiB | "
                     f"{r['counted_gib'] / max(r['measured_gib'], 1e-9):.2f} |")
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.md and OUT.json")
    p.add_argument("--sizes", type=int, nargs="+", default=None,
                   help="frame sides, each with the batch of CASES, or 2 (default: CASES)")
    args = p.parse_args(argv)
    if not peak_memory_readable("training_memory.py"):
        return 1
    batches = dict(CASES)
    cases = CASES if args.sizes is None else tuple((s, batches.get(s, 2)) for s in args.sizes)
    record: dict[str, Any] = {"runs": [], "cases": []}
    for size, batch in cases:
        for key, measure_one, what in (("runs", measure_run, "a whole run"), ("cases", measure, "one pass")):
            row = measured_in_fresh_process(measure_one, (size, batch), "training_memory.py", f"{what} at {size} px")
            if row is None:
                return 1
            record[key].append(row)
            print(f"{size} px, batch {batch}, {what}: {row}", flush=True)
    command = shlex.join(["python", "benchmarks/training_memory.py", *(sys.argv[1:] if argv is None else argv)])
    record = {"command": command, "machine": machine(), **record}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
