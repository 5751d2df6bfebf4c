"""The model-free runs' table on ``results/ddpg_tuning.md``, rendered from the committed records.

Every DDPG and SAC run of ``benchmarks/baselines.py`` keeps one record in
``results/baselines_runs/records/NAME.json`` (its spec, machine, learning curve and training time).
This script reads those records and writes the table between the page's two marker lines, so that
every number in it is the record's:

    python benchmarks/ddpg_tuning.py                 # rewrite the table in results/ddpg_tuning.md
    python benchmarks/ddpg_tuning.py --check         # exit 1 if the page's table is not the records'

The rest of the page (the tries that have no record, the probes) names its own commands.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from common import ALGO_LABELS, machine_words, signed

from agents.sb3.train import first_step_reaching
from piga.io.atomic import atomic_output
from piga.cli.common import ArgumentParser

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "results" / "baselines_runs" / "records"
PAGE = ROOT / "results" / "ddpg_tuning.md"
#: The lines between which the page holds the rendered table.
BEGIN = "<!-- the table below is rendered from the records by benchmarks/ddpg_tuning.py; do not edit it by hand -->"
END = "<!-- end of the rendered table -->"
#: A return at or above this is the learning curves' "swung up and held" mark (Gymnasium's pendulum).
SOLVED_RETURN = -200.0


def model_free_records(folder: Path = RECORDS) -> list[dict[str, Any]]:
    """The model-free records (DDPG, SAC and DrQ-v2: agent "ddpg"), in name order."""
    records = [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))]
    return [r for r in records if r["spec"]["agent"] in ("ddpg", "sac")]


def row(record: dict[str, Any]) -> str:
    """One run's line: what it observed, its steps, when it first reached the mark, its best and final
    evaluation returns (EvalCallback's), its training time and where it ran."""
    spec, metrics = record["spec"], record["metrics"]
    curve = metrics["learning_curve"]  # [{step, eval_mean_return, seconds}, ...] every eval_every steps
    first = first_step_reaching(curve, SOLVED_RETURN)
    best = max(curve, key=lambda p: p["eval_mean_return"])
    minutes = f"{metrics['train_seconds'] / 60:.1f}"
    if metrics.get("autoencoder_train_seconds"):
        minutes += f" (+ {metrics['autoencoder_train_seconds'] / 60:.1f} autoencoder)"
    m = record["machine"]
    where = f"{m['cpu']} {m['cpu_family_model']}, {m['torch_threads']} thread{'s' if m['torch_threads'] != 1 else ''}"
    return (f"| `{spec['name']}` | {ALGO_LABELS.get(metrics['algo'], metrics['algo'])} | {spec['obs']} | {spec['seed']} | {spec['steps'] // 1000}k | "
            f"{f'{first // 1000}k' if first is not None else 'never'} | {signed(best['eval_mean_return'])} ({best['step'] // 1000}k) | "
            f"{signed(curve[-1]['eval_mean_return'])} | {minutes} | {where} |")


def table(records: list[dict[str, Any]]) -> str:
    """The rendered block, markers included."""
    machines = sorted({machine_words(r["machine"]) for r in records})
    lines = [BEGIN, "",
             "| record | agent | observation | seed | env steps | first evaluation ≥ −200 | best evaluation (step) | "
             "final evaluation | training minutes | machine |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [row(r) for r in records]
    lines += ["", "Machines: " + "; ".join(machines) + ". The training minutes were measured beside other jobs.", "", END]
    return "\n".join(lines)


def render(page: str, records: list[dict[str, Any]]) -> str:
    """The page with its block replaced by the records' table.

    Raises:
        ValueError: the page lacks the markers.
    """
    start, end = page.find(BEGIN), page.find(END)
    if start < 0 or end < start:
        raise ValueError(f"the page has no block between {BEGIN!r} and {END!r}")
    return page[:start] + table(records) + page[end + len(END):]


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="only check that the page's table is the records' (exit 1 if not)")
    p.add_argument("--page", type=Path, default=PAGE, help="the page (default: results/ddpg_tuning.md)")
    p.add_argument("--records", type=Path, default=RECORDS, help="the records' folder (default: results/baselines_runs/records)")
    args = p.parse_args(argv)
    try:
        page = args.page.read_text()
        rendered = render(page, model_free_records(args.records))
    except (OSError, ValueError, KeyError) as exc:
        print(f"ddpg_tuning.py: error: {args.page}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    if args.check:
        if rendered != page:
            print(f"ddpg_tuning.py: error: {args.page}'s table is not the records'; run python benchmarks/ddpg_tuning.py",
                  file=sys.stderr)
            return 1
        return 0
    with atomic_output(args.page, overwrite=True) as tmp:
        tmp.write_text(rendered)
    print(f"wrote the table of {args.page}")
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
