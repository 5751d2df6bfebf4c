"""Benchmark: the PlaNet-style model with PlaNet's reward settings, against the baselines table's at one data size.

The baselines table's PlaNet-style model (benchmarks/baselines.py) departs from PlaNet in two reward settings
(docs/commands/baseline.md, "Where the PlaNet-style model departs from PlaNet"):

- its reward head reads the latent state of the frame *before* a model step's actions (``reward_alignment="frame"``),
  whose target it cannot fully see (the actions' cost, and at action repeat 2 the second step's reward); PlaNet's
  reads the state the actions lead to (``"transition"``);
- its reward term has weight 1; the official PlaNet code weighs it 10 (``reward_scale``).

Each variant here (:data:`VARIANTS`) trains the model again with one set of those settings, on the very data, schedule
(12000 steps), seeds and episodes of the table's runs at ``--sequences`` (its data file is the baselines benchmark's:
:func:`baselines.data_file`), and is scored like them: 20 episodes at x1.0 and the sweep's 5 at x1.4 (not told), the
same starts and success rule. The page sets each beside the table's own runs at that size (their records in
``--runs``), so the difference is the settings' alone.

    python benchmarks/planet_faithful.py --out results/planet_faithful                 # 500 sequences, seed 0
    python benchmarks/planet_faithful.py --out results/planet_faithful --seeds 0 1

Each variant and seed is one job of piga's job runner (:func:`piga.io.pool.run_recorded`, one torch thread, about
1.5-2.5 h on one core of a 2-core CPU); its record, ``OUT_runs/records/NAME.json``, is kept while its settings are
unchanged, and a stopped training continues from its checkpoint, so the same command continues. Writes OUT.json
and OUT.md.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal, get_args

from baselines import PRESETS, BenchConfig, data_file, planet_scores, planet_table_runs, train_planet_run
from common import farm_main, machine, machine_words, out_prefix, write_page

from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.cli.common import ArgumentParser, positive_int, seed_int

Variant = Literal["planet-reward", "planet-sizes"]
#: Each variant's settings: overrides of :class:`agents.planet.config.RSSMConfig` and of
#: :class:`agents.planet.config.PlanetTrainConfig`, and the page's words for them.
VARIANTS: dict[str, dict[str, Any]] = {
    "planet-reward": {"rssm": {"reward_alignment": "transition"}, "planet": {"reward_scale": 10.0},
                      "words": "PlaNet's reward: the head reads the state after the actions (`transition`), weight 10"},
    "planet-sizes": {"rssm": {"deter_size": 200, "stoch_size": 30, "hidden_size": 200, "depth": 32, "reward_layers": 3,
                              "reward_units": 300},
                     "planet": {"batch_size": 50},
                     "words": "PlaNet's sizes: GRU 200, stochastic state 30, MLPs 200, convs from 32 channels, reward head "
                              "3 x 300, batches of 50 chunks (of 20 model steps: the data's 40 frames, not PlaNet's 50)"},
}


@dataclass(frozen=True)
class Job:
    """One variant trained with one seed."""

    name: str
    variant: str
    seed: int
    sequences: int
    cfg: BenchConfig
    folder: Path
    runs: Path
    device: str = "cpu"
    """Where to train (not part of the recipe: a run continues on any device)."""
    workers: int = 1
    """Processes the evaluation episodes are split over (the same episodes and scores as one)."""


def variant_config(base: BenchConfig, variant: str) -> BenchConfig:
    """The baselines preset with the variant's PlaNet-style settings over its own."""
    settings = VARIANTS[variant]
    overrides = {key: {**base.overrides.get(key, {}), **settings.get(key, {})} for key in ("planet", "rssm")}
    return replace(base, overrides={**base.overrides, **overrides})


def train_job(job: Job) -> float:
    """Trains the variant (continuing a stopped run); returns its training seconds."""
    import torch

    torch.set_num_threads(1)
    data = data_file(job.cfg, job.runs, job.sequences)  # the table's file at this size (collected once, in --runs)
    return train_planet_run(data, job.folder / job.name, job.seed, variant_config(job.cfg, job.variant), job.sequences,
                            job.device)


def run_job(job: Job) -> dict[str, Any]:
    """Trains the variant (continuing a stopped run) and scores it at x1.0 and x1.4."""
    seconds = train_job(job)
    cfg = variant_config(job.cfg, job.variant)
    run = job.folder / job.name
    metrics = json.loads((run / "metrics.json").read_text())
    return {"machine": machine(), "train_seconds": seconds, "train_device": metrics.get("device"),
            "train_device_name": metrics.get("device_name"),
            **planet_scores(run, cfg, job.workers),
            "valid": metrics.get("valid"), "open_loop": metrics.get("open_loop")}


def _device(run: dict[str, Any]) -> str:
    """" (on DEVICE)" for a run trained off the CPU, naming the GPU where its metrics do."""
    device = run.get("train_device") or "cpu"
    return "" if device == "cpu" else f" (on {run.get('train_device_name') or device})"


def markdown(record: dict[str, Any]) -> str:
    n = record["sequences"]
    lines = ["# The PlaNet-style model with PlaNet's reward settings and sizes", "",
             f"Command: `{record['command']}`", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Data, schedule and episodes are the baselines table's at {n} random-action sequences (results/baselines.md): "
             "the same file, 12000 training steps, 20 episodes at x1.0 and 5 at x1.4 (not told), the same starts and "
             "success rule. Only the settings of each row differ. Training minutes are one CPU thread's unless the "
             "row names the device it trained on.", "",
             "| row | settings | seed | success x1.0 (episodes) | mean return x1.0 | success x1.4 | training min |",
             "|---|---|---|---|---|---|---|"]
    for name, run in record["table"].items():
        lines.append(f"| the table's ({name}) | the benchmark's: the head reads the state before the actions "
                     f"(`frame`), weight 1 | {run['seed']} | {100 * run['x1']['success_rate']:.0f}% ({run['x1']['episodes']}) | "
                     f"{run['x1']['mean_return']:.1f} | {100 * run['x1.4']['success_rate']:.0f}% | "
                     f"{run['train_seconds'] / 60:.0f} |")
    for name, run in record["runs"].items():
        lines.append(f"| {run['variant']} ({name}) | {VARIANTS[run['variant']]['words']} | {run['seed']} | "
                     f"{100 * run['x1']['success_rate']:.0f}% ({run['x1']['episodes']}) | {run['x1']['mean_return']:.1f} | "
                     f"{100 * run['x1.4']['success_rate']:.0f}% | {run['train_seconds'] / 60:.0f}{_device(run)} |")
    return "\n".join(lines) + "\n"


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequences", type=positive_int, default=500, help="the table's data size to compare at (default %(default)s)")
    p.add_argument("--seeds", type=seed_int, nargs="+", default=[0], help="training seeds (default 0)")
    p.add_argument("--variants", nargs="+", choices=get_args(Variant), default=list(get_args(Variant)),
                   help="the variants to train (default: all)")
    p.add_argument("--runs", type=Path, default=Path("results/baselines_runs"),
                   help="the baselines benchmark's folder: its data files and records (default %(default)s)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="budget", help="the baselines preset (default %(default)s)")
    p.add_argument("--out", type=out_prefix, default=Path("results/planet_faithful"), help="output prefix (default %(default)s)")
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu",
                   help="where to train (default %(default)s; a run continues on either)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="processes the evaluation episodes are split over (default %(default)s; the same scores)")
    p.add_argument("--train-only", action="store_true",
                   help="train (or continue) the runs and stop: no evaluation, no record, no page")
    args = p.parse_args(argv)
    cfg = PRESETS[args.preset]
    if args.sequences not in cfg.planet_size_list:
        p.error(f"--sequences {args.sequences}: the {args.preset} preset's PlaNet-style sizes are "
                f"{', '.join(map(str, cfg.planet_size_list))}")
    folder = args.out.parent / f"{args.out.name}_runs"
    folder.mkdir(parents=True, exist_ok=True)
    jobs = []
    for variant in args.variants:
        for seed in dict.fromkeys(args.seeds):
            name = f"{variant}-n{args.sequences}-s{seed}"
            spec = {"variant": variant, "seed": seed, "sequences": args.sequences, "preset": args.preset,
                    "overrides": variant_config(cfg, variant).overrides, "steps": cfg.planet_steps,
                    "episodes": cfg.planet_episode_count, "data_seed": cfg.data_seed}
            jobs.append(RecordedJob(name, spec, Job(name, variant, seed, args.sequences, cfg, folder, args.runs,
                                                    args.device, args.workers)))
    if args.train_only:
        for job in jobs:
            print(f"{job.name}: trained, {train_job(job.args) / 60:.1f} min", flush=True)
        return 0
    done = run_recorded(run_job, jobs, JobRecords(folder / "records"), 1, progress=False)
    record = {"command": " ".join(["python", "benchmarks/planet_faithful.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "sequences": args.sequences,
              "table": planet_table_runs(args.runs, args.sequences),
              "runs": {name: {**r["spec"], **{k: v for k, v in r.items() if k != "spec"}} for name, r in done.items()}}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
