"""Benchmark: dm_control's pendulum-swingup, identified, diagnosed and swung up from pixels, against published pixel-RL scores.

For each seed (and each variant of the pendulum given with ``--variant``), as a user would, with
the commands themselves:

1. ``piga-collect --env piga/DMCPendulum-v0``: ``--sequences`` x ``--steps`` random-action frames
   (u ~ U(-1, 1), no reward is read), 64x64 gray from the face-on camera, dt 0.04 s;
2. ``piga-train-model --preset continuous`` (RK4 within the frame, velocities through it, a
   learnable damping; g, a, b start at 1, 0.3, 0.01); the learned g, a, b against the truth in
   piga's form, with the identification floor (every parameter within 3%; the stretch goal 1%).
   A flipped camera or motor (``--variant flip=camera|motor``) is trained with
   ``--signed-actuation``, so that a can turn negative: its truth is then −gear / (3·I);
3. ``piga-control --env piga/DMCPendulum-v0 --model RUN --oracle``: 10 DMC episodes (1000 physics
   steps of 0.02 s, DMC's reward summed, max 1000) for the piga agent and for the oracle (true
   state, true physics, the same planner);
4. the diagnosis, for the cases of ``--diagnose`` (by default the first seed's): the same file
   through the unchanged default preset (``piga-train-model --preset fast``: one Euler step per
   frame, no damping; ``--epochs`` as above), then ``piga-diagnose`` on that model and file; its
   ``report.json`` is read for the floors: damping named within 5% of the truth, no speed clip (and
   nothing said of Gymnasium), and a headline closure that has a valid floor and is at most 100%.
   A flipped case is not diagnosed: the diagnosis needs a > 0, and refuses such a model in one line.

    python benchmarks/dmc.py --work runs/dmc --out results/dmc
    python benchmarks/dmc.py --work runs/dmc --out results/dmc --epochs 6 --seeds 0 1 2 --variant flip=motor \
        --variant mass=1.5 --variant length=0.4 --variant damping=0.3

Variants run for the first seed only unless ``--variant-seeds all``.

The cases are jobs of piga's job runner (:func:`piga.io.pool.run_pool`): one at a time by default,
``--jobs N`` at once in processes of this machine, or with ``--ray auto|HOST:PORT`` as tasks of a Ray
cluster (``--work`` then one folder shared by every machine); each command trains with one thread.
A command that fails stops the benchmark with one line naming the case and the command's log.
Finished steps are kept in ``--work`` and skipped when the benchmark is run again, so an
interrupted or failed run continues. ``OUT.json`` holds every number, ``OUT.md`` the tables, with the
published scores next to piga's point.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
from pathlib import Path
from typing import NamedTuple

from common import (add_diagnose_options, add_ray_option, diagnose_options, farm_main, logged_command, machine,
                    out_prefix, ray_backend, work_folder, write_page)
from piga.io.pool import run_pool
from piga.cli.common import ArgumentParser, PigaError, positive_int, seed_int

#: Published pixel-based scores on DMC pendulum-swingup, read from the score files that DreamerV3's
#: authors publish for it and its baselines (github.com/danijar/dreamerv3, ``scores/dmc_vision-{dreamerv3,
#: drqv2,curl,sac}.json.gz``, commit e3f0224): per seed, the curve ``ys`` linearly interpolated at
#: ``xs`` = x (the last point where a curve ends short of 1M: 993,984 for DreamerV3, 980,000 for
#: DrQ-v2), then mean ± std over seeds. ``xs`` counts environment steps of 0.02 s (DMC's control
#: step); DreamerV3's series holds every episode (noisy: its nearest point to 100k gives 296 ± 350).
SCORE_FILES = "github.com/danijar/dreamerv3 scores/dmc_vision-*.json.gz (commit e3f0224)"
PUBLISHED: list[dict[str, object]] = [
    {"method": "DreamerV3", "steps": 100_000, "score": 336, "std": 324, "seeds": 10,
     "source": "Hafner et al., Mastering Diverse Domains through World Models (2023)"},
    {"method": "DrQ-v2", "steps": 100_000, "score": 235, "std": 212, "seeds": 9,
     "source": "Yarats et al., Mastering Visual Continuous Control (2021)"},
    {"method": "CURL", "steps": 100_000, "score": 38, "std": 64, "seeds": 10,
     "source": "Laskin et al., CURL (ICML 2020)"},
    {"method": "pixel SAC", "steps": 100_000, "score": 99, "std": 148, "seeds": 9,
     "source": "SAC from pixels, as in Laskin et al. (2020)"},
    {"method": "DreamerV3", "steps": 1_000_000, "score": 733, "std": 269, "seeds": 10,
     "source": "Hafner et al. (2023)"},
    {"method": "DrQ-v2", "steps": 1_000_000, "score": 838, "std": 36, "seeds": 9,
     "source": "Yarats et al. (2021)"},
]


def sh(*args: str, log: Path) -> None:
    """Runs a piga command as a user would; its output goes to ``log``; a failure raises (and stops the benchmark)."""
    code = logged_command(list(args), log)
    if code:
        raise PigaError(f"'{' '.join(args[:2])} ...' failed (exit {code}); see {log}")  # its own failure: not a bug here


#: Identification floor (every parameter's relative error) and its stretch goal.
ID_FLOOR, ID_STRETCH = 0.03, 0.01
#: Diagnosis floor: the named damping's relative error.
DAMPING_FLOOR = 0.05


def case_name(seed: int, variant: list[str]) -> str:
    return f"seed{seed}" + "".join(f"-{v.replace('=', '')}" for v in variant)


def flipped(variant: list[str]) -> bool:
    return any(v.startswith("flip=") and v != "flip=none" for v in variant)


class Case(NamedTuple):
    """One case of the benchmark: a seed, a variant of the pendulum (``--env-option``s), and whether it is diagnosed."""

    seed: int
    variant: list[str]
    diagnose: bool

    @property
    def name(self) -> str:
        return case_name(self.seed, self.variant)


def run_job(case: Case, work: Path, args: argparse.Namespace) -> dict[str, object]:
    """A job of the runner: :func:`run_case` of ``case``."""
    return run_case(work, case.seed, case.variant, args, case.diagnose)


def run_case(work: Path, seed: int, variant: list[str], args: argparse.Namespace, diagnose: bool) -> dict[str, object]:
    """Collect, train and control (and, with ``diagnose``, diagnose) for one seed and variant; returns its numbers."""
    name = case_name(seed, variant)
    folder = work / name
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "log.txt"
    options = [x for v in variant for x in ("--env-option", v)]
    signed = ["--signed-actuation"] if flipped(variant) else []
    data, run = folder / "data.h5", folder / "run"
    if not data.exists():
        sh("piga-collect", "--env", "piga/DMCPendulum-v0", *options, "--out", str(data), "--sequences",
           str(args.sequences), "--steps", str(args.steps), "--seed", str(1000 + seed), "--workers", "1", "--quiet", log=log)
    train(data, run, "continuous", seed, args, log, signed)
    control = folder / "control"
    if not args.skip_control and not control.with_name("control.json").exists():
        sh("piga-control", "--env", "piga/DMCPendulum-v0", *options, "--model", str(run), "--oracle", "--episodes",
           str(args.episodes), "--seed", str(args.control_seed), "--quiet", "--out", str(control), log=log)
    metrics = json.loads((run / "metrics.json").read_text())
    control_file = control.with_name("control.json")
    control_json = json.loads(control_file.read_text()) if control_file.exists() else {"results": []}
    errors = [p["relative_error"] for p in metrics["parameter_errors"].values()]
    case: dict[str, object] = {
        "case": name, "seed": seed, "variant": variant, "frames": args.sequences * args.steps,
        "preset": "continuous" + (" --signed-actuation" if signed else ""),
        "parameters": metrics["parameter_errors"], "max_relative_error": max(errors),
        "identification_floor": max(errors) <= ID_FLOOR, "identification_stretch": max(errors) <= ID_STRETCH,
        "encoder_angle_error_deg": metrics.get("angle", {}).get("mean_abs_error_deg"),
        "control": {r["agent"]: r for r in control_json["results"]}}
    if diagnose and not signed:
        case["diagnosis"] = run_diagnosis(folder, data, seed, args, log)
    return case


def train(data: Path, run: Path, preset: str, seed: int, args: argparse.Namespace, log: Path, extra: list[str]) -> None:
    """``piga-train-model`` with ``preset`` into ``run``, resumed if a checkpoint is there, skipped if finished."""
    if (run / "metrics.json").exists():
        return
    # A resumed run keeps its recipe (piga-train-model refuses recipe options with --resume).
    recipe = ["--resume"] if (run / "checkpoint.pt").exists() else ["--preset", preset, *extra]
    sh("piga-train-model", str(data), "--out", str(run), *recipe, "--epochs", str(args.epochs),
       "--seed", str(seed), "--threads", "1", "--quiet", log=log)


def run_diagnosis(folder: Path, data: Path, seed: int, args: argparse.Namespace, log: Path) -> dict[str, object]:
    """The default preset on the same file, then ``piga-diagnose`` as a user runs it; its report checked against the truth."""
    from piga.data.schema import inspect_dataset

    fast, report = folder / "fast", folder / "diagnosis"
    train(data, fast, "fast", seed, args, log, [])
    if not (report / "report.json").exists():
        sh("piga-diagnose", "--model", str(fast), "--data", str(data), "--out", str(report), "--seed", str(seed),
           *diagnose_options(args), "--quiet", log=log)
    d = json.loads((report / "report.json").read_text())
    truth = inspect_dataset(data).params
    true = {"g": float(truth["g"]), "a": float(truth["actuation_gain"]), "b": float(truth["damping"])}
    fast_metrics = json.loads((fast / "metrics.json").read_text())
    named = {e["effect"]: e for e in d["effects"]}
    damping = named.get("damping", {}).get("value")
    gap = d["gap"]
    closure, floor = gap["free_run_gap_closure"], gap["typical_free_run_mse_floor"]
    corrected = {k: float(d["corrected"][k]) for k in ("g", "a", "b") if k in d["corrected"]}
    checks = {
        "damping_within_5pct": damping is not None and abs(damping / true["b"] - 1) <= DAMPING_FLOOR,
        "no_clip": "speed_clip" not in named and "speed_clip" not in d["corrected_effects"]
                   and not any("clip" in n for n in d["notes"]) and "clip" not in d["verdict"],
        "closure_has_valid_floor": floor is not None and not gap.get("floor_note"),
        "closure_at_most_100pct": closure is not None and closure <= 1.0,
    }
    return {
        "fast_model": {k: fast_metrics["parameter_errors"][k] for k in fast_metrics["parameter_errors"]},
        "verdict": d["verdict"], "notes": d["notes"], "selected": d["corrected_effects"],
        "substeps": d["corrected"].get("substeps"), "damping": damping,
        "damping_interval": named.get("damping", {}).get("interval"), "true": true,
        "corrected": corrected,
        "corrected_errors": {k: abs(v / true[k] - 1) for k, v in corrected.items()},
        "closure": closure, "closure_raw": gap["typical_free_run_closure"], "floor": floor,
        "floor_source": gap.get("floor_source"), "floor_note": gap.get("floor_note"),
        "typical_mse_nominal": gap["typical_free_run_mse_nominal"],
        "typical_mse_corrected": gap["typical_free_run_mse_corrected"],
        "checks": checks, "floor_met": all(checks.values()),
    }


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.1f}%"


def markdown(cases: list[dict[str, object]], command: str, info: dict[str, object]) -> str:
    lines = [f"Command: `{command}`", "", f"Machine: {info['cpu']} ({info['cores']} cores), torch {info['torch']}.", "",
             "## Identification (piga-train-model --preset continuous, no labels)", "",
             "Truth in piga's form θ̈ = 1.5·g·sin θ + 3·a·u − 3·b·θ̇: g = m·g·l / (1.5·I), a = gear / (3·I), "
             "b = d / (3·I), from the file's own parameters (`piga_params()` of the variant). The continuous preset "
             "models the integration within the frame (RK4, action held) and learns b itself, so its values are "
             "those after the correction the diagnosis points to. A flipped camera or motor shows the actuation "
             f"reversed: its true a is negative, learned with `--signed-actuation`. Floor: every parameter within "
             f"{100 * ID_FLOOR:g}% (stretch goal {100 * ID_STRETCH:g}%).", "",
             "| case | preset | frames | g learned (true, error) | a learned (true, error) | b learned (true, error) "
             f"| worst | floor ≤{100 * ID_FLOOR:g}% | stretch ≤{100 * ID_STRETCH:g}% |",
             "|---|---|---|---|---|---|---|---|---|"]
    for c in cases:
        cells = []
        for key in ("g", "a", "b"):
            p = c["parameters"].get(key)
            cells.append("–" if p is None else f"{p['learned']:.4g} ({p['true']:.4g}, {100 * p['relative_error']:.2f}%)")
        lines.append(f"| {c['case']} | {c['preset']} | {c['frames']} | " + " | ".join(cells)
                     + f" | {100 * c['max_relative_error']:.2f}% | {'yes' if c['identification_floor'] else 'no'} | "
                     f"{'yes' if c['identification_stretch'] else 'no'} |")
    base = [c for c in cases if not c["variant"]]
    if base:
        worst = {k: max(c["parameters"][k]["relative_error"] for c in base if k in c["parameters"]) for k in ("g", "a", "b")}
        seeds = ", ".join(str(c["seed"]) for c in base)
        met = sum(bool(c["identification_floor"]) for c in base)
        stretch = sum(bool(c["identification_stretch"]) for c in base)
        lines += ["", f"Across seeds {seeds} of the unmodified pendulum, the worst errors are g {100 * worst['g']:.2f}%, "
                  f"a {100 * worst['a']:.2f}%, b {100 * worst['b']:.2f}%: the {100 * ID_FLOOR:g}% floor is met on {met} of "
                  f"{len(base)} seed(s), the {100 * ID_STRETCH:g}% stretch goal on {stretch} of {len(base)}."]
    variants = [c for c in cases if c["variant"]]
    if variants:
        lines += ["", "Variants (`--variant`, as `--env-option` of every command: the model XML edited, the truth from "
                  f"`piga_params()`): the {100 * ID_FLOOR:g}% floor is met on "
                  f"{sum(bool(c['identification_floor']) for c in variants)} of {len(variants)}."]
    diagnosed = [c for c in cases if "diagnosis" in c]
    if diagnosed:
        lines += ["", "## Diagnosis (piga-train-model --preset fast, then piga-diagnose on the same file)", "",
                  "The unchanged default preset (one Euler step per frame, no damping) identifies the DMC pendulum as "
                  "if it were Gymnasium's; `piga-diagnose` then reads only the file's frames and actions and names what "
                  "the model misses. Floors: damping named within 5% of the truth; no speed clip named (the file is "
                  "not from Gymnasium); the headline closure has a valid floor (a twin of the held-out data drawn by "
                  "the model's own decoder, used only when the autoencoder re-renders this camera about as well as its "
                  "training frames) and is at most 100%.", "",
                  "| case | fast model g, a (error) | selected | damping found (true, error) | corrected g, a errors "
                  "| closure (raw) | floor (rad²) | floors met |",
                  "|---|---|---|---|---|---|---|---|"]
        for c in diagnosed:
            d = c["diagnosis"]
            fm = d["fast_model"]
            fast = ", ".join(f"{fm[k]['learned']:.4g} ({100 * fm[k]['relative_error']:.1f}%)" for k in ("g", "a") if k in fm)
            selected = ", ".join(e + (f" (M = {d['substeps']})" if e == "within_frame" and d["substeps"] else "")
                                 for e in d["selected"]) or "none"
            damping = ("not named" if d["damping"] is None else
                       f"{d['damping']:.4g} ({d['true']['b']:.4g}, {100 * abs(d['damping'] / d['true']['b'] - 1):.2f}%)")
            errs = ", ".join(f"{k} {100 * d['corrected_errors'][k]:.2f}%" for k in ("g", "a") if k in d["corrected_errors"])
            floor = "none" if d["floor"] is None else f"{d['floor']:.3g} ({d['floor_source']})"
            failed = [k for k, v in d["checks"].items() if not v]
            lines.append(f"| {c['case']} | {fast} | {selected} | {damping} | {errs} | {_pct(d['closure'])} "
                         f"({_pct(d['closure_raw'])}) | {floor} | {'all' if not failed else 'no: ' + ', '.join(failed)} |")
        lines += ["", "Verdicts:", ""] + [f"- {c['case']}: {c['diagnosis']['verdict']}" for c in diagnosed]
        notes = [f"- {c['case']}: {n}" for c in diagnosed for n in [*c["diagnosis"]["notes"],
                                                                     *([c['diagnosis']['floor_note']] if c['diagnosis']['floor_note'] else [])]]
        if notes:
            lines += ["", "Notes of the reports:", "", *notes]
    controlled = [c for c in cases if c["control"]]
    if controlled:
        lines += ["", "## Swing-up from pixels, in DMC's score (10 episodes of 1000 physics steps, max 1000)", "",
                  "| case | piga mean ± std | oracle mean ± std | piga / oracle |", "|---|---|---|---|"]
    for c in controlled:
        piga, oracle = c["control"].get("piga"), c["control"].get("oracle")
        ratio = f"{100 * piga['mean'] / oracle['mean']:.1f}%" if piga and oracle and oracle["mean"] > 0 else "–"
        fmt = lambda r: "–" if r is None else f"{r['mean']:.1f} ± {r['std']:.1f}"  # noqa: E731
        lines.append(f"| {c['case']} | {fmt(piga)} | {fmt(oracle)} | {ratio} |")
    lines += ["", "## Against published pixel-based scores (pendulum-swingup)", "",
              f"Published curves read from {SCORE_FILES}; x is in environment steps of 0.02 s, the files' unit. "
              "piga learns its model from random-action frames only (no reward) at an action repeat of 2: its x "
              "counts the physics steps those frames span (2 per frame).", "",
              "| method | environment steps | score (mean ± std) | seeds | source |", "|---|---|---|---|---|"]
    rows = [(str(p["method"]), int(p["steps"]), f"{p['score']} ± {p['std']}", str(p["seeds"]), str(p["source"]))
            for p in PUBLISHED]
    for c in cases:
        piga = c["control"].get("piga")
        if piga and not c["variant"]:
            rows.append((f"piga ({c['case']}, {c['frames']:,} frames)", 2 * int(c["frames"]),
                         f"{piga['mean']:.0f} ± {piga['std']:.0f}", "1 model, 10 episodes", "this table"))
    for method, steps, score, seeds, source in sorted(rows, key=lambda r: (r[1], r[0])):
        lines.append(f"| {method} | {steps:,} | {score} | {seeds} | {source} |")
    return "\n".join(lines) + "\n"


@farm_main
def main() -> None:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", type=work_folder, required=True, help="folder for data and runs (kept, reused on a rerun)")
    p.add_argument("--out", type=out_prefix, required=True, help="OUT.json and OUT.md are written")
    p.add_argument("--seeds", type=seed_int, nargs="+", default=[0])
    p.add_argument("--variant", action="append", default=[], metavar="KEY=VALUE",
                   help="also run the pendulum with this --env-option (repeatable; each one is its own case)")
    p.add_argument("--sequences", type=positive_int, default=500)
    p.add_argument("--steps", type=positive_int, default=40)
    p.add_argument("--epochs", type=positive_int, default=16)
    p.add_argument("--episodes", type=positive_int, default=10)
    p.add_argument("--control-seed", type=seed_int, default=0)
    p.add_argument("--diagnose", choices=("first", "all", "none"), default="first",
                   help="diagnose the cases of the first seed (default), of every seed, or none")
    p.add_argument("--variant-seeds", choices=("first", "all"), default="first",
                   help="run the variants for the first seed only (default) or for every seed")
    add_diagnose_options(p)
    p.add_argument("--skip-control", action="store_true",
                   help="no control episodes (identification and diagnosis only; the control table is left out)")
    p.add_argument("--jobs", type=positive_int, default=1, help="cases run at once, each in its own process (default 1)")
    add_ray_option(p, "the cases (--work shared by every machine)")
    args = p.parse_args()
    if args.jobs < 1:
        p.error(f"--jobs must be >= 1, got {args.jobs}")
    from piga.cli.collect import dmc_config, parse_env_option

    for variant in args.variant:  # here, not in its case after the first seed's hour of work
        try:
            dmc_config([parse_env_option(variant)])
        except (ValueError, argparse.ArgumentTypeError) as exc:
            raise PigaError(f"--variant {variant}: {exc}") from None
    backend = ray_backend(p, args)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    work = Path(args.work)
    todo = []
    for seed in args.seeds:
        diagnose = args.diagnose == "all" or (args.diagnose == "first" and seed == args.seeds[0])
        variants = args.variant if args.variant_seeds == "all" or seed == args.seeds[0] else []
        todo += [Case(seed, variant, diagnose) for variant in [[], *([v] for v in variants)]]

    def finished(i: int, case: dict[str, object]) -> None:
        print(f"{todo[i].name}: max error {100 * float(case['max_relative_error']):.2f}%", flush=True)  # type: ignore[arg-type]

    cases = run_pool(functools.partial(run_job, work=work, args=args), todo, workers=args.jobs, progress=False,
                     on_result=finished, backend=backend)
    command = "python benchmarks/dmc.py " + " ".join(sys.argv[1:])
    info = machine()
    out = Path(args.out)
    write_page(out, {"command": command, "machine": info, "cases": cases, "published": PUBLISHED},
               markdown(cases, command, info))


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
