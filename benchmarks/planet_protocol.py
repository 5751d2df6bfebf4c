"""Benchmark: the PlaNet-style model on PlaNet's own data protocol, beside the baselines table's random-data curve.

The baselines table trains the PlaNet-style model on files of N random-action sequences (N x 40 env steps). PlaNet
itself (Hafner et al., 2019) collects its data: a few random seed episodes, then, in turn, C training steps and one
episode run by its planner with Gaussian exploration noise (0.3 of the action bound). This runs that protocol
(``piga-baseline planet --iterative``, :mod:`agents.planet.iterative`) at the table's env-step budgets:

- seed episodes: the table's first ``--seed-sequences`` random sequences (25 x 40 = 1000 env steps: PlaNet's 5 seed
  episodes, of Pendulum-v1's 200 steps); the same collection, so the same first sequences as every table file;
- then (N - 25) x 40 / 200 rounds of one 200-step planner episode each (0.3 noise), so that the data total N x 40
  env steps, the table's at N;
- the table's 12000 optimiser steps in all: ``--first-steps`` (1000) on the seed episodes, the rest spread evenly
  over the rounds (C = 11000 / rounds, the remainder added to the first training): 115 a round at N = 500, near
  PlaNet's 100; 244 at 250; 733 at 100. Equal env steps and equal updates: only the data's source differs;
- scored as the table's runs are: 20 episodes at x1.0 and the sweep's 5 at x1.4 (not told), seed 0's starts.

    python benchmarks/planet_protocol.py --out results/planet_protocol                        # N = 100, 250, 500
    python benchmarks/planet_protocol.py --out results/planet_protocol --sequences 100 --seeds 0 1

Each (N, seed) is one job of piga's job runner (:func:`piga.io.pool.run_recorded`, one torch thread): its record,
``OUT_runs/records/NAME.json``, is kept while its settings are unchanged, and a stopped run continues exactly from
its checkpoint and ``collected.h5``, so the same command continues. The estimated cost is printed first. Writes
OUT.json and OUT.md, with the table's records at each N beside the protocol's.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from baselines import COST_S, PRESETS, BenchConfig, data_file, planet_scores, planet_table_runs, sweep_episodes
from common import farm_main, machine, machine_words, out_prefix, score_cells, write_page

from piga.cli.common import ArgumentParser, positive_int, seed_int
from piga.io.atomic import write_json
from piga.io.pool import JobRecords, RecordedJob, run_recorded


@dataclass(frozen=True)
class Plan:
    """The protocol at one env-step budget: seed sequences, rounds, and how the optimiser steps are spread."""

    sequences: int
    """N: the table's point, whose N x 40 env steps the protocol's data total."""
    seed_sequences: int
    rounds: int
    first_steps: int
    """Optimiser steps on the seed episodes before the first round."""
    round_steps: int
    """Optimiser steps after each round's episode (PlaNet's C)."""

    @property
    def total_steps(self) -> int:
        return self.first_steps + self.rounds * self.round_steps


def plan_for(sequences: int, cfg: BenchConfig, seed_sequences: int, first_steps: int) -> Plan:
    """The rounds (episodes of the control episodes' length) and step split that match the table's env steps and
    optimiser steps at ``sequences``.

    Raises:
        ValueError: the budget does not leave whole episodes after the seed sequences, or no steps for the rounds.
    """
    extra = (sequences - seed_sequences) * cfg.steps  # env steps to collect with the planner
    if extra <= 0 or extra % cfg.episode_steps:
        raise ValueError(f"{sequences} sequences of {cfg.steps} frames less {seed_sequences} seed sequences leave "
                         f"{extra} env steps: not a positive whole number of {cfg.episode_steps}-step episodes")
    if first_steps < 1:
        raise ValueError(f"--first-steps must be at least 1, got {first_steps}")
    rounds = extra // cfg.episode_steps
    round_steps = (cfg.planet_steps - first_steps) // rounds
    if round_steps < 1:
        raise ValueError(f"{cfg.planet_steps} optimiser steps less --first-steps {first_steps} leave none for "
                         f"{rounds} rounds")
    return Plan(sequences, seed_sequences, rounds, cfg.planet_steps - rounds * round_steps, round_steps)


@dataclass(frozen=True)
class Job:
    """The protocol at one budget with one training seed."""

    name: str
    plan: Plan
    seed: int
    cfg: BenchConfig
    folder: Path
    runs: Path
    workers: int = 1
    """Processes that play the scored episodes (the same episodes and scores as one; not part of the record's spec)."""


def train(job: Job) -> float:
    """Runs the protocol (continuing a stopped run) and returns its training seconds (the optimiser's: its planner
    episodes not counted)."""
    import torch

    from agents.planet.config import IterativeConfig, PlanetTrainConfig
    from agents.planet.iterative import train_planet_iterative
    from agents.planet.train import rssm_config_for
    from piga.data.schema import inspect_dataset

    torch.set_num_threads(1)
    data = data_file(job.cfg, job.runs, job.plan.seed_sequences)  # the table's collection: its first sequences
    run = job.folder / job.name
    metrics = run / "metrics.json"
    if not metrics.exists() or json.loads(metrics.read_text()).get("iterative", {}).get("rounds", 0) < job.plan.rounds:
        config = PlanetTrainConfig(steps=job.plan.first_steps, seed=job.seed, threads=1, device="cpu",
                                   **job.cfg.overrides.get("planet", {}))
        iterative = IterativeConfig(rounds=job.plan.rounds, episodes=1, steps_per_round=job.plan.round_steps,
                                    episode_steps=job.cfg.episode_steps)
        rssm = rssm_config_for(inspect_dataset(data), job.cfg.overrides.get("rssm"))
        resume = (run / "checkpoint.pt").exists()
        run.mkdir(parents=True, exist_ok=True)
        if not resume:  # the record piga-baseline planet writes, so that the run can be continued by hand too
            write_json(run / "config.json", {"kind": "planet", "data": str(data), "rssm": rssm.to_dict(),
                                             "train": config.to_dict(), "iterative": iterative.to_dict()})
        train_planet_iterative(data, run, config, iterative, rssm, resume=resume, progress=False,
                               command="benchmarks/planet_protocol.py")
    return float(json.loads(metrics.read_text())["train_seconds"])


def run_job(job: Job) -> dict[str, Any]:
    """Runs the protocol and scores the final model at x1.0 and x1.4."""
    seconds = train(job)
    run = job.folder / job.name
    metrics = json.loads((run / "metrics.json").read_text())
    return {"machine": machine(), "train_seconds": seconds, "steps": metrics.get("steps"),
            "iterative": metrics.get("iterative"),
            **planet_scores(run, job.cfg, workers=job.workers)}


def estimate_hours(plan: Plan, cfg: BenchConfig) -> float:
    """One core's hours for a job: its optimiser steps, its planner episodes and its 25 scored episodes."""
    seconds = (plan.total_steps * COST_S["planet_train_step"]
               + (plan.rounds * cfg.episode_steps + (cfg.planet_episode_count + sweep_episodes(cfg, "planet"))
                  * cfg.episode_steps) * COST_S["planet_plan_step"])
    return seconds / 3600


def _cells(run: dict[str, Any]) -> str:
    """The scores' three cells and the training minutes."""
    return f"{score_cells(run, x14_episodes=False)} | {run['train_seconds'] / 60:.0f}"


def _machines(record: dict[str, Any]) -> str:
    """The machine line: each protocol run's own, named with its runs where they differ (a run continued on another
    machine is named by the one that finished it, which wrote its record)."""
    by_machine: dict[str, list[str]] = {}
    for name, run in record["runs"].items():
        by_machine.setdefault(machine_words(run.get("machine", record["machine"])), []).append(name)
    if len(by_machine) <= 1:
        return f"Machine: {next(iter(by_machine), machine_words(record['machine']))}."
    return "Machines of the protocol's runs: " + "; ".join(f"{', '.join(names)}: {words}"
                                                           for words, names in by_machine.items()) + "."


def markdown(record: dict[str, Any]) -> str:
    lines = ["# The PlaNet-style model on PlaNet's data protocol", "",
             f"Command: `{record['command']}`", "",
             _machines(record), "",
             "Each protocol row collects its data as PlaNet does: the table's first "
             f"{record['seed_sequences']} random sequences as seed episodes, then one 200-step episode of the latent "
             "planner with exploration noise 0.3 (of the action bound) per round, until its data total the table's "
             "env steps at that size; its optimiser steps total the table's 12000. Both are scored on the same 20 "
             "episodes at x1.0 and 5 at x1.4 (not told). Training minutes count the optimiser's steps, not the protocol's "
             "planner episodes; they are wall-clock minutes of one-thread runs that shared the machine with other jobs "
             "(the protocol's at 500 ran at low priority beside them), so they compare costs only roughly.", "",
             "| env steps (table's sequences) | data | seed | rounds x steps per round | success x1.0 (episodes) | "
             "mean return x1.0 | success x1.4 | training min |",
             "|---|---|---|---|---|---|---|---|"]
    for n in record["sequences"]:
        for name, run in record["table"].get(str(n), {}).items():
            lines.append(f"| {n * record['frames']:,} ({n}) | random actions (the table's {name}) | {run['seed']} | "
                         f"- | {_cells(run)} |")
        for name, run in record["runs"].items():
            if run["plan"]["sequences"] == n:
                plan = run["plan"]
                lines.append(f"| {n * record['frames']:,} ({n}) | PlaNet's protocol ({name}) | {run['seed']} | "
                             f"{plan['rounds']} x {plan['round_steps']} (+{plan['first_steps']} first) | {_cells(run)} |")
    return "\n".join(lines) + "\n"


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequences", type=positive_int, nargs="+", default=[100, 250, 500],
                   help="the table's points whose env steps the protocol matches (default %(default)s)")
    p.add_argument("--seeds", type=seed_int, nargs="+", default=[0], help="training seeds (default 0)")
    p.add_argument("--seed-sequences", type=int, default=25,
                   help="random sequences that seed the protocol (default %(default)s: PlaNet's 5 seed episodes)")
    p.add_argument("--first-steps", type=int, default=1000,
                   help="optimiser steps on the seed sequences before the first round (default %(default)s)")
    p.add_argument("--runs", type=Path, default=Path("results/baselines_runs"),
                   help="the baselines benchmark's folder: its data files and records (default %(default)s)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="processes that play a job's scored episodes, one torch thread each (the same episodes and "
                   "scores as one; default %(default)s)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="budget", help="the baselines preset (default %(default)s)")
    p.add_argument("--out", type=out_prefix, default=Path("results/planet_protocol"), help="output prefix (default %(default)s)")
    args = p.parse_args(argv)
    cfg = PRESETS[args.preset]
    plans = {}
    for n in dict.fromkeys(args.sequences):
        if n not in cfg.planet_size_list:
            p.error(f"--sequences {n}: the {args.preset} preset's PlaNet-style sizes are "
                    f"{', '.join(map(str, cfg.planet_size_list))}")
        try:
            plans[n] = plan_for(n, cfg, args.seed_sequences, args.first_steps)
        except ValueError as exc:
            p.error(f"--sequences {n}: {exc}")
    folder = args.out.parent / f"{args.out.name}_runs"
    folder.mkdir(parents=True, exist_ok=True)
    jobs, records = [], JobRecords(folder / "records")
    for n, plan in plans.items():
        for seed in dict.fromkeys(args.seeds):
            name = f"protocol-n{n}-s{seed}"
            spec = {"plan": plan.__dict__, "seed": seed, "preset": args.preset, "overrides": cfg.overrides,
                    "episodes": cfg.planet_episode_count, "data_seed": cfg.data_seed}
            jobs.append(RecordedJob(name, spec, Job(name, plan, seed, cfg, folder, args.runs, args.workers)))
    todo = [job for job in jobs if records.kept(job.name, job.spec) is None]
    print(f"{len(todo)} of {len(jobs)} job(s) to run, about "
          f"{sum(estimate_hours(job.args.plan, cfg) for job in todo):.1f} h on one core (less where a run continues)",
          flush=True)
    done = run_recorded(run_job, jobs, records, 1, progress=False)
    record = {"command": " ".join(["python", "benchmarks/planet_protocol.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "sequences": list(plans), "frames": cfg.steps,
              "seed_sequences": args.seed_sequences,
              "table": {str(n): planet_table_runs(args.runs, n) for n in plans},
              "runs": {name: {**r["spec"], **{k: v for k, v in r.items() if k != "spec"}} for name, r in done.items()}}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
