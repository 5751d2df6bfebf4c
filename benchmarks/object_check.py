"""Benchmark: the lost-object check (:mod:`piga.evaluation.objects`) on finished scene runs.

For every run folder given (a ``piga-train-model`` run of a scene, whose ``config.json`` names its data
file, or ``RUN=DATA`` to name it), it reconstructs the test split's single frames and prints the ratio of
the residual's peak to the moving content's peak, against the threshold. It trains nothing: it shows where
the threshold sits between runs that found every object and runs that lost one, for example the
robustness benchmark's runs, and the dark-background gravity run at seed 0 without the retry that
finds its lost ball (``piga-train-model`` trains again with the next seed when the check fails)::

    piga-train-model runs/robustness/data/gravity-background-401a4d.h5 --seed-retries 0 --threads 1 \
        --out runs/object_check/gravity-background-401a4d-seed0-no-retry     # exits 1: a ball lost
    python benchmarks/object_check.py runs/robustness/runs/*-seed0 \
        runs/object_check/gravity-background-401a4d-seed0-no-retry --out results/object_check

Writes OUT.json and OUT.md.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import torch

from common import machine, machine_words
from piga.data.schema import read_sequences
from piga.evaluation.objects import LOST_RATIO, check_objects
from piga.io.atomic import atomic_output, write_json
from piga.io.runs import load_model


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("runs", nargs="+", help="run folders (RUN, or RUN=DATA when its config.json does not name the file)")
    p.add_argument("--out", default="results/object_check", help="output prefix (default %(default)s)")
    args = p.parse_args()
    torch.set_num_threads(1)
    rows = []
    for spec in args.runs:
        run, _, data = spec.partition("=")
        model, _ = load_model(run)
        if model.config.coord_dim != 2:
            continue  # not a scene of objects
        if not data:
            data = json.loads((Path(run) / "config.json").read_text())["data"]
        check = check_objects(model, read_sequences(data, "test")[0])
        rows.append({"run": run, "data": data, **check.to_dict()})
        print(f"{run}: ratio {check.ratio:.3f}{' LOST' if check.lost else ''}", flush=True)
    found = [r["ratio"] for r in rows if not r["lost"]]
    lines = ["# The lost-object check on finished scene runs", "",
             f"Command: `{shlex.join(['python', *sys.argv])}`", "",
             f"Machine: {machine_words(machine())}. Threshold: {LOST_RATIO:g} (residual peak over content peak).", "",
             f"{len(rows)} runs; {len(found)} below the threshold"
             + (f" (ratio {min(found):.3f}–{max(found):.3f})" if found else "") + "; "
             + ", ".join(f"{Path(r['run']).name} {r['ratio']:.2f}" for r in rows if r["lost"]) + " above.", "",
             "| run | residual peak | content peak | ratio | lost |", "|---|---|---|---|---|"]
    lines += [f"| {Path(r['run']).name} | {r['residual_peak']:.4f} | {r['content_peak']:.3f} | {r['ratio']:.3f} | "
              f"{'**yes**' if r['lost'] else 'no'} |" for r in rows]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    write_json(out.with_suffix(".json"), {"command": shlex.join(["python", *sys.argv]), "threshold": LOST_RATIO,
                                          "machine": machine(), "rows": rows}, overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
