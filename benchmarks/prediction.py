"""Benchmark: the paper's Figure 3 from pixels: explicit physics (piga) against black-box frame predictors.

For each system it collects one small data set with ``piga-collect --system SYSTEM`` (``--sequences``, split
80/10/10, data seed 100), then trains every model of ``piga-train-model --model`` on it for each seed, all with
the same budget of optimiser steps (``--budget-steps``) and the scene's ``fast`` recipe otherwise: ``piga``
(encoder, velocity estimator, the system's physics, decoder), ``in-ig`` (an Interaction Network in place of the
physics) and ``video-lstm`` (an LSTM over per-frame codes). Each run is scored by ``piga-train-model`` itself on
the test split: SSIM and MSE per step over the T_pred predicted and the T_ext extrapolated frames.

    python benchmarks/prediction.py --out results/prediction                          # every system and model
    python benchmarks/prediction.py --out results/prediction --systems spring gravity --seeds 0 --jobs 2

Each (system, model, seed) is one job of piga's job runner (:func:`piga.io.pool.run_recorded`): one torch thread,
``--jobs N`` at once in processes of this machine, or ``--ray auto|HOST:PORT`` as tasks of a Ray cluster (the
output folder then shared by every machine). Each job's record, ``OUT_runs/records/NAME.json`` (its settings,
per-step scores, exit status, training minutes, machine and the code's commit), is written as the job ends and
is kept while its settings are the job's, so that the same command continues a stopped benchmark; data and
run folders (``OUT_runs/data``, ``OUT_runs/NAME``) are not needed once the records exist. A job whose command
fails (not a run that trained and was judged unconverged: that is recorded) ends the benchmark with one line.
Writes ``OUT.json``, ``OUT.md`` and ``OUT-ssim.png`` (SSIM per step, a panel per system, a line per model).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Literal, get_args, get_type_hints

from common import (add_training_options, farm_main, logged_command, machine, machine_words, out_prefix, ray_backend,
                    TrainingBenchConfig, write_page)

from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.world.model import ModelConfig
from piga.cli.common import ArgumentParser

#: The models of ``piga-train-model --model`` (one source: :class:`ModelConfig`'s ``architecture``).
MODELS: tuple[str, ...] = get_args(get_type_hints(ModelConfig)["architecture"])
#: Variants the benchmark can also train, by name: ``piga-train-model``'s flags for each (a capacity check:
#: VideoLSTM at twice the widths, more parameters than piga's on every system).
VARIANTS: dict[str, list[str]] = {"video-lstm-x2": ["--model", "video-lstm", "--video-lstm-scale", "2"]}
System = Literal["spring", "bouncing", "gravity", "digits-spring"]
SYSTEMS: tuple[str, ...] = get_args(System)
#: ``piga-train-model``'s exit statuses for a run that trained and wrote its metrics: converged (0), its check
#: failed ("untrained": 1, with metrics.json written) and not converged (3). They are results to compare, recorded.
RUN_EXITS = (0, 1, 3)


@dataclass(frozen=True)
class BenchConfig(TrainingBenchConfig):
    """The benchmark's settings; a job's record is kept while its part of them is unchanged."""

    systems: tuple[str, ...] = ("spring", "bouncing", "gravity")
    models: tuple[str, ...] = MODELS
    budget_steps: int = 800
    jobs: int = 2


DEFAULTS = BenchConfig()


@dataclass(frozen=True)
class Job:
    """One training run: what its worker needs."""

    name: str
    system: str
    model: str
    seed: int
    budget_steps: int
    data: Path
    run_dir: Path


def job_name(system: str, model: str, seed: int) -> str:
    return f"{system}-{model}-s{seed}"


def collect_command(system: str, cfg: BenchConfig, path: Path) -> list[str]:
    return ["piga-collect", "--system", system, "--sequences", str(cfg.sequences), "--seed", str(cfg.data_seed),
            "--out", str(path), "--quiet"]


def train_command(job: Job) -> list[str]:
    flags = VARIANTS.get(job.model, ["--model", job.model])
    # one retry where there are object slots to check: the records were made with it (video-lstm has none)
    retries = [] if "video-lstm" in job.model else ["--seed-retries", "1"]
    return ["piga-train-model", str(job.data), "--out", str(job.run_dir), *flags, "--seed", str(job.seed),
            "--budget-steps", str(job.budget_steps), *retries, "--threads", "1", "--device", "cpu", "--quiet",
            "--overwrite"]


def data_path(system: str, cfg: BenchConfig, folder: Path) -> Path:
    return folder / "data" / f"{system}-n{cfg.sequences}-seed{cfg.data_seed}.h5"


def collect_data(system: str, cfg: BenchConfig, folder: Path) -> None:
    """Collects the system's data set once with ``piga-collect`` (reused while its file exists)."""
    path = data_path(system, cfg, folder)
    if not path.exists():
        log = path.with_suffix(".log")
        code = logged_command(collect_command(system, cfg, path), log)
        if code:
            raise RuntimeError(f"'piga-collect --system {system} ...' failed (exit {code}); see {log}")


def run_training(command: list[str], run_dir: Path, log: Path, what: str) -> tuple[int, dict[str, Any]]:
    """Runs a ``piga-train-model ... --out RUN_DIR --overwrite`` command (its output appended to ``log``); its exit
    status and the metrics.json it wrote. A command that fails (not a run that trained and was judged: those are
    :data:`RUN_EXITS`) raises RuntimeError naming ``what`` and the log."""
    metrics_path = run_dir / "metrics.json"
    # The command replaces the run (--overwrite); a stale metrics.json goes first so that one left behind is this
    # run's (file times come from a coarser clock than time.time() and cannot tell a fresh file from a stale one).
    metrics_path.unlink(missing_ok=True)
    code = logged_command(command, log)
    if code not in RUN_EXITS or not metrics_path.exists():
        raise RuntimeError(f"'{what}' failed (exit {code}); see {log}")
    return code, json.loads(metrics_path.read_text())


def train_job(job: Job) -> dict[str, Any]:
    """A job of the runner: trains ``job`` with ``piga-train-model`` and returns its record's fields (the scores that
    ``piga-train-model`` wrote to metrics.json, its exit status, minutes and machine)."""
    started = time.time()
    code, m = run_training(train_command(job), job.run_dir, job.run_dir.parent / f"{job.name}.log",
                           f"piga-train-model --model {job.model}")
    print(f"{job.name}: SSIM prediction {m['frame_ssim_mean']['prediction']:.3f}, extrapolation "
          f"{_fmt(m['frame_ssim_mean']['extrapolation'])}, {m['training']['seconds'] / 60:.1f} min (exit {code})",
          flush=True)
    keep = ("model", "split", "input_frames", "pred_frames", "extrapolate_frames", "frame_ssim_per_step",
            "frame_mse_per_step", "frame_ssim_mean", "frame_mse_mean", "frame_mse_background", "parameter_errors",
            "physical_parameters", "converged")
    return {"command": " ".join(train_command(job)), "exit": code, "metrics": {k: m.get(k) for k in keep},
            "convergence": (m.get("convergence") or {}).get("outcome"), "steps": m["training"].get("steps"),
            "train_seconds": m["training"]["seconds"], "wall_seconds": time.time() - started, "machine": machine()}


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def jobs_for(cfg: BenchConfig, folder: Path) -> list[RecordedJob]:
    """Every (system, model, seed) as a recorded job, the slowest model first so that ``--jobs`` ends together."""
    slow_first = sorted(cfg.models, key=lambda m: ("video-lstm", "in-ig", "piga").index(m) if m in MODELS else 0)
    out = []
    for system in cfg.systems:
        for seed in cfg.seeds:
            for model in slow_first:
                name = job_name(system, model, seed)
                spec = {"system": system, "model": model, "seed": seed, "budget_steps": cfg.budget_steps,
                        "data": " ".join(collect_command(system, cfg, Path(f"{system}.h5")))}
                out.append(RecordedJob(name, spec, Job(name, system, model, seed, cfg.budget_steps,
                                                       data_path(system, cfg, folder), folder / name)))
    return out


def parameter_counts(cfg: BenchConfig, folder: Path) -> dict[str, dict[str, int]]:
    """Per system and model: the trainable parameters of the model ``piga-train-model --model MODEL`` builds for the
    system's data set (collected if it is not there; nothing is trained)."""
    from piga.data.schema import inspect_dataset
    from piga.training.train import model_config_for, preset_for
    from piga.world.variants import parameter_count

    counts: dict[str, dict[str, int]] = {}
    for system in cfg.systems:
        collect_data(system, cfg, folder)
        info = inspect_dataset(data_path(system, cfg, folder))
        base = model_config_for(info, preset_for("fast", info).model)
        counts[system] = {}
        for model in cfg.models:
            config = (replace(base, architecture="video-lstm", video_lstm_scale=2) if model == "video-lstm-x2"
                      else replace(base, architecture=model))
            counts[system][model] = parameter_count(config)
    return counts


def _spread(values: list[float]) -> float | None:
    """The sample standard deviation over seeds (None for one seed)."""
    return statistics.stdev(values) if len(values) > 1 else None


def summary(records: dict[str, dict[str, Any]], cfg: BenchConfig,
            counts: dict[str, dict[str, int]] | None = None) -> dict[str, dict[str, Any]]:
    """Per system and model: per-step SSIM and MSE (mean and spread over seeds), the horizons' means, and the
    model's trainable parameters (``counts``, :func:`parameter_counts`)."""
    out: dict[str, dict[str, Any]] = {}
    for system in cfg.systems:
        for model in cfg.models:
            rows = [records[job_name(system, model, seed)] for seed in cfg.seeds]
            m0 = rows[0]["metrics"]
            n_pred, steps = m0["pred_frames"], len(m0["frame_ssim_per_step"])
            entry: dict[str, Any] = {"seeds": list(cfg.seeds), "input_frames": m0["input_frames"], "pred_frames": n_pred,
                                     "extrapolate_frames": m0["extrapolate_frames"],
                                     "exits": [r["exit"] for r in rows],
                                     "parameters": (counts or {}).get(system, {}).get(model),
                                     "train_minutes": [r["train_seconds"] / 60 for r in rows]}
            for key, metric in (("ssim", "frame_ssim_per_step"), ("mse", "frame_mse_per_step")):
                per_seed = [r["metrics"][metric] for r in rows]  # seeds x steps
                entry[f"{key}_per_step"] = [statistics.fmean(s[t] for s in per_seed) for t in range(steps)]
                entry[f"{key}_spread_per_step"] = [_spread([s[t] for s in per_seed]) for t in range(steps)]
                for horizon, part in (("prediction", slice(0, n_pred)), ("extrapolation", slice(n_pred, steps))):
                    means = [statistics.fmean(s[part]) for s in per_seed if s[part]]
                    entry[f"{key}_{horizon}"] = {"mean": statistics.fmean(means) if means else None,
                                                 "spread": _spread(means), "per_seed": means}
            out.setdefault(system, {})[model] = entry
    return out


def _cell(stat: dict[str, Any], digits: int) -> str:
    if stat["mean"] is None:
        return "-"
    return _fmt(stat["mean"], digits) + (f" ± {stat['spread']:.{digits}f}" if stat["spread"] is not None else "")


def _smaller(s: dict[str, dict[str, Any]]) -> str:
    """Where VideoLSTM has fewer parameters than piga, in words."""
    where = [system for system, m in s.items() if "video-lstm" in m and "piga" in m
             and None not in (m["video-lstm"].get("parameters"), m["piga"].get("parameters"))
             and m["video-lstm"]["parameters"] < m["piga"]["parameters"]]
    if not where:
        return ""
    return ", with fewer parameters than piga's on " + ("every system" if len(where) == len(s) else ", ".join(where))


def markdown(record: dict[str, Any], out: Path) -> str:
    cfg = record["config"]
    seeds = ", ".join(map(str, cfg["seeds"]))
    lines = ["# Prediction: explicit physics against black-box frame predictors (the paper's Figure 3)", "",
             f"Reproduce (resumable: kept job records are reused): `{record['command']}`.", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Each system: one data set, `piga-collect --system SYSTEM --sequences {cfg['sequences']} "
             f"--seed {cfg['data_seed']}` (split 80/10/10). Each model trained on it with `piga-train-model DATA "
             f"--model MODEL --seed SEED --budget-steps {cfg['budget_steps']} --threads 1` (the scene's `fast` "
             f"recipe otherwise; the same windows, loss and budget for every model), seeds {seeds}. Scores are "
             "`piga-train-model`'s own, on the test split's sequences: SSIM and MSE per frame over the T_pred predicted "
             "frames (prediction) and the T_ext frames after them (extrapolation)"
             + (", mean ± standard deviation over seeds." if len(cfg["seeds"]) > 1 else ", one seed."), "",
             "| system | L, T_pred, T_ext | model | parameters | SSIM prediction | SSIM extrapolation | MSE prediction | "
             "MSE extrapolation | train min | exit |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for system, models in record["summary"].items():
        for model, e in models.items():
            lines.append(f"| {system} | {e['input_frames']}, {e['pred_frames']}, {e['extrapolate_frames']} | {model} | "
                         f"{'-' if e.get('parameters') is None else format(e['parameters'], ',')} | "
                         f"{_cell(e['ssim_prediction'], 3)} | {_cell(e['ssim_extrapolation'], 3)} | "
                         f"{_cell(e['mse_prediction'], 4)} | {_cell(e['mse_extrapolation'], 4)} | "
                         f"{', '.join(f'{m:.1f}' for m in e['train_minutes'])} | "
                         f"{', '.join(map(str, e['exits']))} |")
    lines += ["", "MSE is per pixel channel, frames in [0, 1]. Exit is `piga-train-model`'s status: 0 converged, "
              "3 not converged (a parameter still moving over the last 10% of steps, or the run stopped short), "
              "1 its check failed (piga: the physics did not train or an object was lost; a baseline: its held-out "
              "predictions did not beat drawing the background alone). "
              f"Training minutes are wall-clock with one torch thread, {cfg['jobs']} run{'s' if cfg['jobs'] != 1 else ''} at once on the machine "
              "above (which may be shared). Parameters are the trainable ones of each model as built for the system's "
              "file. Most of piga's are its decoder's template generator (as the paper's: a 200-unit layer whose "
              "output is every pixel of every object's content and mask), which IN+IG shares; VideoLSTM's sizes "
              "(32-channel convolutions, an LSTM of 256 units) are its own" + _smaller(record["summary"]) + "."
              + (" video-lstm-x2 is VideoLSTM with every width doubled (`--video-lstm-scale 2`): a capacity check at "
                 "more parameters than piga's." if "video-lstm-x2" in cfg["models"] else ""), "", f"![SSIM per step]({out.name}-ssim.png)", ""]
    return "\n".join(lines)


def ssim_figure(s: dict[str, dict[str, Any]]) -> Any:
    """SSIM per step: a panel per system, a line per model (mean over seeds, shaded ± spread), T_pred's end dotted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(s), figsize=(3.4 * len(s), 3.0), sharey=True, squeeze=False)
    for ax, (system, models) in zip(axes[0], s.items()):
        for model, e in models.items():
            steps = list(range(1, len(e["ssim_per_step"]) + 1))
            (line,) = ax.plot(steps, e["ssim_per_step"], marker=".", ms=3, label=model)
            if all(v is not None for v in e["ssim_spread_per_step"]):
                lo = [m - d for m, d in zip(e["ssim_per_step"], e["ssim_spread_per_step"])]
                hi = [m + d for m, d in zip(e["ssim_per_step"], e["ssim_spread_per_step"])]
                ax.fill_between(steps, lo, hi, color=line.get_color(), alpha=0.2, lw=0)
        n_pred = next(iter(models.values()))["pred_frames"]
        ax.axvline(n_pred + 0.5, color="grey", ls=":", lw=1)
        ax.text(n_pred + 0.5, 0.02, " extrapolation", transform=ax.get_xaxis_transform(), fontsize=7, color="grey")
        ax.set_title(system, fontsize=9)
        ax.set_xlabel("step after the input frames")
    axes[0][0].set_ylabel("SSIM (test split)")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def parser() -> argparse.ArgumentParser:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default=Path("results/prediction"),
                   help="output prefix: OUT.json, OUT.md, OUT-ssim.png; runs and records in OUT_runs/ "
                        "(default %(default)s)")
    p.add_argument("--systems", nargs="+", choices=SYSTEMS, default=list(DEFAULTS.systems),
                   help="default %(default)s")
    p.add_argument("--models", nargs="+", choices=(*MODELS, *VARIANTS), default=list(DEFAULTS.models),
                   help="default %(default)s; video-lstm-x2: VideoLSTM with --video-lstm-scale 2")
    add_training_options(p, DEFAULTS, "sequences per data set, split 80/10/10")
    return p


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = p.parse_args(argv)
    cfg = BenchConfig(systems=tuple(dict.fromkeys(args.systems)), models=tuple(dict.fromkeys(args.models)),
                      seeds=tuple(dict.fromkeys(args.seeds)), budget_steps=args.budget_steps,
                      sequences=args.sequences, jobs=args.jobs)
    backend = ray_backend(p, args)
    folder = args.out.parent / f"{args.out.name}_runs"
    records = JobRecords(folder / "records")
    jobs = jobs_for(cfg, folder)
    for system in dict.fromkeys(job.spec["system"] for job in jobs if records.kept(job.name, job.spec) is None):
        collect_data(system, cfg, folder)  # only for the jobs still to run
    done = run_recorded(train_job, jobs, records, cfg.jobs, progress=False, backend=backend)
    from piga.evaluation.plots import save_figure

    record = {"command": " ".join(["python", "benchmarks/prediction.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "config": asdict(cfg), "runs": done,
              "summary": summary(done, cfg, parameter_counts(cfg, folder))}
    save_figure(ssim_figure(record["summary"]), args.out.parent / f"{args.out.name}-ssim.png")
    write_page(args.out, record, markdown(record, args.out))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
