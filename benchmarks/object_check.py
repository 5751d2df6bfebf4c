"""Benchmark: the object check (:mod:`piga.evaluation.objects`) on finished scene runs.

For every run folder given (a ``piga-train-model`` run of a scene, whose ``config.json`` names its data
file, or ``RUN=DATA`` to name it), it reconstructs the test split's single frames and prints the ratio of
the residual's peak to the moving content's peak, against the lost-object threshold, and for each slot the
change that taking it out makes, against the empty-slot threshold. It trains nothing: it shows where
the thresholds sit between runs that found every object and runs that lost one or have a slot too many, for example the
robustness benchmark's runs, and the dark-background gravity run at seed 0 without the retry that
finds its lost ball (``piga-train-model`` trains again with the next seed when the check fails)::

    piga-train-model runs/robustness/data/gravity-background-401a4d.h5 --seed-retries 0 --threads 1 \
        --out runs/object_check/gravity-background-401a4d-seed0-no-retry     # exits 1: a ball lost
    python benchmarks/object_check.py runs/robustness/runs/*-seed0 \
        runs/object_check/gravity-background-401a4d-seed0-no-retry --out results/object_check

Writes OUT.json and OUT.md.
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import torch

from common import machine, machine_words, out_prefix, write_page
from piga.data.schema import read_sequences
from piga.evaluation.objects import EMPTY_RATIO, LOST_RATIO, check_objects
from piga.io.runs import load_model
from piga.cli.common import ArgumentParser, PigaError


def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="run folders (RUN, or RUN=DATA when its config.json does not name the file)")
    p.add_argument("--out", type=out_prefix, default="results/object_check", help="output prefix (default %(default)s)")
    args = p.parse_args()
    torch.set_num_threads(1)
    rows = []
    for spec in args.runs:
        run, _, data = spec.partition("=")
        model, _ = load_model(run)
        if model.config.coord_dim != 2:  # a pendulum's angle: no objects to check (a page of 0 runs said nothing)
            raise PigaError(f"{run} is a run of {model.config.system}, not of a scene of objects; give scene runs "
                            "(piga-train-model on a spring, bouncing or gravity file)")
        if not data:
            data = json.loads((Path(run) / "config.json").read_text())["data"]
        check = check_objects(model, read_sequences(data, "test")[0]).with_counts(model.config.n_objects, None)
        rows.append({"run": run, "data": data, **check.to_dict()})
        print(f"{run}: ratio {check.ratio:.3f}{' LOST' if check.lost else ''}; slots "
              + " ".join(f"{r:.3f}" for r in check.slot_ratios) + (f" EMPTY {check.empty_slots}" if check.empty_slots else "")
              + f" ({check.slots} slots)", flush=True)
    found = [r["ratio"] for r in rows if not r["lost"]]
    drawn = [x for r in rows for i, x in enumerate(r["slot_ratios"]) if i not in r["empty_slots"]]
    empty = [x for r in rows for i, x in enumerate(r["slot_ratios"]) if i in r["empty_slots"]]
    lines = ["# The object check on finished scene runs", "",
             f"Command: `{shlex.join(['python', *sys.argv])}`", "",
             f"Machine: {machine_words(machine())}. Thresholds: an object is lost above {LOST_RATIO:g} (residual peak "
             f"over content peak); a slot is empty below {EMPTY_RATIO:g} (the peak change that taking it out of the "
             "reconstruction makes, over the content peak).", "",
             f"{len(rows)} runs; {len(found)} below the lost-object threshold"
             + (f" (ratio {min(found):.3f}–{max(found):.3f})" if found else "") + "; "
             + (", ".join(f"{Path(r['run']).name} {r['ratio']:.2f}" for r in rows if r["lost"]) or "none") + " above. "
             f"Slots: {len(drawn)} draw"
             + (f" (change {min(drawn):.3f}–{max(drawn):.3f})" if drawn else "") + f", {len(empty)} empty"
             + (f" (change {min(empty):.3f}–{max(empty):.3f})" if empty else "") + ".", "",
             "| run | slots | residual peak | content peak | ratio | lost | change per slot | empty slots |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {Path(r['run']).name} | {r['slots']} | {r['residual_peak']:.4f} | {r['content_peak']:.3f} | {r['ratio']:.3f} | "
              f"{'**yes**' if r['lost'] else 'no'} | {', '.join(f'{x:.3f}' for x in r['slot_ratios'])} | "
              f"{', '.join(map(str, r['empty_slots'])) or 'none'} |" for r in rows]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_page(out, {"command": shlex.join(["python", *sys.argv]), "threshold": LOST_RATIO,
                     "empty_threshold": EMPTY_RATIO, "machine": machine(), "rows": rows}, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
