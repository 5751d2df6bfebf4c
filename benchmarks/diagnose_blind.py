"""Blind check of ``piga-diagnose``: random effects and magnitudes, labels hidden, then scored.

Cases are drawn with a seeded RNG: no effect, one candidate effect (dynamics: delay, deadzone,
saturation, gain, damping, friction, bias, speed_clip; camera: blur, shift, noise, frame_drop,
frame_delay), two of them, or an effect outside the candidate set (``cogging``, a
position-periodic torque -k·sin(4θ)). An actuator delay and a camera delay are never drawn
together: their sum could pass the largest delay the fit tries (4 steps). For each case the script collects
``--sequences`` sequences of the "real" system with ``piga.data.collect.collect``, then strips every
label from the file: the ``effects`` attribute, the effects in ``env_config``, the command line,
and ``/states``. Only then does it run the diagnosis, in a fresh process, as a user would:
``piga-diagnose --model RUN_DIR --data CASE.h5 --out REPORT_DIR``. The scorer alone reads the
labels, which it keeps in its own JSON.

    python benchmarks/diagnose_blind.py --model RUN_DIR --out results/diagnose_blind

Cases run ``--jobs`` at a time in local processes, or with ``--ray auto|HOST:PORT`` as tasks of a Ray
cluster (one CPU and one torch thread each, as with ``--jobs`` > 1: the same records either way, bar the
wall times). Each finished case is appended to OUT.json, so an interrupted run continues where it stopped.
OUT.md holds the scores: confusion matrix, top-1 accuracy, false positives on no-effect data,
coefficient and delay errors, and free-run closure.
"""

from __future__ import annotations

import functools
import json
import shlex
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np

from common import (add_diagnose_options, add_ray_option, check_piga_model, diagnose_options, farm_main, job_command,
                    machine, out_prefix, ray_backend, work_folder)
from envs.pendulum import PixelPendulumConfig
from piga.io.atomic import atomic_output, write_json, written_together
from piga.data.collect import CollectConfig, collect
from piga.io.pool import run_pool
from piga.cli.common import ArgumentParser, positive_int, seed_int

#: Candidate effects and how their magnitudes are drawn (rng -> value).
DRAWS = {
    "damping": lambda r: round(float(r.uniform(0.05, 0.3)), 3),
    "friction": lambda r: round(float(r.uniform(0.05, 0.3)), 3),
    "bias": lambda r: round(float(r.choice([-1, 1]) * r.uniform(0.1, 0.4)), 3),
    "delay": lambda r: int(r.integers(1, 4)),
    "deadzone": lambda r: round(float(r.uniform(0.2, 0.6)), 3),
    "saturation": lambda r: round(float(r.uniform(0.8, 1.5)), 3),
    "gain": lambda r: round(float(r.choice([r.uniform(0.7, 0.9), r.uniform(1.1, 1.3)])), 3),
    "speed_clip": lambda r: round(float(r.uniform(4.0, 6.0)), 3),
    "blur": lambda r: round(float(r.uniform(0.8, 2.5)), 3),
    "shift": lambda r: round(float(r.choice([-1, 1]) * r.uniform(0.8, 3.0)), 3),
    "noise": lambda r: round(float(r.uniform(4.0, 25.0)), 2),
    "frame_drop": lambda r: round(float(r.uniform(0.05, 0.3)), 3),
    "frame_delay": lambda r: int(r.integers(1, 4)),
}
#: Pairs never drawn together.
EXCLUDED_PAIRS = ({"delay", "frame_delay"},)
#: Integer-valued effects, scored as exact or not.
DISCRETE = ("delay", "frame_delay")
#: The effect outside the candidate set.
OUTSIDE = {"cogging": lambda r: round(float(r.uniform(0.3, 0.6)), 3)}


def draw_cases(n: int, seed: int, mix: str = "all") -> list[dict]:
    """``n`` cases: about 1/6 no effect, 1/2 one effect, 1/5 two effects, the rest outside the set, shuffled.

    ``mix`` "none" draws no-effect cases only (for the false-positive rate). Case i collects its
    data with seed 1000·(seed + 1) + i.
    """
    if mix == "none":
        return [{"case": i, "effects": {}, "data_seed": int(1000 * (seed + 1) + i)} for i in range(n)]
    rng = np.random.default_rng(seed)
    n_none, n_pair, n_out = max(1, n // 6), max(1, n // 5), max(1, n // 10)
    n_single = n - n_none - n_pair - n_out
    names = list(DRAWS)
    cases: list[dict] = [{"effects": {}} for _ in range(n_none)]
    singles = [names[i % len(names)] for i in range(n_single)]  # every candidate at least once when n_single >= 8
    cases += [{"effects": {e: DRAWS[e](rng)}} for e in singles]
    for _ in range(n_pair):
        a, b = rng.choice(names, 2, replace=False)
        while {str(a), str(b)} in EXCLUDED_PAIRS:
            a, b = rng.choice(names, 2, replace=False)
        cases.append({"effects": {str(a): DRAWS[str(a)](rng), str(b): DRAWS[str(b)](rng)}})
    cases += [{"effects": {"cogging": OUTSIDE["cogging"](rng)}} for _ in range(n_out)]
    order = rng.permutation(len(cases))
    return [{"case": i, **cases[j], "data_seed": int(1000 * (seed + 1) + i)} for i, j in enumerate(order)]


def truth_class(effects: dict) -> str:
    if not effects:
        return "none"
    if set(effects) & set(OUTSIDE):
        return "unexplained"
    return "+".join(sorted(effects))


def strip_labels(path: Path) -> None:
    """Removes everything that names the effects from the file (in place)."""
    with h5py.File(path, "r+") as f:
        for key in ("effects", "command"):
            if key in f.attrs:
                del f.attrs[key]
        if "env_config" in f.attrs:
            cfg = json.loads(f.attrs["env_config"])
            cfg.pop("effects", None)
            f.attrs["env_config"] = json.dumps(cfg)
        if "states" in f:
            del f["states"]


def score(case: dict, report: dict) -> dict:
    """Compares a report with the hidden truth."""
    truth = truth_class(case["effects"])
    predicted = report["verdict_class"]
    found = {e["effect"]: e for e in report["effects"]}
    first = report["effects"][0]["effect"] if report["effects"] else predicted
    if truth in ("none", "unexplained"):
        top1 = predicted == truth
    else:
        top1 = first in case["effects"] and predicted != "unexplained"
    coef = {}
    for name, value in case["effects"].items():
        if name in found and name == "shift":  # the env shifts right and down by the same p
            coef[name] = max(abs(found[name]["dx"] - value), abs(found[name]["dy"] - value)) / abs(value)
        elif name in found and name not in DISCRETE:
            coef[name] = abs(found[name]["value"] - value) / abs(value)
    delay_ok = None
    for name in DISCRETE:
        if name in case["effects"]:
            ok = name in found and found[name]["value"] == case["effects"][name]
            delay_ok = ok if delay_ok is None else (delay_ok and ok)
    return {"truth": truth, "predicted": predicted, "first": first, "top1": bool(top1), "exact": predicted == truth,
            "coefficient_error": coef, "delay_exact": delay_ok, "free_run_closure": report["gap"]["free_run_closure"],
            "free_run_gap_closure": report["gap"]["free_run_gap_closure"], "closure_basis": report["gap"]["closure_basis"],
            "mean_free_run_gap_closure": report["gap"]["mean_free_run_gap_closure"],
            "typical_free_run_closure": report["gap"]["typical_free_run_closure"],
            "verdict": report["verdict"]}


def summarize(runs: list[dict]) -> dict:
    s = [r["score"] for r in runs]
    none = [x for x in s if x["truth"] == "none"]
    coefs = [v for x in s for v in x["coefficient_error"].values()]
    delays = [x["delay_exact"] for x in s if x["delay_exact"] is not None]
    with_gap = [x["free_run_gap_closure"] for x in s if x["truth"] not in ("none", "unexplained")
                and x["free_run_gap_closure"] is not None]
    raw = [x["free_run_closure"] for x in s if x["truth"] not in ("none", "unexplained") and x["free_run_closure"] is not None]
    state = [x for x in s if x["truth"] not in ("none", "unexplained") and x.get("closure_basis") == "state"]
    mean_gap = [x["mean_free_run_gap_closure"] for x in state if x.get("mean_free_run_gap_closure") is not None]
    raw_typical = [x["typical_free_run_closure"] for x in state if x.get("typical_free_run_closure") is not None]
    return {
        "cases": len(s),
        "top1_accuracy": float(np.mean([x["top1"] for x in s])) if s else None,
        "exact_accuracy": float(np.mean([x["exact"] for x in s])) if s else None,
        "false_positive_rate_no_effect": float(np.mean([x["predicted"] != "none" for x in none])) if none else None,
        "no_effect_cases": len(none),
        "coefficient_error_median": float(np.median(coefs)) if coefs else None,
        "coefficient_error_max": float(np.max(coefs)) if coefs else None,
        "coefficients_within_10pct": float(np.mean([c <= 0.1 for c in coefs])) if coefs else None,
        "delay_exact_rate": float(np.mean(delays)) if delays else None,
        "closure_median": float(np.median(with_gap)) if with_gap else None,
        "closure_min": float(np.min(with_gap)) if with_gap else None,
        "closure_at_least_90pct": float(np.mean([c >= 0.9 for c in with_gap])) if with_gap else None,
        "raw_closure_median": float(np.median(raw)) if raw else None,
        "raw_closure_min": float(np.min(raw)) if raw else None,
        "mean_gap_closure_median": float(np.median(mean_gap)) if mean_gap else None,
        "mean_gap_closure_at_least_90pct": float(np.mean([c >= 0.9 for c in mean_gap])) if mean_gap else None,
        "raw_typical_closure_median": float(np.median(raw_typical)) if raw_typical else None,
        "raw_typical_closure_at_least_90pct": float(np.mean([c >= 0.9 for c in raw_typical])) if raw_typical else None,
        "outside_reported_unexplained": float(np.mean([x["predicted"] == "unexplained" for x in s if x["truth"] == "unexplained"]))
        if any(x["truth"] == "unexplained" for x in s) else None,
    }


def markdown(runs: list[dict], summary: dict, command: str, info: dict) -> str:
    s = [r["score"] for r in runs]
    preds = sorted({x["first"] for x in s} | {"none"})
    conf = Counter((x["truth"] if "+" not in x["truth"] else "pair", x["first"]) for x in s)
    rows = sorted({x["truth"] if "+" not in x["truth"] else "pair" for x in s})
    pct = lambda v: "–" if v is None else f"{100 * v:.0f}%"  # noqa: E731
    lines = [
        "# Blind check of piga-diagnose", "",
        f"Command: `{command}`", "",
        f"Model: `{info['model']}`. {info['sequences']} sequences x 40 frames per case. Machine: {info['machine']['cpu']}, "
        f"{info['machine']['cores']} cores.", "",
        "## Scores", "",
        "| measure | value | floor |", "|---|---|---|",
        f"| cases | {summary['cases']} | ≥ 30 |",
        f"| top-1 accuracy (first named effect is a true one; none / unexplained exact) | {pct(summary['top1_accuracy'])} | ≥ 95% |",
        f"| exact (the whole verdict right) | {pct(summary['exact_accuracy'])} | |",
        f"| false positives on no-effect data ({summary['no_effect_cases']} cases) | {pct(summary['false_positive_rate_no_effect'])} | ≤ 5% |",
        f"| coefficients within 10% | {pct(summary['coefficients_within_10pct'])} (median error {pct(summary['coefficient_error_median'])}, "
        f"max {pct(summary['coefficient_error_max'])}) | all |",
        f"| delay exact | {pct(summary['delay_exact_rate'])} | 100% |",
        f"| free-run closure (report's headline), cases with a candidate effect | median "
        f"{pct(summary['closure_median'])}, min {pct(summary['closure_min'])}, ≥ 90% in {pct(summary['closure_at_least_90pct'])} | ≥ 90% |",
        f"| raw free-run closure 1 − err_corrected / err_nominal, mean over all held-out windows, same cases | median "
        f"{pct(summary['raw_closure_median'])}, min {pct(summary['raw_closure_min'])} | |",
        f"| angle-basis cases: typical-window closure with no floor subtracted | median "
        f"{pct(summary.get('raw_typical_closure_median'))}, ≥ 90% in {pct(summary.get('raw_typical_closure_at_least_90pct'))} | |",
        f"| angle-basis cases: closure of the mean over all windows, above the twin's floor | median "
        f"{pct(summary.get('mean_gap_closure_median'))}, ≥ 90% in {pct(summary.get('mean_gap_closure_at_least_90pct'))} | |",
        f"| outside-the-set effect reported as unexplained | {pct(summary['outside_reported_unexplained'])} | 100% |", "",
        "The headline closure is the share of the gap above the floor that the correction closes, "
        "(err_nominal − err_corrected) / (err_nominal − err_floor), on the typical held-out window (the median over "
        "windows of each window's mean squared free-run angle error). The floor is the corrected model's own error on "
        "a simulated twin of the held-out data: re-simulated with the corrected physics from the same starts and "
        "actions, rendered by the simulator, read by the encoder (`piga/diagnostics/twin.py`). When a camera effect "
        "(blur, shift, noise) is found, the corrected model reads different angles from the frames, so the closure is "
        "taken in pixels instead, on the typical window, of the gap above the matched re-rendering error (a true "
        "floor: no angle renders closer).", "",
        "## Confusion (rows: truth, 'pair' for two effects; columns: first named effect or verdict)", "",
        "| truth \\ predicted | " + " | ".join(preds) + " |", "|---|" + "---|" * len(preds),
    ]
    for t in rows:
        lines.append(f"| {t} | " + " | ".join(str(conf.get((t, p), 0) or "") for p in preds) + " |")
    lines += ["", "## Cases", "", "| case | truth (hidden from the diagnosis) | verdict | top-1 | closure (basis) | raw mean closure |",
              "|---|---|---|---|---|---|"]
    for r in runs:
        eff = ", ".join(f"{k}={v}" for k, v in r["effects"].items()) or "none"
        sc = r["score"]
        lines.append(f"| {r['case']} | {eff} | {sc['verdict']} | {'yes' if sc['top1'] else '**no**'} | "
                     f"{pct(sc['free_run_gap_closure'])} ({sc.get('closure_basis', 'state')}) | {pct(sc['free_run_closure'])} |")
    return "\n".join(lines) + "\n"


def save(out: Path, command: str, info: dict, runs: list[dict], summarize: Callable[[list[dict]], dict],
         markdown: Callable[[list[dict], dict, str, dict], str]) -> dict:
    """Summarises ``runs`` and writes OUT.json (the command, ``info``, the summary and every run) and
    OUT.md (``markdown`` of the runs in case order), each atomically and both or neither; returns the summary."""
    summary = summarize(runs)
    out.parent.mkdir(parents=True, exist_ok=True)
    # the record last: a failed page keeps the previous one to continue from
    with written_together([out.with_suffix(".json"), out.with_suffix(".md")]):
        with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
            tmp.write_text(markdown(sorted(runs, key=lambda r: r["case"]), summary, command, info))
        write_json(out.with_suffix(".json"), {"command": command, **info, "summary": summary, "runs": runs},
                   overwrite=True)
    return summary


@farm_main
def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model (the nominal, identified model)")
    p.add_argument("--out", type=out_prefix, default="results/diagnose_blind")
    p.add_argument("--work", type=work_folder, default="runs/blind", help="folder for the case data and reports")
    p.add_argument("--cases", type=positive_int, default=30)
    p.add_argument("--sequences", type=positive_int, default=200)
    p.add_argument("--seed", type=seed_int, default=0)
    p.add_argument("--workers", type=positive_int, default=2, help="collection workers of one case (with --jobs 1)")
    p.add_argument("--jobs", type=positive_int, default=1,
                   help="cases run at once, each in its own process with one torch thread (a machine's cores)")
    add_ray_option(p, "the cases (each with one torch thread, as with --jobs > 1)")
    p.add_argument("--mix", choices=("all", "none"), default="all",
                   help="'all': the mix of effects; 'none': no-effect cases only (false-positive rate)")
    add_diagnose_options(p)
    args = p.parse_args()
    backend = ray_backend(p, args)
    check_piga_model(args.model)
    out, work = Path(args.out), Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    command = shlex.join(["python", *sys.argv])
    done: list[dict] = json.loads(out.with_suffix(".json").read_text())["runs"] if out.with_suffix(".json").exists() else []
    info = {"model": args.model, "sequences": args.sequences, "seed": args.seed, "mix": args.mix, "machine": machine(),
            "jobs": args.jobs, "backend": str(backend)}
    todo = [c for c in draw_cases(args.cases, args.seed, args.mix)
            if not any(r["case"] == c["case"] and r["effects"] == c["effects"] for r in done)]
    alone = args.jobs <= 1 and backend.kind == "local"  # one case at a time on this machine: all its cores
    run = functools.partial(run_case, model=args.model, work=work, sequences=args.sequences,
                            workers=args.workers if alone else 1, threads=None if alone else 1,
                            options=diagnose_options(args))

    def finished(_: int, record: dict) -> None:  # saved as each case ends, so that a stopped run continues
        done.append(record)
        done.sort(key=lambda r: r["case"])
        closure = record["score"]["free_run_closure"]  # None: the case was refused
        print(f"case {record['case']}: truth {record['effects'] or 'none'} -> {record['score']['verdict']} "
              f"({'ok' if record['score']['top1'] else 'WRONG'}, raw closure "
              f"{'n/a' if closure is None else f'{100 * closure:.1f}%'}, gap closure "
              f"{record['score']['free_run_gap_closure']})", flush=True)
        save(out, command, info, done, summarize, markdown)

    run_pool(run, todo, workers=args.jobs, progress=False, on_result=finished, backend=backend,
             names=[f"case {c['case']}" for c in todo])
    print(json.dumps(summarize(done), indent=2))
    return 0


def run_case(case: dict, model: str, work: Path, sequences: int, workers: int, threads: int | None,
             options: tuple[str, ...] = ()) -> dict:
    """Collects, strips, diagnoses (in a fresh process, ``piga-diagnose`` with ``options``) and scores one case;
    returns its record."""
    data = work / f"case{case['case']:02d}.h5"
    work.mkdir(parents=True, exist_ok=True)  # on a machine of a cluster, the first case there makes it
    t0 = time.time()
    env = PixelPendulumConfig(effects=tuple(case["effects"].items()))
    collect(replace(CollectConfig(), sequences=sequences, seed=case["data_seed"], env=env, workers=workers),
            data, overwrite=True, command="", progress=False)
    strip_labels(data)
    report = run_diagnose(model, data, work / f"case{case['case']:02d}", case["case"], threads, options)
    return {**case, "seconds": time.time() - t0,
            "score": refused(case, report) if isinstance(report, str) else score(case, report)}


def run_diagnose(model: str | Path, data: Path, report_dir: Path, case: int, threads: int | None,
                 options: tuple[str, ...] = ()) -> dict | str:
    """``piga-diagnose`` on ``data`` in a fresh process, with ``options`` (e.g. ``("--fit-starts",)``): its
    report, or the one line of its refusal (an outcome, scored as wrong). A crash (an internal error, or no
    line at all) raises."""
    done = job_command(["piga-diagnose", "--model", str(model), "--data", str(data), "--out", str(report_dir),
                           "--overwrite", "--quiet", *(["--threads", str(threads)] if threads else []), *options],
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        if "internal error" in done.stderr or not done.stderr.strip():
            raise RuntimeError(f"piga-diagnose failed on case {case}: {done.stderr.strip()}")
        return done.stderr.strip().splitlines()[-1]
    return json.loads((report_dir / "report.json").read_text())


def refused(case: dict, message: str) -> dict:
    """The score of a case that piga-diagnose refused: wrong, with its one line as the verdict."""
    truth = truth_class(case["effects"])
    return {"truth": truth, "predicted": "refused", "first": "refused", "top1": False, "exact": False,
            "coefficient_error": {}, "delay_exact": None, "free_run_closure": None, "free_run_gap_closure": None,
            "closure_basis": None, "mean_free_run_gap_closure": None, "typical_free_run_closure": None,
            "verdict": f"refused: {message}"}


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
