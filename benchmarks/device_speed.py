"""Benchmark: how much faster does training run on a GPU than on the CPU?

On one pendulum file with ``/rewards`` (``piga-collect``'s), it times optimiser steps of two trainings on
each device asked for, in this process, one after the other:

- ``piga fast``: the world model of the fast preset, at its full horizon (L = 4 input frames, T_pred = 10),
  batches of 32 windows from the training DataLoader;
- ``PlaNet-style``: the RSSM of ``piga-baseline planet``'s defaults, batches of 16 chunks of 20 model steps;
- ``PlaNet sizes`` (only with ``--workloads``): the same at PlaNet's sizes, batches of 50 chunks
  (benchmarks/planet_faithful.py's ``planet-sizes``: what a CPU step costs at them).

A step is what the training loops do per batch: read and copy the batch, forward, backward, clip,
update, and read the loss back (and, for piga, its physical parameters). Checkpoints and evaluation are
not timed. Each repeat times ``--steps`` steps after ``--warmup`` untimed ones (cuDNN picks its kernels,
the allocator fills); the table gives the median over ``--repeats`` of the seconds per step, and the
speed-up of each device over the CPU (the ratio of the medians). The CPU runs ``--threads`` torch
threads (default 2: the 2-core machine the other results were measured on). ``--reference`` adds the
rows of an earlier record, e.g. the CPU measured on another machine, and the speed-up over them.

``--full gpu`` (or ``all``: every device timed) also trains the fast preset end to end on the GPU
(``TrainConfig(device=...)``, the step budget it sizes from the file, its evaluation and report), and
records the training time and the learned g and a with their errors (the truth is read only here, to
score): whether accuracy holds on the GPU, and what a whole identification costs there.

    piga-collect --out runs/default.h5 --seed 0                                                       # the data
    python benchmarks/device_speed.py --data runs/default.h5 --full all --out results/device_speed_cpu  # the CPU alone
    python benchmarks/device_speed.py --data runs/default.h5 --device cuda --full gpu \
        --reference results/device_speed_cpu.json --out results/device_speed

Writes ``OUT.json`` and ``OUT.md``. ``--device cuda`` on a machine without a GPU stops with one line.
Mixed precision is not measured: training runs in float32 on every device (on a GPU, PyTorch's
defaults apply: cuDNN may convolve in TF32).
"""

from __future__ import annotations

import argparse
import json
import shlex
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch

from common import machine, machine_words, out_prefix, write_page
from planet_faithful import VARIANTS
from piga.io.device import cuda_available, resolve_device
from piga.cli.common import ArgumentParser, positive_int, seed_int

#: The trainings that can be timed, in the order the page lists them; the first two unless ``--workloads`` says.
WORKLOADS = ("piga fast", "PlaNet-style", "PlaNet sizes")
#: The ``machine`` of the rows measured by the invocation that wrote the record.
THIS = "this machine"


def gpu_name(device: torch.device) -> str:
    """The device in words: the GPU's name, or "CPU"."""
    return torch.cuda.get_device_name(device) if device.type == "cuda" else "CPU"


def synchronize(device: torch.device) -> None:
    """Waits for the device's queued work, so that the clock reads finished steps."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def piga_steps(data: Path, device: torch.device, seed: int) -> Iterator[None]:
    """Training steps of the fast preset's model on ``data``, one per ``next``: the steps of
    :func:`piga.training.train.train` at the full horizon."""
    from torch.utils.data import DataLoader, RandomSampler

    from piga.data.schema import inspect_dataset
    from piga.data.windows import SequenceWindows
    from piga.training.train import model_config_for, preset_for
    from piga.world.model import PhysicsModel

    info = inspect_dataset(data)
    recipe = preset_for("fast", info)
    torch.manual_seed(seed)
    model = PhysicsModel(model_config_for(info, recipe.model)).to(device).train()
    optimizer = torch.optim.Adam(model.parameters(), lr=recipe.train.lr)
    windows = SequenceWindows(data, "train", window=model.config.window)
    cuda = device.type == "cuda"
    try:
        while True:
            loader = DataLoader(windows, batch_size=recipe.train.batch_size, drop_last=True, pin_memory=cuda,
                                sampler=RandomSampler(windows, generator=torch.Generator().manual_seed(seed)))
            for batch in loader:
                frames = batch.frames.to(device, non_blocking=cuda)  # uint8 (B, L+T, H, W)
                actions = batch.actions.to(device, non_blocking=cuda)  # (B, L+T, A)
                out = model(frames, actions)
                optimizer.zero_grad(set_to_none=True)
                out.loss.backward()
                torch.nn.utils.clip_grad_norm_(model.parameters(), recipe.train.grad_clip)
                optimizer.step()
                float(out.loss.detach())
                model.physical_parameters()
                yield
    finally:
        windows.close()


def planet_steps(data: Path, device: torch.device, seed: int, sizes: dict[str, Any] | None = None,
                 batch_size: int | None = None) -> Iterator[None]:
    """Training steps of ``piga-baseline planet``'s default model on ``data`` (``sizes``: RSSMConfig overrides,
    ``batch_size``: chunks per batch), one per ``next``: the steps of :func:`agents.planet.train.train_planet`."""
    from dataclasses import replace

    from agents.planet.config import PlanetTrainConfig
    from agents.planet.rssm import WorldModel, model_steps
    from agents.planet.train import optimizer_step, rssm_config_for
    from piga.data.schema import inspect_dataset, load_rewards, read_sequences

    info = inspect_dataset(data)
    config = PlanetTrainConfig() if batch_size is None else replace(PlanetTrainConfig(), batch_size=batch_size)
    frames, actions = (torch.from_numpy(x) for x in read_sequences(data, "train"))  # (N, T, H, W), (N, T, A)
    rewards = torch.from_numpy(load_rewards(data, "train"))  # (N, T)
    torch.manual_seed(seed)
    model = WorldModel(rssm_config_for(info, sizes)).to(device).train()
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, eps=config.adam_eps)
    rng, generator = np.random.default_rng(seed), torch.Generator().manual_seed(seed)
    repeat = model.config.action_repeat
    length = config.chunk_length * repeat  # env steps per chunk
    while True:
        rows = torch.from_numpy(rng.integers(len(frames), size=config.batch_size))[:, None]  # (B, 1)
        cols = torch.from_numpy(rng.integers(frames.shape[1] - length + 1, size=config.batch_size))[:, None] \
            + torch.arange(length)[None]  # (B, L·R)
        batch = model_steps(frames[rows, cols], actions[rows, cols], rewards[rows, cols], repeat)
        parts = model.loss(*(x.to(device) for x in batch), config, generator)
        optimizer_step(model, optimizer, parts.loss, config.grad_clip)
        float(parts.loss.detach())
        yield


#: PlaNet's sizes: benchmarks/planet_faithful.py's ``planet-sizes`` variant, its model and batch.
PLANET_SIZES = VARIANTS["planet-sizes"]
STEPS: dict[str, Callable[[Path, torch.device, int], Iterator[None]]] = {
    "piga fast": piga_steps, "PlaNet-style": planet_steps,
    "PlaNet sizes": lambda data, device, seed: planet_steps(data, device, seed, PLANET_SIZES["rssm"],
                                                            PLANET_SIZES["planet"]["batch_size"])}


def check_data(data: Path) -> None:
    """Refuses, before anything is timed, a file that either training would refuse.

    Raises:
        ValueError: naming the file and what is wrong (not a pendulum file, no /rewards, sequences too short).
    """
    from agents.planet.config import PlanetTrainConfig
    from agents.planet.train import check_planet_data, rssm_config_for
    from piga.data.schema import inspect_dataset
    from piga.training.train import check_trainable, model_config_for, preset_for

    info = inspect_dataset(data)
    if info.system != "pendulum":
        raise ValueError(f"{data}: holds {info.system} data; the benchmark times the pendulum's trainings")
    recipe = preset_for("fast", info)
    check_trainable(info, model_config_for(info, recipe.model), recipe.train)
    check_planet_data(info, PlanetTrainConfig(), rssm_config_for(info).action_repeat)


def seconds_per_step(workload: str, data: Path, device: torch.device, steps: int, warmup: int, seed: int) -> float:
    """Wall seconds per step of ``steps`` steps after ``warmup`` untimed ones, on a fresh model."""
    run = STEPS[workload](data, device, seed)
    try:
        for _ in range(warmup):
            next(run)
        synchronize(device)
        started = time.perf_counter()
        for _ in range(steps):
            next(run)
        synchronize(device)
        return (time.perf_counter() - started) / steps
    finally:
        run.close()


def measure(args: argparse.Namespace, devices: list[torch.device]) -> list[dict[str, Any]]:
    """One row per (workload, device): the seconds per step of each repeat and their median."""
    rows = []
    for workload in args.workloads:
        for device in devices:
            times = [seconds_per_step(workload, args.data, device, args.steps, args.warmup, args.seed + k)
                     for k in range(args.repeats)]
            rows.append({"workload": workload, "device": str(device), "device_name": gpu_name(device),
                         "threads": torch.get_num_threads(), "seconds_per_step": times,
                         "median": statistics.median(times), "machine": THIS})
            print(f"{workload} on {rows[-1]['device_name']}: {1000 * rows[-1]['median']:.1f} ms per step "
                  f"(median of {args.repeats})", flush=True)
    return rows


def speedups(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """For each workload, each GPU row over each CPU row: the ratio of their medians."""
    out = []
    for workload in WORKLOADS:
        mine = [r for r in rows if r["workload"] == workload]
        for gpu in (r for r in mine if not r["device"].startswith("cpu")):
            for cpu in (r for r in mine if r["device"].startswith("cpu")):
                out.append({"workload": workload, "gpu": gpu["device_name"], "cpu_machine": cpu["machine"],
                            "cpu_threads": cpu["threads"], "speedup": cpu["median"] / gpu["median"]})
    return out


def full_run(data: Path, device: torch.device, threads: int, seed: int) -> dict[str, Any]:
    """The fast preset trained end to end on ``device`` (in a temporary folder): its training seconds
    (``TrainState.elapsed``: the epochs and their checkpoints, not the report), steps, learned g and a with
    their relative errors, and the convergence check."""
    import tempfile

    from piga.training.report import write_run_report
    from piga.training.train import TrainConfig, train

    choice = "cuda" if device.type == "cuda" else "cpu"
    config = TrainConfig(device=choice, threads=threads, seed=seed)
    with tempfile.TemporaryDirectory(prefix="device_speed-") as work:
        model, state = train(data, Path(work) / "run", config, progress=False)
        metrics = write_run_report(model, state, data, Path(work) / "run")
    errors = metrics["parameter_errors"]
    row = {"device": str(device), "device_name": gpu_name(device), "threads": threads, "seconds": state.elapsed,
           "steps": state.step, "learned": {k: v["learned"] for k, v in errors.items()},
           "errors": {k: v["relative_error"] for k, v in errors.items()}, "converged": metrics.get("converged"),
           "machine": THIS}
    print(f"full fast-preset training on {row['device_name']}: {state.elapsed:.1f} s, {state.step} steps, "
          + ", ".join(f"{k} error {100 * e:.3f}%" for k, e in row["errors"].items()), flush=True)
    return row


def markdown(record: dict[str, Any]) -> str:
    """The results page."""
    settings = record["settings"]
    lines = ["# Training speed on a GPU against the CPU", "",
             f"Reproduce: `{record['command']}`. Each row times {settings['steps']} optimiser steps after "
             f"{settings['warmup']} untimed ones, {settings['repeats']} times, on a fresh model each time "
             "(`benchmarks/device_speed.py`: data, forward, backward, update; no checkpoints, no evaluation). "
             "Training runs in float32 on every device; mixed precision is not used.", "",
             f"Data: `{settings['data']}`.", "",
             f"Machine: {machine_words(record['machine'])}"
             + (f"; GPU: {record['machine']['gpu']}" if record["machine"].get("gpu") else "") + ".", ""]
    for ref in record.get("references", []):
        lines += [f"Reference `{ref['path']}`: {machine_words(ref['machine'])}.", ""]
    lines += ["| training | device | machine | CPU threads | ms per step (median) | each repeat (ms) |",
              "|---|---|---|---|---|---|"]
    for r in record["rows"]:
        repeats = ", ".join(f"{1000 * t:.1f}" for t in r["seconds_per_step"])
        lines.append(f"| {r['workload']} | {r['device_name']} | {r['machine']} | {r['threads']} | "
                     f"{1000 * r['median']:.1f} | {repeats} |")
    if record["speedups"]:
        lines += ["", "| training | GPU | over the CPU of | CPU threads | speed-up |", "|---|---|---|---|---|"]
        for s in record["speedups"]:
            lines.append(f"| {s['workload']} | {s['gpu']} | {s['cpu_machine']} | {s['cpu_threads']} | "
                         f"**{s['speedup']:.1f}x** |")
    if record.get("full"):
        lines += ["", "Whole fast-preset trainings (`--full`): the training time (`TrainState.elapsed`: the epochs and "
                  "their checkpoints) and the learned parameters' relative errors (the truth is read only to score).",
                  "", "| device | machine | CPU threads | steps | training seconds | g error | a error | converged |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in record["full"]:
            lines.append(f"| {r['device_name']} | {r['machine']} | {r['threads']} | {r['steps']} | {r['seconds']:.1f} | "
                         f"{100 * r['errors']['g']:.3f}% | {100 * r['errors']['a']:.3f}% | "
                         f"{'yes' if r['converged'] else 'no'} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, type=Path, help="a pendulum file with /rewards (piga-collect's)")
    p.add_argument("--out", required=True, type=out_prefix, help="output prefix: OUT.json and OUT.md")
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                   help="cuda: time the CPU and the GPU, and the speed-up; cpu: the CPU alone (default %(default)s)")
    p.add_argument("--steps", type=positive_int, default=30, help="timed steps per repeat (default %(default)s)")
    p.add_argument("--warmup", type=int, default=5, help="untimed steps first (default %(default)s)")
    p.add_argument("--repeats", type=positive_int, default=3, help="repeats; the table gives their median (default %(default)s)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (default %(default)s: the 2-core machine)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the models and batches (default %(default)s)")
    p.add_argument("--workloads", nargs="+", choices=list(STEPS), default=list(WORKLOADS[:2]),
                   help="the trainings to time (default: %(default)s)")
    p.add_argument("--full", choices=("none", "gpu", "all"), default="none",
                   help="also train the fast preset end to end: on the GPU (gpu, with --device cuda) or on every "
                        "device timed (all); default %(default)s")
    p.add_argument("--reference", type=Path, action="append", default=[],
                   help="an earlier OUT.json (e.g. the CPU of another machine): its rows join the table")
    args = p.parse_args(argv)
    if min(args.steps, args.repeats, args.threads) < 1 or args.warmup < 0:
        p.error("--steps, --repeats and --threads must be >= 1 and --warmup >= 0")
    if args.full == "gpu" and args.device != "cuda":
        p.error("--full gpu needs --device cuda (--full all trains on the CPU too)")
    if args.device == "cuda" and not cuda_available():
        print("device_speed.py: error: --device cuda: no CUDA device is available "
              "(torch.cuda.is_available() is False); run it on a machine with a GPU, or with --device cpu to time the CPU alone", file=sys.stderr)
        return 1
    devices = [torch.device("cpu")] + ([resolve_device("cuda")] if args.device == "cuda" else [])
    try:
        check_data(args.data)
    except (OSError, ValueError) as exc:
        print(f"device_speed.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    torch.set_num_threads(args.threads)
    rows = measure(args, devices)
    full_devices = devices if args.full == "all" else devices[1:] if args.full == "gpu" else []
    full = [full_run(args.data, device, args.threads, args.seed) for device in full_devices]
    here = machine() | ({"gpu": gpu_name(devices[-1])} if len(devices) > 1 else {})
    references = []
    for path in args.reference:
        earlier = json.loads(path.read_text())
        references.append({"path": str(path), "machine": earlier["machine"]})
        words = earlier["machine"].get("gpu") or earlier["machine"].get("cpu", str(path))
        rows += [{**r, "machine": f"{words} ({path.name})"} for r in earlier["rows"] if r["machine"] == THIS]
        full += [{**r, "machine": f"{words} ({path.name})"} for r in earlier.get("full", []) if r["machine"] == THIS]
    record = {"command": "python benchmarks/device_speed.py " + shlex.join(argv if argv is not None else sys.argv[1:]),
              "machine": here, "settings": {"data": str(args.data), "steps": args.steps, "warmup": args.warmup,
                                            "repeats": args.repeats, "threads": args.threads, "seed": args.seed, "workloads": args.workloads,
                                            "full": args.full},
              "references": references, "rows": rows, "speedups": speedups(rows), "full": full}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    page = markdown(record)
    write_page(args.out, record, page)
    print(page)
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
