"""The published per-seed learning curves of one method on one DMC task, from the score files that DreamerV3's
authors publish for it and its baselines (github.com/danijar/dreamerv3, ``scores/dmc_vision-METHOD.json.gz``).

    git clone https://github.com/danijar/dreamerv3 && git -C dreamerv3 checkout e3f0224
    python benchmarks/published_scores.py dreamerv3/scores/dmc_vision-drqv2.json.gz --task dmc_pendulum_swingup \
        --source "github.com/danijar/dreamerv3 scores/dmc_vision-drqv2.json.gz (commit e3f0224)" \
        --out results/published/dmc_vision-drqv2-pendulum_swingup.json

Writes OUT (JSON): the source, the task, the method, and per seed the curve as published (``xs``: environment steps
of 0.02 s, DMC's control step, so frames at action repeat 1; ``ys``: the evaluation score, 0-1000). The file is
small, so that pages can compare with the curve without the download.
"""

from __future__ import annotations

import gzip
import json
import sys
import zlib
from pathlib import Path

from common import check_record, is_number, out_prefix

from piga.io.atomic import write_json
from piga.cli.common import ArgumentParser


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scores", type=Path, help="a score file: a gzipped JSON list of {task, method, seed, xs, ys}")
    p.add_argument("--task", required=True, help="the task's name in the file, e.g. dmc_pendulum_swingup")
    p.add_argument("--source", required=True, help="where the file came from, for the record")
    p.add_argument("--out", type=out_prefix, required=True, help="the JSON to write")
    p.add_argument("--overwrite", action="store_true", help="replace an existing OUT")
    args = p.parse_args(argv)
    try:
        with gzip.open(args.scores, "rt") as f:
            listed = json.load(f)
        check_record(args.scores, isinstance(listed, list) and all(isinstance(r, dict) and isinstance(r.get("task"), str)
                                                                   for r in listed),
                     "must be a list of curves, each an object with a 'task'")
        runs = [r for r in listed if r["task"] == args.task]
        for r in runs:
            check_record(args.scores, isinstance(r.get("method"), str) and isinstance(r.get("seed"), int)
                         and isinstance(r.get("xs"), list) and isinstance(r.get("ys"), list) and len(r["xs"]) == len(r["ys"]) > 0
                         and all(is_number(v) for v in r["xs"] + r["ys"]),
                         f"each curve of {args.task} must give its method, its seed (an integer) and xs and ys (lists of "
                         f"as many numbers); got {str(r)[:80]}")
        if not runs:
            raise ValueError(f"{args.scores} has no curve of task {args.task!r}")
        methods = sorted({r["method"] for r in runs})
        record = {"source": args.source, "task": args.task, "method": ", ".join(methods), "x_unit": "environment steps of 0.02 s",
                  "seeds": [{"seed": r["seed"], "xs": r["xs"], "ys": r["ys"]} for r in sorted(runs, key=lambda r: r["seed"])]}
        write_json(args.out, record, overwrite=args.overwrite)
    except (OSError, EOFError, zlib.error, ValueError, KeyError, TypeError) as exc:  # (a gzip cut short or damaged)
        print(f"published_scores.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    print(f"wrote {args.out}: {len(runs)} seeds of {record['method']} on {args.task}")
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
