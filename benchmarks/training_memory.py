"""Benchmark: the memory one training step of piga-train-model takes, against what its memory check counts.

``piga-train-model`` refuses, before it builds the model, a run whose parameters and batch do not fit in memory
(:mod:`piga.training.memory`): per parameter the weights, gradients, Adam's moments, an averaged copy and the backward
pass's temporaries; per window twice the activations that autograd saves (measured on torch's meta device,
:func:`piga.world.variants.activation_bytes`). This checks that count against the process's own memory.

For each (frame side, batch), in a fresh process with one torch thread: builds the fast preset's model for frames of
that side, then runs one forward and backward pass on random frames and reads how much the process's high-water mark
of resident memory rose over it (Linux's VmHWM, reset just before). The count for the same step is the gradients and
temporaries (8 bytes per parameter) and the batch's activations; the optimizer's moments and the averaged copy, which
the check also counts, are not allocated by one pass.

    python benchmarks/training_memory.py --out results/training_memory

Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any

from common import machine, machine_words, measured_in_fresh_process, out_prefix, peak_memory_readable, write_page
from piga.cli.common import ArgumentParser

#: (frame side, batch) measured by default: the default 64 px run, and larger frames where the check matters.
CASES = ((64, 32), (256, 2), (512, 2), (1024, 1))


def _peak_gib() -> float:
    fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    return int(fields["VmHWM"].split()[0]) * 1024 / 2**30


def measure(size: int, batch: int) -> dict[str, float]:
    """One step at frames of ``size`` px and a batch of ``batch``, in this process: measured and counted GiB."""
    from dataclasses import replace

    import torch

    from piga.training.memory import BACKWARD_BYTES_PER_PARAMETER, training_need
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
    counted = (parameters * (4 + BACKWARD_BYTES_PER_PARAMETER) + batched) / 2**30  # gradients, temporaries, activations
    return {"size": size, "batch": batch, "parameters": parameters, "activations_mib": activations / 2**20,
            "measured_gib": measured, "counted_gib": counted}


def markdown(record: dict[str, Any]) -> str:
    lines = ["# piga-train-model's memory check against one training step", "",
             f"From `{record['command']}` on {machine_words(record['machine'])}.", "",
             "The fast preset's model, one forward and backward pass in a fresh process with one torch thread. Measured: "
             "the rise of the process's high-water mark of resident memory over the pass (Linux's VmHWM). Counted: "
             "what `piga.training.memory` counts for the same pass (gradients and the backward pass's temporaries, 8 "
             "bytes per parameter, and twice the activations autograd saves per window, measured on torch's meta "
             "device); its check adds Adam's moments and the averaged copy, which one pass does not allocate.", "",
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
    rows = []
    for size, batch in cases:
        if (row := measured_in_fresh_process(measure, (size, batch), "training_memory.py", f"{size} px")) is None:
            return 1
        rows.append(row)
        print(f"{size} px, batch {batch}: {row}")
    command = shlex.join(["python", "benchmarks/training_memory.py", *(sys.argv[1:] if argv is None else argv)])
    record = {"command": command, "machine": machine(), "cases": rows}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
