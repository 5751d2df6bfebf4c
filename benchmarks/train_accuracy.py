"""Benchmark: does the default recipe identify g and a to 1% on a 2-core CPU, for every seed and value?

For each case it collects a data set with ``piga-collect``'s defaults, except for the case's
physical values. It then trains with the default ``fast`` preset, which never reads /states and
starts at g = 1, a = 0.3, and records the learned parameters and their errors, the training
time, SSIM per step, and the encoder angle error.

    python benchmarks/train_accuracy.py --out results/train_accuracy            # all cases
    python benchmarks/train_accuracy.py --out results/train_accuracy --cases default --seeds 0 1

Each finished run is appended to ``OUT.json`` (atomically), so an interrupted benchmark
continues where it stopped. ``OUT.md`` is rewritten each time with the table. Runs are sequential
by default, so training time is measured on the whole machine; the machine is recorded. ``--jobs N``
trains N runs at once (one torch thread each), and ``--ray auto|HOST:PORT`` trains them as tasks of a
Ray cluster (one CPU and one torch thread each; on several machines ``--work`` must be one shared
folder: the data files are collected there first, by this process).
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path


from common import add_ray_option, farm_main, machine, out_prefix, ray_backend, work_folder
from piga.io.atomic import atomic_output
from piga.io.pool import run_pool
from piga.data.collect import CollectConfig, collect
from piga.training.convergence import check_convergence
from piga.evaluation.evaluate import EvalConfig, evaluate
from piga.io.atomic import write_json, written_together
from piga.world.model import ModelConfig
from piga.training.train import PRESETS, TrainConfig, train
from piga.cli.common import ArgumentParser, positive_int, seed_int

#: case name -> (gravity, actuation gain, data seed)
CASES: dict[str, tuple[float, float, int]] = {
    "default": (10.0, 1.0, 100),
    "g6": (6.0, 1.0, 101),
    "g14": (14.0, 1.0, 102),
    "a0.5": (10.0, 0.5, 103),
    "a1.5": (10.0, 1.5, 104),
}


def markdown(record: dict, out: Path) -> str:
    """The Markdown page: how to reproduce, the machine, the table."""
    return (f"# Parameter identification benchmark\n\nReproduce all runs (resumable, skips finished ones): "
            f"`python benchmarks/train_accuracy.py --out {out}`. Last invocation: `{record['command']}`.\n\n"
            f"Machine: {record['machine']}\n\n" + table(record["runs"]))


def table(runs: list[dict[str, object]]) -> str:
    """Markdown: one row per run, then per-case medians and spreads."""
    lines = ["| case | seed | true g | learned g | g error | true a | learned a | a error | converged | train min | SSIM pred | SSIM ext | angle err (deg) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        pe = r["metrics"]["parameter_errors"]  # type: ignore[index]
        m = r["metrics"]
        ssim = m["frame_ssim_mean"]  # type: ignore[index]
        angle = m.get("angle", {}).get("mean_abs_error_deg", float("nan"))  # type: ignore[union-attr]
        lines.append(
            f"| {r['case']} | {r['seed']} | {pe['g']['true']:g} | {pe['g']['learned']:.4f} | {100 * pe['g']['relative_error']:.2f}% | "
            f"{pe['a']['true']:g} | {pe['a']['learned']:.4f} | {100 * pe['a']['relative_error']:.2f}% | "
            f"{ {True: 'yes', False: 'no'}.get(r.get('converged'), '-') } | {r['train_seconds'] / 60:.1f} | {ssim['prediction']:.3f} | {ssim['extrapolation']:.3f} | {angle:.2f} |"
        )
    lines += ["", "| case | runs | g error median (max) | a error median (max) | all ≤ 1% | train min median |", "|---|---|---|---|---|---|"]
    for case in dict.fromkeys(r["case"] for r in runs):
        rs = [r for r in runs if r["case"] == case]
        ge = [100 * r["metrics"]["parameter_errors"]["g"]["relative_error"] for r in rs]  # type: ignore[index]
        ae = [100 * r["metrics"]["parameter_errors"]["a"]["relative_error"] for r in rs]  # type: ignore[index]
        ok = sum(g <= 1 and a <= 1 for g, a in zip(ge, ae))
        lines.append(f"| {case} | {len(rs)} | {statistics.median(ge):.2f}% ({max(ge):.2f}%) | {statistics.median(ae):.2f}% ({max(ae):.2f}%) | "
                     f"{ok}/{len(rs)} | {statistics.median([r['train_seconds'] / 60 for r in rs]):.1f} |")
    return "\n".join(lines) + "\n"


def train_run(job: tuple[str, int, Path, Path]) -> dict[str, object]:
    """Trains one (case, seed) run on the case's data with the default ``fast`` preset and evaluates it; its record."""
    case, seed, data, run_dir = job
    started = time.monotonic()
    model, state = train(data, run_dir, TrainConfig(seed=seed, device="cpu"), PRESETS["fast"].model,
                         progress=False)  # the 2-core CPU's times, on every machine
    wall = time.monotonic() - started
    metrics = evaluate(model, data, EvalConfig())
    convergence = check_convergence(state)
    return {"case": case, "seed": seed, "train_seconds": state.elapsed, "wall_seconds": wall, "history": state.history,
            "metrics": metrics, "converged": convergence.converged, "convergence": convergence.to_dict()}


@farm_main
def main() -> None:
    p = ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=out_prefix, default="results/train_accuracy", help="output stem (.json and .md)")
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    p.add_argument("--seeds", nargs="+", type=seed_int, default=None, help="training seeds (default: 0-4 for 'default', 0 otherwise)")
    p.add_argument("--work", type=work_folder, default="runs/bench", help="folder for data and run folders")
    p.add_argument("--jobs", type=positive_int, default=1, help="runs trained at once, one torch thread each (default 1: one at a "
                   "time, on torch's default threads)")
    add_ray_option(p, "the training runs")
    args = p.parse_args()
    backend = ray_backend(p, args)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    record_path = out.with_suffix(".json")
    record = json.loads(record_path.read_text()) if record_path.exists() else {"runs": []}
    record["machine"] = machine()
    record["command"] = " ".join(["python", *sys.argv])
    record["recipe"] = {"train": TrainConfig(device="cpu").__dict__, "preset": "fast", "model": ModelConfig().to_dict()}
    done = {(r["case"], r["seed"]) for r in record["runs"]}
    todo: list[tuple[str, int, Path, Path]] = []
    for case in args.cases:
        gravity, gain, data_seed = CASES[case]
        seeds = args.seeds if args.seeds is not None else ([0, 1, 2, 3, 4] if case == "default" else [0])
        data = work / f"{case}.h5"
        if not data.exists() and any((case, seed) not in done for seed in seeds):
            base = CollectConfig()
            collect(replace(base, env=replace(base.env, gravity=gravity, actuation_gain=gain), seed=data_seed), data,
                    progress=False, command=f"benchmark case {case}")
        todo += [(case, seed, data, work / f"{case}-seed{seed}") for seed in seeds if (case, seed) not in done]

    def finished(_: int, run: dict[str, object]) -> None:  # saved as each run ends, so that a stopped benchmark continues
        record["runs"].append(run)
        record["runs"].sort(key=lambda r: (list(CASES).index(r["case"]), r["seed"]))
        # the record last: a failed page keeps the previous one to continue from
        with written_together([record_path, out.with_suffix(".md")]):
            with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
                tmp.write_text(markdown(record, out))
            write_json(record_path, record)
        pe = run["metrics"]["parameter_errors"]  # type: ignore[index]
        name = f"{run['case']} seed {run['seed']}"
        if not run["converged"]:
            print(f"{name}: warning: not converged: {run['convergence']['reason']}", file=sys.stderr)  # type: ignore[index]
        print(f"{name}: g={pe['g']['learned']:.4f} ({100 * pe['g']['relative_error']:.2f}%), "
              f"a={pe['a']['learned']:.4f} ({100 * pe['a']['relative_error']:.2f}%), "
              f"{run['train_seconds'] / 60:.1f} min", flush=True)  # type: ignore[operator]

    run_pool(train_run, todo, workers=args.jobs, progress=False, on_result=finished, backend=backend,
             names=[f"{case} seed {seed}" for case, seed, _, _ in todo])


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
