"""Benchmark: the baselines table's runs again on a second data draw.

Every data file of the baselines table (benchmarks/baselines.py) is a nested subset of one random-action collection,
``data_seed`` 100, so its curve and its data ratio say nothing of how much another collection would move them. This
reruns chosen jobs of the table exactly as the table runs them (:func:`baselines.run_job`: the same recipes, training
seeds, episodes, sweep and goal images; the same record fields) on the subsets of another collection, and sets each
beside the table's record of the same job.

    python benchmarks/data_draw.py --out results/data_draw                       # the default jobs, data seed 200
    python benchmarks/data_draw.py --out results/data_draw --jobs piga-n2-s0 planet-n250-s0

The default jobs are piga at its smallest size (2 sequences, 3 training seeds: the cell most exposed to the draw)
and the PlaNet-style model where its curve crosses 80% and 95% (250, 500 and 1000 sequences, seed 0; about 2 h each
on one core).
Runs, data files and records go in ``OUT_runs/`` (the table's layout); a job whose record has the same settings is
not run again, so the same command continues. Writes OUT.json and OUT.md. The page also reads off each draw's
curve, and both draws' runs pooled, the data each agent needs at the table's success thresholds and their ratio
(:func:`draw_needs`, as the table reads its own).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from baselines import PRESETS, RATIO_THRESHOLDS, TABLE_GRAVITY, jobs_for, need_cell, ratio_cell, recorded_scores, run_all
from common import farm_main, machine_words, out_prefix, score_cells, write_page
from efficiency import Point, data_ratio
from piga.cli.common import ArgumentParser

DATA_SEED = 200
"""The second collection's seed (the table's is ``BenchConfig.data_seed``, 100)."""
JOBS = ("piga-n2-s0", "piga-n2-s1", "piga-n2-s2", "planet-n250-s0", "planet-n500-s0", "planet-n1000-s0")
"""The table's jobs run again by default."""


DRAWS = ("table", "second", "both")
"""The curves whose needs the page reads: the table's draw, the second draw, and both draws' runs pooled."""


def _points(rows: dict[str, dict[str, Any]], agent: str, draw: str) -> list[Point]:
    """``agent``'s curve on ``draw`` (:data:`DRAWS`) from the page's rows: at each size, each run's (successes,
    episodes) at x1.0. A size enters the pooled curve only where both draws have a run of it."""
    runs: dict[int, dict[str, list[dict[str, Any]]]] = {}
    for row in rows.values():
        if row["agent"] == agent:
            at = runs.setdefault(row["sequences"], {"table": [], "second": []})
            if row["table"] is not None:
                at["table"].append(row["table"]["x1"])
            at["second"].append(row["x1"])
    points = []
    for size, at in sorted(runs.items()):
        chosen = at["table"] + at["second"] if draw == "both" else at[draw]
        if chosen and (draw != "both" or (at["table"] and at["second"])):
            points.append(Point(size, tuple((round(s["success_rate"] * s["episodes"]), s["episodes"]) for s in chosen)))
    return points


def draw_needs(rows: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """At each of the table's thresholds and on each curve of :data:`DRAWS`, the sequences the PlaNet-style model
    and piga need and their ratio (:func:`efficiency.data_ratio`, read on this page's jobs only); none for a curve
    on which an agent has no run."""
    out = []
    for threshold in RATIO_THRESHOLDS:
        for draw in DRAWS:
            planet, piga = _points(rows, "planet", draw), _points(rows, "piga", draw)
            if planet and piga:
                out.append({"draw": draw, **data_ratio(planet, piga, threshold)})
    return out


def _listed(sizes: list[int]) -> str:
    """Sizes in words: "250, 500 and 1000"."""
    return ", ".join(map(str, sizes[:-1])) + (" and " if len(sizes) > 1 else "") + str(sizes[-1])


def needs_lines(record: dict[str, Any]) -> list[str]:
    """The page's section on the data each agent needs, per draw and pooled."""
    if not record["needs"]:
        return []
    sizes = {agent: sorted({row["sequences"] for row in record["jobs"].values() if row["agent"] == agent})
             for agent in ("piga", "planet")}
    label = {"table": f"{record['table_data_seed']} (the table)", "second": f"{record['data_seed']}", "both": "both"}
    lines = ["## Data needed at equal success, on each draw", "",
             "Read as the table reads its own (results/baselines.md, `benchmarks/efficiency.py`): where each agent's "
             "curve of success at x1.0 first reaches a rate, interpolated in log(sequences) between its sizes, and the "
             f"PlaNet-style model's need over piga's; 95% intervals over {record['needs'][0]['draws']:,} bootstrap "
             "draws that resample each size's runs, then their episodes. The curves hold this page's jobs only "
             f"(the PlaNet-style model at {_listed(sizes['planet'])} sequences, piga at {_listed(sizes['piga'])}), "
             "so a need past the largest size reads \"more than\" it and one reached at the smallest \"at most\" it. "
             "A ratio with such a need is a bound, and \"undefined\" where its draws bound it both ways (its interval "
             "is then of ratios of bounds). \"both\" pools the two draws' runs at each size that both have, as runs of "
             "one sample.", "",
             "| success | data seed | piga needs (sequences) | PlaNet-style needs (sequences) | PlaNet-style / piga |",
             "|---|---|---|---|---|"]
    for row in record["needs"]:
        lines.append(f"| {100 * row['threshold']:.0f}% | {label[row['draw']]} | {need_cell(row['denominator'])} | "
                     f"{need_cell(row['numerator'])} | {ratio_cell(row['ratio'])} |")
    return lines + [""]


def _machine_lines(record: dict[str, Any]) -> list[str]:
    """The machine the jobs ran on, or each machine and its jobs where they ran on several."""
    jobs: dict[str, list[str]] = {}
    for name, machine in record.get("machines", {"": record["machine"]}).items():
        jobs.setdefault(machine_words(machine), []).append(name)
    if len(jobs) == 1:
        return [f"Machine: {next(iter(jobs))}."]
    return ["Machines:", "", *(f"- {words}: {', '.join(names)}" for words, names in jobs.items())]


def markdown(record: dict[str, Any]) -> str:
    """The page: a row per job and draw, the table's first."""
    lines = ["# The baselines table's runs on a second data draw", "",
             f"Command: `{record['command']}`", "",
             *_machine_lines(record), "",
             f"Each job runs exactly as in the baselines table (results/baselines.md), on the nested subsets of a "
             f"second random-action collection (data seed {record['data_seed']}) instead of the table's (seed "
             f"{record['table_data_seed']}). The episodes are the table's; piga is told x{TABLE_GRAVITY:g}, the "
             "PlaNet-style model not.", "",
             "| job | data seed | success x1.0 (episodes) | mean return x1.0 | success x1.4 (episodes) |",
             "|---|---|---|---|---|"]
    for name, row in record["jobs"].items():
        lines.append(f"| {name} | {record['table_data_seed']} (the table) | {score_cells(row['table'])} |")
        lines.append(f"| {name} | {record['data_seed']} | {score_cells(row)} |")
    return "\n".join(lines + ["", *needs_lines(record)]).rstrip("\n") + "\n"


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--jobs", nargs="+", default=list(JOBS), help="the table's job names (default: %(default)s)")
    p.add_argument("--data-seed", type=int, default=DATA_SEED, help="the second collection's seed (default %(default)s)")
    p.add_argument("--table", type=Path, default=Path("results/baselines_runs"),
                   help="the table's runs folder, for its records (default %(default)s)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="budget", help="the baselines preset (default %(default)s)")
    p.add_argument("--out", type=out_prefix, default=Path("results/data_draw"), help="output prefix (default %(default)s)")
    args = p.parse_args(argv)
    table_cfg = PRESETS[args.preset]
    if args.data_seed == table_cfg.data_seed:
        p.error(f"--data-seed {args.data_seed} is the table's own draw; a second draw is another seed")
    cfg = replace(table_cfg, data_seed=args.data_seed, workers=1)
    known = {job.name: job for job in jobs_for(cfg) if job.agent in ("piga", "planet")}
    unknown = [name for name in args.jobs if name not in known]
    if unknown:
        p.error(f"--jobs: not a piga or PlaNet-style job of the {args.preset} table: {', '.join(unknown)}")
    folder = args.out.parent / f"{args.out.name}_runs"
    folder.mkdir(parents=True, exist_ok=True)
    names = list(dict.fromkeys(args.jobs))
    records = run_all(cfg, folder, only=tuple(names))  # the table's own runner: kept records, data files, jobs
    rows = {name: {"agent": known[name].agent, "sequences": known[name].sequences,
                   "table": recorded_scores(args.table / name), "x1": records[name]["control"],
                   "x1.4": records[name]["sweep"][f"{TABLE_GRAVITY:g}"], "train_seconds": records[name]["train_seconds"]}
            for name in names}
    record = {"command": " ".join(["python", "benchmarks/data_draw.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": records[names[0]]["machine"], "machines": {name: records[name]["machine"] for name in names},
              "data_seed": args.data_seed,
              "table_data_seed": table_cfg.data_seed, "jobs": rows, "needs": draw_needs(rows)}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
