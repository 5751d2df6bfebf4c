"""Benchmark: the baselines' agents on held-out evaluation episodes.

The baselines table (benchmarks/baselines.py) scores every agent on the episodes of seed 0 (the default of
:class:`piga.control.episodes.EpisodeConfig`: its starts and env seeds), the episodes on which piga's planner was
tuned (on the oracle) and the PlaNet-style model's settings were chosen. This scores the trained runs that are still
on this machine, and the oracle, on the episodes of :data:`HELD_OUT_SEED`, which no tuning and no other benchmark in
the repository uses, with everything else the table's (:func:`baselines.episode_config_for`: 200 steps, 20 episodes
at x1.0 and the sweep's count at x1.4, the first episode hanging down, success = upright held over the last 20
steps; piga and the oracle told x1.4, the baselines not), and sets each beside its record's seed-0 numbers.

    python benchmarks/held_out.py --out results/held_out                    # every run folder with a record
    python benchmarks/held_out.py --out results/held_out --jobs piga-n2-s0 oracle

A run's folder is ``RUNS/NAME`` (``--runs``, the baselines benchmark's ``results/baselines_runs``) with its
checkpoint; its seed-0 numbers are its record there (``RUNS/records/NAME.json``). Records whose folder is not on the
machine (trained elsewhere: checkpoints are not kept in the repository) are listed as not evaluated. Each evaluation
is one job of piga's job runner (:func:`piga.io.pool.run_recorded`, one torch thread), its record kept in
``OUT_runs/records/`` while its settings are unchanged, so the same command continues. Writes OUT.json and OUT.md.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from baselines import AGENTS, PRESETS, BenchConfig, evaluate, sweep_episodes
from common import change_cells, farm_main, machine, machine_words, out_prefix, write_page

from piga.io.checkpoint import CHECKPOINT
from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.cli.common import ArgumentParser, PigaError, seed_int

HELD_OUT_SEED = 4242
"""The held-out episodes' seed (starts drawn from ``default_rng(4242)``, env seeds 4242000 + e)."""
GRAVITY = 1.4
"""The changed gravity multiplier (the baselines table's x1.4 column)."""


@dataclass(frozen=True)
class Evaluation:
    """One run (or the oracle) to score on the held-out episodes."""

    name: str
    agent: str
    run: str | None
    seed: int


def evaluations(runs: Path, names: tuple[str, ...] | None, seed: int) -> tuple[list[Evaluation], list[str]]:
    """The run folders of ``runs`` that have a record and a checkpoint (only ``names``, if given), and the oracle;
    and the names of the records whose folder is not here."""
    specs = {path.stem: json.loads(path.read_text())["spec"] for path in (runs / "records").glob("*.json")}
    todo, missing = [], []
    for name, spec in sorted(specs.items(), key=lambda item: (AGENTS.index(item[1]["agent"]) if item[1]["agent"] in AGENTS
                                                              else len(AGENTS), item[1].get("sequences", 0),
                                                              item[1].get("seed", 0), item[0])):
        if names is not None and name not in names:
            continue
        agent = spec["agent"]
        if agent == "oracle":
            todo.append(Evaluation(name, agent, None, seed))
        elif (runs / name / CHECKPOINT).exists():
            todo.append(Evaluation(name, agent, str(runs / name), seed))
        else:
            missing.append(name)
    unknown = sorted(set(names or ()) - set(specs))
    if unknown:
        raise PigaError(f"no record in {runs / 'records'} for {', '.join(unknown)}")
    return todo, missing


def run_job(args: tuple[Evaluation, BenchConfig]) -> dict[str, Any]:
    """The run's summaries at x1.0 and x1.4 on the held-out episodes."""
    import torch

    torch.set_num_threads(1)
    job, cfg = args
    run = Path(job.run) if job.run else None
    return {"machine": machine(),
            "x1": evaluate(job.agent, run, cfg, seed=job.seed),
            "x1.4": evaluate(job.agent, run, cfg, GRAVITY, sweep_episodes(cfg, job.agent), seed=job.seed)}


def markdown(record: dict[str, Any]) -> str:
    """The page: a row per run, its seed-0 numbers (the table's) beside the held-out ones."""
    lines = ["# The baselines' agents on held-out episodes", "",
             f"Command: `{record['command']}`", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Each run of the baselines table (results/baselines.md) that is on this machine, scored on the episodes of "
             f"seed {record['seed']} instead of the table's seed 0, on which piga's planner and the PlaNet-style "
             "model's settings were tuned. Everything else is the table's: 200 steps, the first episode hanging "
             "down, success = upright held over the last 20 steps; piga and the oracle told x1.4, the baselines not. "
             "Cells: seed 0 (the run's record) → held out.", "",
             "| run | agent | sequences | training seed | success x1.0 (episodes) | mean return x1.0 | success x1.4 (episodes) |",
             "|---|---|---|---|---|---|---|"]
    for name, row in record["runs"].items():
        seed0 = row.get("seed0") or {}
        spec = seed0.get("spec", {})
        lines.append(f"| {name} | {spec.get('agent', '?')} | {spec.get('sequences') or ''} | {spec.get('seed', '')} | "
                     f"{change_cells(row.get('seed0'), row)} |")
    lines += ["", "## Summary", ""]
    for agent, s in record["summary"].items():
        lines.append(f"- {agent}: {s['runs']} run(s); success x1.0 over its runs {s['seed0_x1']:.0f}% on seed 0, "
                     f"{s['held_x1']:.0f}% held out; x1.4 {s['seed0_x14']:.0f}% and {s['held_x14']:.0f}%.")
    if record["not_here"]:
        lines += ["", "Not evaluated (their run folders are not on this machine; the checkpoints are not kept in the "
                      f"repository): {', '.join(record['not_here'])}."]
    return "\n".join(lines) + "\n"


def summary(rows: dict[str, dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per agent: its runs' mean success (percent) at x1.0 and x1.4, on seed 0 and held out."""
    out: dict[str, dict[str, float]] = {}
    for agent in AGENTS:
        if mine := [r for r in rows.values() if r["agent"] == agent and r.get("seed0")]:
            out[agent] = {"runs": len(mine),
                          **{key: 100 * sum(pick(r)["success_rate"] for r in mine) / len(mine) for key, pick in (
                              ("seed0_x1", lambda r: r["seed0"]["x1"]), ("held_x1", lambda r: r["x1"]),
                              ("seed0_x14", lambda r: r["seed0"]["x1.4"]), ("held_x14", lambda r: r["x1.4"]))}}
    return out


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=Path, default=Path("results/baselines_runs"),
                   help="the baselines benchmark's run folders and records (default %(default)s)")
    p.add_argument("--jobs", nargs="+", help="only these runs (record names, 'oracle' included; default: every one here)")
    p.add_argument("--seed", type=seed_int, default=HELD_OUT_SEED, help="the held-out episodes' seed (default %(default)s)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="budget", help="the baselines preset (default %(default)s)")
    p.add_argument("--out", type=out_prefix, default=Path("results/held_out"), help="output prefix (default %(default)s)")
    args = p.parse_args(argv)
    if args.seed == 0:
        p.error("--seed 0 gives the table's own episodes; a held-out seed is another")
    cfg = PRESETS[args.preset]
    todo, missing = evaluations(args.runs, tuple(args.jobs) if args.jobs else None, args.seed)
    if not todo:
        p.error(f"no run folder with a checkpoint and a record in {args.runs}")
    folder = args.out.parent / f"{args.out.name}_runs"
    folder.mkdir(parents=True, exist_ok=True)
    jobs = [RecordedJob(job.name, {"run": job.name, "agent": job.agent, "seed": job.seed, "preset": args.preset,
                                   "episodes": cfg.episodes, "gravity": GRAVITY}, (job, cfg)) for job in todo]
    done = run_recorded(run_job, jobs, JobRecords(folder / "records"), 1, progress=False)
    rows = {}
    for job in todo:
        seed0 = json.loads((args.runs / "records" / f"{job.name}.json").read_text())
        rows[job.name] = {"agent": job.agent, "x1": done[job.name]["x1"], "x1.4": done[job.name]["x1.4"],
                          "seed0": {"spec": seed0["spec"], "x1": seed0["control"], "x1.4": seed0["sweep"][f"{GRAVITY:g}"]}}
    record = {"command": " ".join(["python", "benchmarks/held_out.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "seed": args.seed, "runs": rows,
              "summary": summary(rows), "not_here": missing}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
