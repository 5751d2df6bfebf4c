"""Benchmark: PlaNet-style runs scored with the weights their valid split selects, beside their last weights.

A PlaNet-style run (``piga-baseline planet``, the baselines table's and the protocol benchmark's) measures its loss on
the data file's valid split at every checkpoint and keeps the weights of the lowest one
(:func:`agents.planet.train.train_planet`). The tables score the last weights. This scores the selected ones on the
same episodes (20 at x1.0, 5 at x1.4, not told; the baselines preset's), so that a run whose control got worse late in
training (the table's 500-sequence seed 0 scored 90% at 6000 steps and 50% at 12000) can be set against a selection
made on held-out sequences, never on control episodes.

    python benchmarks/planet_select.py --runs results/baselines_runs/planet-n1000-s0 --out results/planet_select

Each run is one job (:func:`piga.io.pool.run_recorded`; its record ``OUT_runs/records/NAME.json`` is kept while the
run's selection is unchanged). The last weights' scores come from the run's record in its folder's ``records/``
(the baselines and protocol benchmarks' layout) where there is one. Writes OUT.json and OUT.md.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from baselines import PRESETS, BenchConfig, planet_scores, recorded_scores
from common import farm_main, machine, machine_words, out_prefix, score_cells, write_page

from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.cli.common import ArgumentParser


@dataclass(frozen=True)
class Job:
    """One run, scored with its selected weights."""

    run: Path
    folder: Path
    cfg: BenchConfig


def selection(run: Path) -> dict[str, Any]:
    """The run's selection as its metrics record it: the selected step and loss, the final step and valid loss.

    Raises:
        ValueError: the run is unfinished or measured no valid loss during training.
    """
    path = run / "metrics.json"
    if not path.exists():
        raise ValueError(f"{run}: no metrics.json (is its training finished?)")
    metrics = json.loads(path.read_text())
    if not metrics.get("best_valid"):
        raise ValueError(f"{run}: no valid loss was measured during its training, so it has no selected weights")
    curve = [r["valid_loss"] for r in metrics["learning_curve"] if "valid_loss" in r]
    return {"selected_step": metrics["best_valid"]["step"], "selected_loss": metrics["best_valid"]["loss"],
            "steps": metrics["steps"], "final_loss": curve[-1]}


def run_job(job: Job) -> dict[str, Any]:
    """Writes the selected weights' run folder and scores it at x1.0 and x1.4."""
    import torch

    from agents.planet.run import write_selected

    torch.set_num_threads(1)
    selected = job.folder / f"{job.run.name}-valid"
    write_selected(job.run, selected)
    return {"machine": machine(), **planet_scores(selected, job.cfg)}


def markdown(record: dict[str, Any]) -> str:
    lines = ["# PlaNet-style runs with the weights their valid split selects", "",
             f"Command: `{record['command']}`", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             "Each run kept, over its checkpoints, the weights of the lowest loss on its data file's valid split. Both "
             "rows of a run are scored on the same 20 episodes at x1.0 and 5 at x1.4 (not told).", "",
             "| run | weights | step (of) | valid loss | success x1.0 (episodes) | mean return x1.0 | success x1.4 |",
             "|---|---|---|---|---|---|---|"]
    for name, run in record["runs"].items():
        s = run["selection"]
        last, selected = (score_cells(scores, "not recorded", x14_episodes=False) for scores in (run["last"], run))
        lines.append(f"| {name} | last | {s['steps']:,} | {s['final_loss']:.4f} | {last} |")
        lines.append(f"| {name} | selected on the valid split | {s['selected_step']:,} ({s['steps']:,}) | "
                     f"{s['selected_loss']:.4f} | {selected} |")
    return "\n".join(lines) + "\n"


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=Path, nargs="+", required=True, help="finished PlaNet-style run folders")
    p.add_argument("--preset", choices=sorted(PRESETS), default="budget", help="the baselines preset (default %(default)s)")
    p.add_argument("--out", type=out_prefix, default=Path("results/planet_select"), help="output prefix (default %(default)s)")
    args = p.parse_args(argv)
    cfg = PRESETS[args.preset]
    folder = args.out.parent / f"{args.out.name}_runs"
    jobs, selections = [], {}
    for run in dict.fromkeys(args.runs):
        try:
            selections[run.name] = selection(run)
        except ValueError as exc:
            p.error(str(exc))
        spec = {"run": str(run), **selections[run.name], "preset": args.preset, "episodes": cfg.planet_episode_count}
        jobs.append(RecordedJob(run.name, spec, Job(run, folder, cfg)))
    if len(selections) < len(jobs):
        p.error("--runs: two runs share a folder name")
    folder.mkdir(parents=True, exist_ok=True)
    done = run_recorded(run_job, jobs, JobRecords(folder / "records"), 1, progress=False)
    record = {"command": " ".join(["python", "benchmarks/planet_select.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"],
              "runs": {name: {"selection": selections[name], "last": recorded_scores(Path(r["spec"]["run"])),
                              "x1": r["x1"], "x1.4": r["x1.4"]} for name, r in done.items()}}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
