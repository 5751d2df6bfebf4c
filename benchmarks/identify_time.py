"""Benchmark: how long does identification take, and how does the error fall with the steps?

On one pendulum file (``piga-collect``'s defaults, or ``--data``), it trains each recipe in turn,
alone, in this process, and records the training time (median over ``--repeats``), the learned g
and a with their errors, the convergence check, and the error of g and a against the optimiser step
(from the parameters' trajectory each run records; the truth is read only here, to score).

The recipes:

- ``today``: the fast preset as it is (a step budget sized from the file, torch's threads);
- ``before``: the fast preset before its budget was cut: 16 epochs of the default file, a 200-step
  warm-up and a 600-step curriculum, the final epoch averaged (what ``results/train_accuracy.md``
  measured);
- ``budget-N``: today's recipe with a budget of N steps, for the error-against-steps curve.

    python benchmarks/identify_time.py --out results/identify_time
    python benchmarks/identify_time.py --out runs/it --recipes today budget-1500 --repeats 1

Writes ``OUT.json``, ``OUT.md`` and ``OUT-error.png``. The speed-up is the ratio of the medians of
``before`` and ``today``, measured in one invocation on one machine.
"""

from __future__ import annotations

import os
import shutil
import statistics
import sys
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from common import machine, out_prefix, work_folder, write_page
from piga.io.atomic import atomic_output
from piga.data.collect import CollectConfig, collect
from piga.data.schema import inspect_dataset
from piga.evaluation.evaluate import PARAMETER_NAMES
from piga.training.report import write_run_report
from piga.training.train import TrainConfig, train
from piga.cli.common import ArgumentParser, positive_int, thread_count

#: The fast preset before its budget was sized from the data: 16 epochs, 200 warm-up and 600 curriculum
#: steps of the default file's 16 x 337, and the last epoch averaged.
BEFORE_STEPS = 16 * 337
BEFORE = TrainConfig(epochs=16, warmup_fraction=200 / BEFORE_STEPS, curriculum_fraction=600 / BEFORE_STEPS,
                     average_fraction=1 / 16)


def recipe(name: str, threads: int) -> TrainConfig:
    """The TrainConfig of a recipe name (see the module docstring), on the CPU: the times are the CPU's on
    every machine."""
    if name == "today":
        return TrainConfig(threads=threads, device="cpu")
    if name == "before":
        return replace(BEFORE, threads=threads, device="cpu")
    if name.startswith("budget-"):
        steps = name.split("-", 1)[1]
        if not (steps.isdecimal() and int(steps) >= 1):  # (int() said "invalid literal for int() with base 10")
            raise ValueError(f"--recipes {name}: budget-N takes a whole number of steps N >= 1")
        return TrainConfig(budget_steps=int(steps), threads=threads, device="cpu")
    raise ValueError(f"--recipes: unknown recipe {name!r}: today, before or budget-N")


def error_curve(trace: list[list[float]], names: list[str], truth: dict[str, float]) -> dict[str, list[float]]:
    """The trajectory as steps and relative errors per parameter."""
    rows = np.asarray(trace, dtype=float)
    curve = {"step": rows[:, 0].tolist()}
    for i, name in enumerate(names):
        if name in truth:
            curve[name] = (np.abs(rows[:, 1 + i] - truth[name]) / abs(truth[name])).tolist()
    return curve


def run_recipe(name: str, data: Path, work: Path, threads: int, repeat: int) -> dict[str, Any]:
    run_dir = work / f"{name}-r{repeat}"
    if run_dir.exists():
        shutil.rmtree(run_dir)
    config = recipe(name, threads)
    model, state = train(data, run_dir, config, progress=False)
    metrics = write_run_report(model, state, data, run_dir)
    info = inspect_dataset(data)
    truth = {PARAMETER_NAMES[k]: float(v) for k, v in info.params.items() if k in PARAMETER_NAMES}
    return {"recipe": name, "repeat": repeat, "train": asdict(config), "plan": state.plan, "seconds": state.elapsed,
            "steps": state.step, "errors": {k: v["relative_error"] for k, v in metrics["parameter_errors"].items()},
            "learned": {k: v["learned"] for k, v in metrics["parameter_errors"].items()},
            "converged": metrics.get("converged"), "reason": metrics.get("convergence", {}).get("reason"),
            "curve": error_curve(state.trace, list(state.start), truth), "load_average_at_end": os.getloadavg()}


def summarise(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for name in dict.fromkeys(r["recipe"] for r in runs):
        mine = [r for r in runs if r["recipe"] == name]
        rows.append({"recipe": name, "runs": len(mine), "steps": mine[0]["steps"],
                     "minutes_median": statistics.median(r["seconds"] for r in mine) / 60,
                     "g_error_max": max(r["errors"]["g"] for r in mine), "a_error_max": max(r["errors"]["a"] for r in mine),
                     "converged": all(r["converged"] for r in mine)})
    return rows


def markdown(record: dict[str, Any]) -> str:
    lines = ["# Identification time on the default pendulum file", "",
             f"Reproduce: `{record['command']}`. Each run trained alone, in turn, in one process: the times "
             "compare within this one run.", "", f"Machine: {record['machine']}", "",
             "| recipe | steps | runs | training minutes (median) | g error (max) | a error (max) | converged |",
             "|---|---|---|---|---|---|---|"]
    for r in record["summary"]:
        lines.append(f"| {r['recipe']} | {r['steps']} | {r['runs']} | {r['minutes_median']:.2f} | "
                     f"{100 * r['g_error_max']:.3f}% | {100 * r['a_error_max']:.3f}% | {'yes' if r['converged'] else 'no'} |")
    if record.get("speedup"):
        lines += ["", f"Speed-up of `today` over `before`: **{record['speedup']:.2f}x** (ratio of the median training times)."]
    lines += ["", "![error against steps](" + Path(record["figure"]).name + ")", ""]
    return "\n".join(lines)


def figure(runs: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    for ax, name in zip(axes, ("g", "a")):
        for r in runs:
            if r["repeat"] == 0 and name in r["curve"]:
                ax.semilogy(r["curve"]["step"], np.maximum(r["curve"][name], 1e-5), label=r["recipe"])
        ax.axhline(0.005, color="k", lw=0.8, ls="--")
        ax.set(title=f"relative error of {name}", xlabel="optimiser step")
    axes[0].legend()
    fig.tight_layout()
    with atomic_output(path, overwrite=True) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, type=out_prefix, help="output prefix: OUT.json, OUT.md, OUT-error.png")
    p.add_argument("--data", type=Path, help="a pendulum file (default: piga-collect's defaults, seed 100, in --work)")
    p.add_argument("--work", type=work_folder, default=Path("runs/identify_time"), help="data and run folders")
    p.add_argument("--recipes", nargs="+", default=["before", "today"])
    p.add_argument("--repeats", type=positive_int, default=1, help="runs of each recipe (the time is their median)")
    p.add_argument("--threads", type=thread_count, default=0, help="torch threads (0: torch's default, as piga-train-model)")
    args = p.parse_args(argv)
    for name in args.recipes:
        recipe(name, 0)  # unknown names fail before any work
    args.work.mkdir(parents=True, exist_ok=True)
    data = args.data
    if data is None:
        data = args.work / "pendulum.h5"
        if not data.exists():
            collect(replace(CollectConfig(), seed=100), data, command="benchmarks/identify_time.py")
    runs = [run_recipe(name, data, args.work, args.threads, k) for k in range(args.repeats) for name in args.recipes]
    summary = summarise(runs)
    medians = {r["recipe"]: r["minutes_median"] for r in summary}
    out = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    record = {"command": "python benchmarks/identify_time.py " + " ".join(argv if argv is not None else sys.argv[1:]),
              "machine": machine(), "data": str(data), "runs": runs, "summary": summary,
              "speedup": medians["before"] / medians["today"] if {"before", "today"} <= set(medians) else None,
              "figure": str(out.with_name(out.name + "-error.png"))}
    figure(runs, Path(record["figure"]))
    page = markdown(record)
    write_page(out, record, page)
    print(page)
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
