"""Benchmark: the paper's training recipe (``--preset paper``) against the fast one, on a file of the paper's size.

The paper trains each scene for 500 epochs of its 5000 training sequences (RMSProp 3e-4, batch 100, the rate
divided by 5 after 375 epochs: 25,000 steps), with a regressing location network and the reconstruction of every
frame. piga's fast recipe trains 1650 steps with Adam, a warm-up and a horizon curriculum. This script collects
one file of the paper's size (``piga-collect --system SYSTEM --preset paper``: 5000 / 500 / 500 sequences), trains
both recipes on it with ``piga-train-model`` as a user would, and writes a page that compares the learned
parameters, the test split's SSIM and the wall time::

    python benchmarks/paper_recipe.py --system spring --device cuda --out results/paper_recipe

Each recipe is a job whose record (``OUT_runs/records/SYSTEM-RECIPE.json``: the command, commit, exit, scores,
steps, seconds, machine and GPU) is kept: a rerun reuses it. ``--max-minutes`` bounds the paper run (it stops after
the epoch that ends past it, saved and judged "not converged"); a later ``--resume`` continues that run from its
checkpoint, on any machine that has the run folder, and records it again. The file is collected with ``--seed 100``,
so the same command gives the same data anywhere. A record names the git commit of the code; on a machine that got
a copy of the files (whose ``.git``, if any, may not be theirs), set ``PIGA_COMMIT`` to the commit they are.

Writes OUT.md and OUT.json.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import torch

from common import logged_command, machine, machine_words, out_prefix, write_page
from prediction import run_training

from piga.cli.common import ArgumentParser, positive_float, positive_int
from piga.io.atomic import write_json
from piga.io.pool import git_commit

SYSTEMS = ("spring", "bouncing", "gravity")
RECIPES = ("fast", "paper")
#: What a record keeps of metrics.json.
KEEP = ("split", "frame_ssim_mean", "frame_mse_mean", "parameter_errors", "physical_parameters", "converged", "training")


def gpu_name(device: str) -> str | None:
    """The GPU a ``--device`` runs on (None on the CPU)."""
    if device == "cpu" or not torch.cuda.is_available():
        return None
    return torch.cuda.get_device_name(0)


def collect(system: str, data: Path, workers: int, log: Path) -> None:
    """The paper-size file (made once: the same seed gives the same file)."""
    if data.exists():
        return
    command = ["piga-collect", "--system", system, "--preset", "paper", "--seed", "100", "--workers", str(workers),
               "--out", str(data), "--quiet"]
    if logged_command(command, log) != 0:
        raise RuntimeError(f"'{shlex.join(command)}' failed; see {log}")


def _segment(record: dict[str, Any]) -> dict[str, Any]:
    """What a record says of the stretch of training its command did (steps and seconds: where the run stood after it)."""
    t = record["metrics"]["training"]
    return {"command": record["command"], "commit": record["commit"], "steps": t["steps"], "seconds": t["seconds"],
            "machine": record["machine"], "gpu": record.get("gpu")}


def train(recipe: str, data: Path, run_dir: Path, args: argparse.Namespace, resume: bool, commit: str | None,
          earlier: dict[str, Any] | None = None) -> dict[str, Any]:
    """Trains (or continues) one recipe; its record. A continued run's record keeps the ``earlier`` record's stretches
    of training (``segments``), each with its machine."""
    command = ["piga-train-model", str(data), "--out", str(run_dir), "--device", args.device, "--quiet"]
    if not resume:  # (a resumed run keeps its recipe and seed)
        command += ["--preset", recipe, "--seed", "0", "--seed-retries", "0"]
    if args.threads:
        command += ["--threads", str(args.threads)]
    if recipe == "paper" and args.max_minutes:
        command += ["--max-minutes", f"{args.max_minutes:g}"]
    command += ["--resume"] if resume else ["--overwrite"]
    started = time.time()
    code, metrics = run_training(command, run_dir, run_dir.parent / f"{run_dir.name}.log", f"piga-train-model --preset {recipe}")
    record = {"recipe": recipe, "command": shlex.join(command), "commit": commit, "exit": code,
              "metrics": {k: metrics.get(k) for k in KEEP}, "outcome": (metrics.get("convergence") or {}).get("outcome"),
              "planned_steps": (metrics.get("convergence") or {}).get("planned_steps"),
              "wall_seconds": time.time() - started, "machine": machine(), "gpu": gpu_name(args.device)}
    before = (earlier.get("segments") or [_segment(earlier)]) if resume and earlier else []
    t = metrics["training"]
    if before and before[-1]["steps"] == t["steps"]:  # a continuation that trained no step (its budget was spent)
        print(f"{recipe}: no step trained (the run is at step {t['steps']:,}; raise --max-minutes to continue)", flush=True)
        return earlier  # type: ignore[return-value]
    record["segments"] = [*before, _segment(record)]
    print(f"{recipe}: {t['steps']} steps in {t['seconds'] / 60:.1f} min, exit {code} ({record['outcome']})", flush=True)
    return record


def _params(record: dict[str, Any]) -> str:
    errors = record["metrics"]["parameter_errors"] or {}
    return ", ".join(f"{k} = {e['learned']:.4g} ({100 * e['relative_error']:.1f}% off {e['true']:g})" for k, e in errors.items())


def markdown(records: dict[str, dict[str, Any]], command: str, system: str) -> str:
    lines = [f"# The paper's recipe against the fast one ({system})", "", f"Command: `{command}`", "",
             "Where each run trained (a run continued with `--resume` lists each stretch; steps and minutes are where the "
             "run stood after it):", "",
             *[f"- {name}: " + "; ".join(f"to step {g['steps']:,} ({g['seconds'] / 60:.1f} min) on "
                                          f"{'GPU ' + g['gpu'] + ', ' if g.get('gpu') else ''}{machine_words(g['machine'])}, "
                                          f"commit {str(g['commit'])[:10]}" for g in r.get("segments") or [_segment(r)])
               for name, r in records.items()], "",
             f"Data: `piga-collect --system {system} --preset paper --seed 100` (the paper's 5000 / 500 / 500 sequences). "
             "Each recipe trained once, seed 0, with `piga-train-model --preset RECIPE` (the commands are in the records); "
             "SSIM on the test split over the predicted and the extrapolated frames.", "",
             "| recipe | optimiser steps (planned) | epochs | train minutes | learned parameters | SSIM prediction | "
             "SSIM extrapolation | exit (outcome) |", "|---|---|---|---|---|---|---|---|"]
    for name in RECIPES:
        r = records.get(name)
        if r is None:
            continue
        t, ssim = r["metrics"]["training"], r["metrics"]["frame_ssim_mean"]
        ext = "-" if ssim.get("extrapolation") is None else f"{ssim['extrapolation']:.3f}"
        lines.append(f"| {name} | {t['steps']:,} ({'?' if r['planned_steps'] is None else format(r['planned_steps'], ',')}) | {t['epochs']} | {t['seconds'] / 60:.1f} | "
                     f"{_params(r)} | {ssim['prediction']:.3f} | {ext} | {r['exit']} ({r['outcome']}) |")
    lines += ["", "Exit is `piga-train-model`'s status: 0 converged, 3 not converged (stopped by `--max-minutes` before "
              "its plan ended, or a parameter still moving), 1 untrained. Train minutes are the training loop's "
              "(metrics.json's `training.seconds`, summed over a continued run's stretches), on the machines above.", ""]
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--system", choices=SYSTEMS, default="spring", help="the scene (default %(default)s)")
    p.add_argument("--recipes", nargs="+", choices=RECIPES, default=list(RECIPES), help="default: both")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="piga-train-model's --device")
    p.add_argument("--threads", type=positive_int, default=None, help="piga-train-model's --threads (default: its own)")
    p.add_argument("--workers", type=positive_int, default=2, help="piga-collect's --workers (default %(default)s)")
    p.add_argument("--max-minutes", type=positive_float, default=None,
                   help="stop the paper run after the epoch that ends past this (default: no limit)")
    p.add_argument("--resume", action="store_true", help="continue a stopped paper run in OUT_runs/ (and record it again)")
    p.add_argument("--out", type=out_prefix, default="results/paper_recipe", help="output prefix (default %(default)s)")
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        return run(parser().parse_args(argv), argv)
    except RuntimeError as exc:  # a command that failed: its log has the rest
        print(f"paper_recipe.py: error: {exc}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace, argv: list[str] | None) -> int:
    out = Path(args.out)
    folder = out.parent / f"{out.name}_runs"
    data = folder / "data" / f"{args.system}-paper-seed100.h5"
    for sub in ("data", "records"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    collect(args.system, data, args.workers, data.with_suffix(".log"))
    # the code that runs is the checkout's now: a commit read when a job ends may be a later one
    commit = os.environ.get("PIGA_COMMIT") or git_commit()
    records: dict[str, dict[str, Any]] = {}
    for recipe in RECIPES:
        path = folder / "records" / f"{args.system}-{recipe}.json"
        resume = args.resume and recipe == "paper" and (folder / f"{args.system}-paper" / "checkpoint.pt").exists()
        if recipe in args.recipes and (resume or not path.exists()):
            earlier = json.loads(path.read_text()) if resume and path.exists() else None
            write_json(path, train(recipe, data, folder / f"{args.system}-{recipe}", args, resume, commit, earlier),
                       overwrite=True)
        if path.exists():
            records[recipe] = json.loads(path.read_text())
    if not records:
        return 0
    command = shlex.join(["python", "benchmarks/paper_recipe.py", *(argv if argv is not None else sys.argv[1:])])
    write_page(out, {"command": command, "system": args.system, "records": records},
               markdown(records, command, args.system))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
