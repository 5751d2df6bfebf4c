"""Benchmark: does the end-of-run check tell a run that identified its system from one that did not?

``piga-train-model`` ends every run with a check (:mod:`piga.training.convergence`) that reads only the run's
own record, never the truth. Its last test compares the model's held-out prediction error with two models that
learned nothing: drawing the label-free background alone (``frame_mse_background``) and holding the last input
frame still (``frame_mse_hold``). This script trains runs that identify their system and runs that cannot
(too few or too short sequences, too few steps), as a user would (``piga-collect``, then ``piga-train-model``
with one thread), and puts each run's two ratios next to its parameters' errors (the truth in the file's
attributes is read here only, to score), so that the check's thresholds are chosen from measurements::

    python benchmarks/convergence_calibration.py --out results/convergence_calibration
    python benchmarks/convergence_calibration.py --out runs/cc --cases dmc-20x10-continuous

A case's record (``OUT_runs/records/CASE-sSEED.json``) is kept: a rerun reuses it (``--retrain`` trains again).
The data files are collected once, with ``--seed 100``. Writes OUT.md and OUT.json.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

from common import logged_command, machine, machine_words, out_prefix, write_page
from prediction import run_training

from piga.cli.common import ArgumentParser, nonnegative_int
from piga.io.atomic import write_json
from piga.io.pool import git_commit
from piga.training.convergence import ConvergenceConfig

#: A run identified its system when every learned parameter is within this of the truth ...
GOOD = 0.10
#: ... and did not when one is this far or farther.
BAD = 0.25


class Case(NamedTuple):
    """One run: its data file (a key of :data:`DATA`) and its ``piga-train-model`` options."""

    data: str
    train: tuple[str, ...]


DMC = ("--env", "piga/DMCPendulum-v0")
#: The data files, by name: ``piga-collect`` options (with ``--seed 100``).
DATA: dict[str, tuple[str, ...]] = {
    "pixel-500x40": (),  # piga-collect's defaults
    "pixel-100x40": ("--sequences", "100"),
    "pixel-20x40": ("--sequences", "20"),
    "pixel-20x20": ("--sequences", "20", "--steps", "20"),
    "pixel-50x10": ("--sequences", "50", "--steps", "10"),
    "pixel-20x10": ("--sequences", "20", "--steps", "10"),
    "dmc-200x40": (*DMC, "--sequences", "200"),
    "dmc-20x40": (*DMC, "--sequences", "20"),
    "dmc-50x20": (*DMC, "--sequences", "50", "--steps", "20"),
    "dmc-20x10": (*DMC, "--sequences", "20", "--steps", "10"),
    "spring-200": ("--system", "spring", "--sequences", "200"),
    "gravity-200": ("--system", "gravity", "--sequences", "200"),
}
SMALL = ("--batch-size", "8")
CASES: dict[str, Case] = {
    "pixel-500x40-fast": Case("pixel-500x40", ("--preset", "fast")),
    "pixel-500x40-continuous": Case("pixel-500x40", ("--preset", "continuous")),
    "pixel-100x40-fast": Case("pixel-100x40", ("--preset", "fast")),
    "pixel-20x40-fast": Case("pixel-20x40", ("--preset", "fast", "--budget-steps", "400", *SMALL)),
    "pixel-20x20-fast": Case("pixel-20x20", ("--preset", "fast", "--budget-steps", "400", *SMALL)),
    "pixel-50x10-fast": Case("pixel-50x10", ("--preset", "fast", "--budget-steps", "400", *SMALL)),
    "pixel-20x10-fast-2000": Case("pixel-20x10", ("--preset", "fast", "--budget-steps", "2000", *SMALL)),
    "pixel-20x10-fast": Case("pixel-20x10", ("--preset", "fast", "--budget-steps", "200", *SMALL)),
    "pixel-20x10-continuous": Case("pixel-20x10", ("--preset", "continuous", "--budget-steps", "200", *SMALL)),
    "dmc-200x40-fast": Case("dmc-200x40", ("--preset", "fast")),
    "dmc-200x40-continuous": Case("dmc-200x40", ("--preset", "continuous")),
    "dmc-20x40-fast": Case("dmc-20x40", ("--preset", "fast", "--budget-steps", "400", *SMALL)),
    "dmc-50x20-fast": Case("dmc-50x20", ("--preset", "fast", "--budget-steps", "400", *SMALL)),
    "dmc-20x10-fast": Case("dmc-20x10", ("--preset", "fast", "--budget-steps", "200", *SMALL)),
    "dmc-20x10-continuous": Case("dmc-20x10", ("--preset", "continuous", "--budget-steps", "200", *SMALL)),
    "spring-200-fast": Case("spring-200", ("--preset", "fast", "--budget-steps", "800", "--seed-retries", "0")),
    "gravity-200-fast": Case("gravity-200", ("--preset", "fast", "--budget-steps", "800", "--seed-retries", "0")),
}


def collect(name: str, folder: Path) -> Path:
    """The data file ``name`` (made once: the same seed gives the same file)."""
    path = folder / f"{name}.h5"
    if not path.exists():
        command = ["piga-collect", *DATA[name], "--seed", "100", "--workers", "1", "--quiet", "--out", str(path)]
        if logged_command(command, path.with_suffix(".log")) != 0:
            raise RuntimeError(f"'{shlex.join(command)}' failed; see {path.with_suffix('.log')}")
    return path


def train(name: str, seed: int, data: Path, run_dir: Path, commit: str | None) -> dict[str, Any]:
    """Trains one case; its record."""
    command = ["piga-train-model", str(data), "--out", str(run_dir), *CASES[name].train, "--seed", str(seed),
               "--threads", "1", "--quiet", "--overwrite"]
    started = time.time()
    code, m = run_training(command, run_dir, run_dir.parent / f"{run_dir.name}.log", name)
    errors = {k: e["relative_error"] for k, e in (m.get("parameter_errors") or {}).items()
              if isinstance(e, dict) and e.get("relative_error") is not None}
    pred = m["frame_mse_mean"]["prediction"]
    record = {"case": name, "seed": seed, "data": DATA[CASES[name].data], "command": shlex.join(command),
              "commit": commit, "exit": code, "outcome": (m.get("convergence") or {}).get("outcome"),
              "reason": (m.get("convergence") or {}).get("reason"), "parameter_errors": errors,
              "frame_mse_prediction": pred, "frame_mse_background": m["frame_mse_background"],
              "frame_mse_hold": m.get("frame_mse_hold"), "profile": m.get("profile") or {},
              "tail_speed": {k: p.get("tail_speed") for k, p in ((m.get("convergence") or {}).get("parameters") or {}).items()},
              "steps": m["training"]["steps"],
              "train_seconds": m["training"]["seconds"], "wall_seconds": time.time() - started, "machine": machine()}
    print(f"{name} s{seed}: exit {code} ({record['outcome']}), errors "
          + ", ".join(f"{k} {100 * v:.1f}%" for k, v in errors.items())
          + f", MSE/background {pred / m['frame_mse_background']:.3f}", flush=True)
    return record


def ratios(r: dict[str, Any]) -> tuple[float, float | None]:
    """A record's prediction MSE over the background's, and over the held frame's (None: not recorded)."""
    hold = r.get("frame_mse_hold")
    return r["frame_mse_prediction"] / r["frame_mse_background"], None if not hold else r["frame_mse_prediction"] / hold


def profile_cell(r: dict[str, Any]) -> str:
    """Each learned parameter's training-frame MSE with it scaled down and up (relative to its value's)."""
    shown = lambda x: "inf" if x is None else f"{x:.3f}"  # noqa: E731 (JSON keeps a blown-up prediction's inf as null)
    return ", ".join(f"{k} {shown(p['lower'])} / {shown(p['upper'])}" for k, p in r["profile"].items()) or "-"


def lowest_profile(r: dict[str, Any]) -> float | None:
    """A record's lowest profile ratio over its parameters and both scalings (None: no profile; a null is a
    blown-up prediction, the worst)."""
    values = [x for p in r["profile"].values() for x in (p["lower"], p["upper"]) if x is not None]
    return min(values, default=None)


def highest_profile(p: dict[str, Any]) -> float:
    """One parameter's larger profile ratio of its two scalings (a null, a blown-up prediction, is inf)."""
    return max(math.inf if x is None else x for x in (p["lower"], p["upper"]))


def _names(records: list[dict[str, Any]]) -> str:
    return " (" + ", ".join(f"{r['case']} s{r['seed']}" for r in records) + ")" if records else ""


def verdict(r: dict[str, Any]) -> str:
    """``identified`` (every parameter within GOOD), ``not identified`` (one BAD or farther) or ``between``."""
    worst = max(r["parameter_errors"].values(), default=float("inf"))
    return "identified" if worst <= GOOD else "not identified" if worst >= BAD else "between"


def summary(records: list[dict[str, Any]]) -> list[str]:
    """The separation of the two groups by each ratio, and where the check's thresholds stand."""
    lines = []
    config = ConvergenceConfig()
    for index, label in ((0, "MSE / background"), (1, "MSE / held frame")):
        good = [ratios(r)[index] for r in records if verdict(r) == "identified" and ratios(r)[index] is not None]
        bad = [ratios(r)[index] for r in records if verdict(r) == "not identified" and ratios(r)[index] is not None]
        if good and bad:
            lines.append(f"- {label}: identified runs at most **{max(good):.3f}** ({len(good)} runs); runs not identified "
                         f"at least **{min(bad):.3f}** ({len(bad)} runs): "
                         + ("the ratio separates them." if max(good) < min(bad) else "the ratio does not separate them."))
    lines.append(f"- The check today: untrained when MSE / background is not below `blank_ratio` = {config.blank_ratio:g}, "
                 f"or (a model with physical parameters) MSE / held frame not below `hold_ratio` = {config.hold_ratio:g} "
                 f"(`piga.training.convergence.ConvergenceConfig`); unsettled when a profile ratio is below "
                 f"1 - `profile_tolerance` = {1 - config.profile_tolerance:g}.")
    floor = 1 - config.profile_tolerance
    short = [r for r in records if (lowest_profile(r) or 1.0) < floor]
    lines.append(f"- Runs with a parameter short of its value by the profile: {len(short)}"
                 + "".join(f"; {r['case']} s{r['seed']} ({verdict(r)})" for r in short) + ".")
    lowest = [(lowest_profile(r), r) for r in records if verdict(r) == "identified" and lowest_profile(r) is not None]
    if lowest:
        value, worst = min(lowest, key=lambda t: t[0])
        lines.append(f"- The lowest profile ratio of an identified run: **{value:.3f}** ({worst['case']} s{worst['seed']}): "
                     + ("no identified run has a parameter that predicts its frames better scaled."
                        if value >= floor else "an identified run is called unsettled."))
    flat_floor = 1 + config.flat_tolerance  # a parameter whose ratios both stay under it is not determined
    curved = [(highest_profile(p), k, f"{r['case']} s{r['seed']}") for r in records if verdict(r) == "identified"
              for k, p in r["profile"].items()]
    flat = [t for t in curved if t[0] < flat_floor]
    if curved:
        lines.append(f"- Flat profiles (both ratios below 1 + `flat_tolerance` = {flat_floor:g}: not determined by the "
                     f"frames) among identified runs: {len(flat)}" + "".join(f"; {k} of {run} ({v:.3f})" for v, k, run in flat)
                     + ".")
        others = [t for t in curved if t[0] >= flat_floor]
        if others:
            v, k, run = min(others)
            lines.append(f"- The least curved of their other parameters: {k} of {run}, whose larger ratio is {v:.3f}.")
    for group in ("identified", "not identified"):  # the parameters' speed over the tail (records that keep it)
        fastest = [(max(abs(x) for x in r["tail_speed"].values() if x is not None), r) for r in records
                   if verdict(r) == group and any(x is not None for x in (r.get("tail_speed") or {}).values())]
        if fastest:
            value, run = max(fastest, key=lambda t: t[0])
            lines.append(f"- The fastest tail of a run {group}: {value:.2f}x the sum of its learning rate there "
                         f"({run['case']} s{run['seed']}; `speed_tolerance` = {config.speed_tolerance:g}).")
    missed = [r for r in records if verdict(r) == "not identified" and r["exit"] == 0]
    alarms = [r for r in records if verdict(r) == "identified" and r["exit"] != 0]
    lines.append(f"- Runs not identified that exit 0 (converged): {len(missed)}{_names(missed)}; identified runs that "
                 f"exit 1 or 3: {len(alarms)}{_names(alarms)}.")
    return lines


def markdown(records: list[dict[str, Any]], command: str) -> str:
    machines = sorted({machine_words(r["machine"]) for r in records})
    lines = ["# Calibrating the end-of-run check", "", f"Reproduce (resumable): `{command}`.", "",
             f"Machine: {'; '.join(machines)}. Each run trained with one torch thread, the data collected with "
             "`--seed 100` (the `piga-collect` options are in the table), the `piga-train-model` command in each record.",
             "", "Each run's held-out prediction MSE (test split, the predicted frames) over that of two models that "
             "learned nothing: the label-free background alone, and the last input frame held still. The profile is "
             "the training frames' prediction MSE with each learned parameter divided and multiplied by 1.65, over "
             "that at its learned value (`piga.evaluation.profile`): below 1, the parameter stopped short. Errors are "
             "the learned parameters' against the file's truth (read only here). A run is *identified* when every "
             f"learned parameter is within {100 * GOOD:.0f}% of the truth and *not identified* when one is "
             f"{100 * BAD:.0f}% off or more.", "",
             "| case | seed | data (`piga-collect` options) | steps | parameter errors | MSE / background | MSE / held frame "
             "| profile (÷1.65 / ×1.65) | verdict | exit (outcome) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(records, key=lambda r: ratios(r)[0]):
        back, hold = ratios(r)
        errors = ", ".join(f"{k} {100 * v:.1f}%" for k, v in r["parameter_errors"].items()) or "-"
        lines.append(f"| {r['case']} | {r['seed']} | `{' '.join(r['data']) or '(defaults)'}` | {r['steps']:,} | {errors} | "
                     f"{back:.3f} | {'-' if hold is None else f'{hold:.3f}'} | {profile_cell(r)} | {verdict(r)} | {r['exit']} ({r['outcome']}) |")
    lines += ["", "## What separates them", "", *summary(records), "",
              "Exit is `piga-train-model`'s: 0 converged, 3 unsettled, 1 untrained (the records keep the check's reason).", ""]
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", nargs="+", choices=tuple(CASES), default=list(CASES), help="default: all")
    p.add_argument("--seeds", nargs="+", type=nonnegative_int, default=[0], help="training seeds (default 0)")
    p.add_argument("--retrain", action="store_true", help="train the cases again rather than reuse their records")
    p.add_argument("--out", type=out_prefix, default="results/convergence_calibration", help="output prefix (default %(default)s)")
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        return run(parser().parse_args(argv), argv)
    except RuntimeError as exc:  # a command that failed: its log has the rest
        print(f"convergence_calibration.py: error: {exc}", file=sys.stderr)
        return 1


def run(args: argparse.Namespace, argv: list[str] | None) -> int:
    out = Path(args.out)
    folder = out.parent / f"{out.name}_runs"
    for sub in ("data", "records"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    commit = git_commit()
    for name in args.cases:
        for seed in args.seeds:
            path = folder / "records" / f"{name}-s{seed}.json"
            if args.retrain or not path.exists():
                data = collect(CASES[name].data, folder / "data")
                write_json(path, train(name, seed, data, folder / f"{name}-s{seed}", commit), overwrite=True)
    records = [json.loads(p.read_text()) for p in sorted((folder / "records").glob("*.json"))]
    if not records:
        return 0
    command = shlex.join(["python", "benchmarks/convergence_calibration.py", *(argv if argv is not None else sys.argv[1:])])
    write_page(out, {"command": command, "good": GOOD, "bad": BAD, "records": records}, markdown(records, command))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
