"""Benchmark: the torque arrow at evaluation as at training.

Every agent of the baselines table trains on frames that show Gymnasium's torque arrow (``piga-collect`` draws it,
as Gymnasium does) and is scored on frames without it (:attr:`piga.control.episodes.EpisodeConfig.torque_arrow`,
off: a real camera sees no arrow). piga's encoder is blind to the arrow by construction (its pivot gate), but a
learned model that never saw an arrow-free frame meets one first at evaluation. This scores trained runs on the
table's own episodes (seed 0: 20 at x1.0, the sweep's count at x1.4; piga told x1.4, the baselines not) with the
arrow shown, everything else the table's, and sets each beside its record's arrow-free numbers.

    python benchmarks/arrow.py --out results/arrow \\
        --runs results/baselines_runs/planet-n250-s0 results/baselines_runs/piga-n10-s0

A run's arrow-free numbers are its benchmark record, ``records/NAME.json`` beside its folder (the baselines and
PlaNet-variant benchmarks' layout). Each run is one job of piga's job runner (:func:`piga.io.pool.run_recorded`, one
torch thread), its record kept in ``OUT_runs/records/`` while the run's checkpoint is unchanged, so the same command
continues. Writes OUT.json and OUT.md.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from baselines import PRESETS, TABLE_GRAVITY, BenchConfig, evaluate, recorded_scores, sweep_episodes
from common import change_cells, farm_main, machine, machine_words, out_prefix, write_page

from piga.io.checkpoint import CHECKPOINT, RunKind, run_kind
from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.cli.common import ArgumentParser

AGENTS = {RunKind.PIGA: "piga", RunKind.PLANET: "planet"}
"""The run kinds scored here, by the agent name :func:`baselines.evaluate` takes. DDPG runs are left out: the
SB3 agents' records are scored at x1.0 only, and their folders are not kept."""


@dataclass(frozen=True)
class Job:
    """One run, scored with the arrow shown."""

    run: Path
    agent: str
    cfg: BenchConfig


def run_job(job: Job) -> dict[str, Any]:
    """The run's summaries at x1.0 and x1.4 on the table's episodes, arrow shown."""
    import torch

    torch.set_num_threads(1)
    return {"machine": machine(),
            "x1": evaluate(job.agent, job.run, job.cfg, torque_arrow=True),
            "x1.4": evaluate(job.agent, job.run, job.cfg, TABLE_GRAVITY, sweep_episodes(job.cfg, job.agent),
                             torque_arrow=True)}


def markdown(record: dict[str, Any]) -> str:
    """The page: a row per run, arrow hidden (its record) → arrow shown."""
    lines = ["# The torque arrow at evaluation as at training", "",
             f"Command: `{record['command']}`", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             "Every run here trained on frames with Gymnasium's torque arrow; the tables score them without it. Each "
             "is scored again on the table's own episodes (seed 0: 20 at x1.0; 5 at x1.4, piga told, the baselines "
             "not) with the arrow shown, everything else the same. Cells: arrow hidden (the run's record) → arrow "
             "shown.", "",
             "| run | agent | success x1.0 (episodes) | mean return x1.0 | success x1.4 (episodes) |",
             "|---|---|---|---|---|"]
    for name, row in record["runs"].items():
        lines.append(f"| {name} | {row['agent']} | {change_cells(row['hidden'], row)} |")
    return "\n".join(lines) + "\n"


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=Path, nargs="+", required=True,
                   help="trained piga or PlaNet-style run folders, each with a benchmark record in records/ beside it")
    p.add_argument("--preset", choices=sorted(PRESETS), default="budget", help="the baselines preset (default %(default)s)")
    p.add_argument("--out", type=out_prefix, default=Path("results/arrow"), help="output prefix (default %(default)s)")
    args = p.parse_args(argv)
    cfg = PRESETS[args.preset]
    runs = list(dict.fromkeys(args.runs))
    if len({run.name for run in runs}) < len(runs):
        p.error("--runs: two runs share a folder name")
    jobs = []
    for run in runs:
        if not (run / CHECKPOINT).exists():
            p.error(f"--runs: {run} holds no {CHECKPOINT}")
        kind = run_kind(run)
        if kind not in AGENTS:
            p.error(f"--runs: {run} is a {kind.value} run; only piga and PlaNet-style runs are scored here")
        spec = {"run": str(run), "agent": AGENTS[kind], "preset": args.preset, "episodes": cfg.episodes,
                "gravity": TABLE_GRAVITY, "checkpoint_mtime": (run / CHECKPOINT).stat().st_mtime}
        jobs.append(RecordedJob(run.name, spec, Job(run, AGENTS[kind], cfg)))
    folder = args.out.parent / f"{args.out.name}_runs"
    folder.mkdir(parents=True, exist_ok=True)
    done = run_recorded(run_job, jobs, JobRecords(folder / "records"), 1, progress=False)
    record = {"command": " ".join(["python", "benchmarks/arrow.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"],
              "runs": {name: {"agent": r["spec"]["agent"], "hidden": recorded_scores(Path(r["spec"]["run"])),
                              "x1": r["x1"], "x1.4": r["x1.4"]} for name, r in done.items()}}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
