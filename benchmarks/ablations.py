"""Benchmark: the paper's Table 2 (training scheme and decoder) and Appendix E (wrong number of object slots).

For each system (3-body gravity by default) it collects one data set with ``piga-collect --system SYSTEM``
(``--sequences``, split 80/10/10, data seed 100, as ``benchmarks/prediction.py``) and trains piga on it with the
scene's ``fast`` recipe, the same seed and the same budget of optimiser steps (``--budget-steps``) in every variant,
one training each (``--seed-retries 0``: a variant that loses an object is a result, not retried with another seed):

- Table 2, ``piga-train-model --loss {joint,pred-only,separate}`` and ``--decoder mlp`` (joint training with the
  black-box MLP decoder): the test prediction loss (MSE per pixel over the T_pred predicted frames, metrics.json's
  ``frame_mse_mean``), its ratio to joint training's, the reconstruction loss of single test frames, and the
  learned parameters with their errors;
- Appendix E, ``--objects N`` for each ``--slots`` N (2 and 4 against the scene's 3): the learned parameters,
  prediction SSIM and MSE, and a figure of what each slot's content and mask learned (the run's templates.png
  drawing, :func:`piga.training.report.template_images`), beside the run with the scene's own count (joint).

    python benchmarks/ablations.py --out results/ablations --seeds 0 --jobs 1

``--no-curriculum`` trains every run without the fast recipe's autoencoder warm-up and rollout curriculum
(``--warmup-fraction 0 --curriculum-fraction 0``: the full prediction horizon from the first step, as the paper's
recipe trains), to see whether they are why a scheme other than joint training learns here.

Each (system, variant, seed) is one job of piga's job runner (:func:`piga.io.pool.run_recorded`), as in
``benchmarks/prediction.py``: one torch thread, ``--jobs N`` at once (or ``--ray``); each job's record,
``OUT_runs/records/NAME.json`` (settings, scores, the slots' templates as a compressed array, exit status, minutes,
machine, commit), is kept while its settings are the job's, so that the same command continues a stopped
benchmark without the data and run folders. Writes ``OUT.json``, ``OUT.md`` and, with slot runs, ``OUT-slots.png``.
"""

from __future__ import annotations

import argparse
import base64
import io
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal, get_args, get_type_hints

from common import (add_ray_option, farm_main, machine, machine_words, out_prefix, ray_backend, TrainingBenchConfig,
                    write_page)
from prediction import collect_command, collect_data, data_path, run_training

from piga.cli.common import ArgumentParser, positive_int, seed_int
from piga.evaluation.objects import EMPTY_RATIO, LOST_RATIO
from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.world.model import SYSTEM_SHAPES, ModelConfig

#: The training schemes of ``piga-train-model --loss`` (one source: :class:`ModelConfig`'s ``loss``).
LOSSES: tuple[str, ...] = get_args(get_type_hints(ModelConfig)["loss"])
#: Table 2's rows: each scheme with the spatial-transformer decoder, then joint training with the MLP decoder.
SCHEMES: tuple[str, ...] = (*LOSSES, "mlp")
System = Literal["gravity", "spring"]
SYSTEMS: tuple[str, ...] = get_args(System)
#: The reference row that the others' losses are divided by, and the slot runs compared with.
REFERENCE = "joint"


@dataclass(frozen=True)
class BenchConfig(TrainingBenchConfig):
    """The benchmark's settings; a job's record is kept while its part of them is unchanged."""

    systems: tuple[str, ...] = ("gravity",)
    schemes: tuple[str, ...] = SCHEMES
    """Table 2's rows (``joint`` always runs: the others are compared with it)."""
    slots: tuple[int, ...] = (2, 4)
    """Appendix E's object slot counts (``piga-train-model --objects``), besides the scene's own."""
    curriculum: bool = True
    """False: every run trains without the autoencoder warm-up and the rollout curriculum (:data:`NO_CURRICULUM`)."""


DEFAULTS = BenchConfig()
#: The ``piga-train-model`` options of ``--no-curriculum``: the full prediction horizon from the first step.
NO_CURRICULUM = ("--warmup-fraction", "0", "--curriculum-fraction", "0")


@dataclass(frozen=True)
class Job:
    """One training run: what its worker needs."""

    name: str
    system: str
    variant: str
    seed: int
    flags: tuple[str, ...]
    """The ``piga-train-model`` options that make the variant."""
    budget_steps: int
    data: Path
    run_dir: Path


def variant_flags(variant: str) -> tuple[str, ...]:
    """``joint``/``pred-only``/``separate`` (``--loss``), ``mlp`` (``--decoder mlp``) or ``slotsN`` (``--objects N``)."""
    if variant == "mlp":
        return ("--decoder", "mlp")
    if variant.startswith("slots"):
        return ("--objects", variant[len("slots"):])
    return ("--loss", variant)


def job_flags(cfg: BenchConfig, variant: str) -> tuple[str, ...]:
    """A run's ``piga-train-model`` options: its variant's, and ``--no-curriculum``'s."""
    return variant_flags(variant) + (() if cfg.curriculum else NO_CURRICULUM)


def variants(cfg: BenchConfig, system: str) -> list[str]:
    """Every run of a system: the reference first, then the other schemes, then the slot counts other than the scene's."""
    own = SYSTEM_SHAPES[system][0]
    schemes = [REFERENCE] + [s for s in cfg.schemes if s != REFERENCE]
    return schemes + [f"slots{n}" for n in cfg.slots if n != own]


def job_name(system: str, variant: str, seed: int) -> str:
    return f"{system}-{variant}-s{seed}"


def train_command(job: Job) -> list[str]:
    return ["piga-train-model", str(job.data), "--out", str(job.run_dir), *job.flags, "--seed", str(job.seed),
            "--budget-steps", str(job.budget_steps), "--seed-retries", "0", "--threads", "1", "--device", "cpu", "--quiet",
            "--overwrite"]


def inspect_run(run_dir: Path, data: Path) -> dict[str, Any]:
    """What metrics.json does not hold: the reconstruction loss of the test split's single frames (the paper's
    L_rec column: MSE per pixel channel of decoder(encoder(frame))), and for a decoder with templates each slot's
    content⊙mask and mask at the reference pose (templates.png's), as a base64 compressed npz of uint8 arrays
    ``objects`` (N, H, W[, C]) and ``masks`` (N, H, W)."""
    import numpy as np
    import torch

    from piga.data.schema import read_sequences
    from piga.io.runs import load_model
    from piga.training.report import template_images
    from piga.world.model import frames_to_float

    model, _ = load_model(run_dir)
    frames, _ = read_sequences(data, "test")
    with torch.no_grad():
        x = frames_to_float(torch.from_numpy(np.ascontiguousarray(frames)), model.config.channels).flatten(0, 1)  # (F, C, H, W)
        rec = model.decoder(model.encode(x[:, None])[:, 0])  # (F, C, H, W)
        out: dict[str, Any] = {"reconstruction_mse": float((rec - x).square().mean())}
        if model.has_templates:
            contents, masks, _, _ = template_images(model)  # (N, H, W[, C]), (N, H, W)
            objects = contents * (masks[..., None] if contents.ndim == 4 else masks)
            buffer = io.BytesIO()
            np.savez_compressed(buffer, objects=np.round(objects * 255).astype(np.uint8),
                                masks=np.round(masks * 255).astype(np.uint8))
            out["templates"] = base64.b64encode(buffer.getvalue()).decode("ascii")
    return out


def read_templates(text: str) -> tuple[Any, Any]:
    """:func:`inspect_run`'s ``templates`` back as float arrays in [0, 1]: (objects, masks)."""
    import numpy as np

    with np.load(io.BytesIO(base64.b64decode(text))) as z:
        return z["objects"] / 255.0, z["masks"] / 255.0


def train_job(job: Job) -> dict[str, Any]:
    """A job of the runner: trains ``job`` with ``piga-train-model`` and returns its record's fields (the scores
    ``piga-train-model`` wrote to metrics.json, :func:`inspect_run`'s, its exit status, minutes and machine)."""
    started = time.time()
    code, m = run_training(train_command(job), job.run_dir, job.run_dir.parent / f"{job.name}.log",
                           f"piga-train-model {' '.join(job.flags)}")
    extra = inspect_run(job.run_dir, job.data)
    print(f"{job.name}: MSE prediction {m['frame_mse_mean']['prediction']:.5f}, parameters "
          f"{m.get('parameters')}, {m['training']['seconds'] / 60:.1f} min (exit {code})", flush=True)
    keep = ("split", "input_frames", "pred_frames", "extrapolate_frames", "frame_ssim_mean", "frame_mse_mean",
            "frame_mse_background", "parameters", "parameter_errors", "objects", "converged")
    return {"command": " ".join(train_command(job)), "exit": code, "metrics": {k: m.get(k) for k in keep}, **extra,
            "convergence": m.get("convergence") or {}, "steps": m["training"].get("steps"),
            "train_seconds": m["training"]["seconds"], "wall_seconds": time.time() - started, "machine": machine()}


def jobs_for(cfg: BenchConfig, folder: Path) -> list[RecordedJob]:
    out = []
    for system in cfg.systems:
        for seed in cfg.seeds:
            for variant in variants(cfg, system):
                name = job_name(system, variant, seed)
                flags = job_flags(cfg, variant)
                spec = {"system": system, "variant": variant, "flags": list(flags), "seed": seed,
                        "budget_steps": cfg.budget_steps,
                        "data": " ".join(collect_command(system, cfg, Path(f"{system}.h5")))}
                out.append(RecordedJob(name, spec, Job(name, system, variant, seed, flags, cfg.budget_steps,
                                                       data_path(system, cfg, folder), folder / name)))
    return out


def _mean(values: list[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return statistics.fmean(kept) if kept else None


def summary(records: dict[str, dict[str, Any]], cfg: BenchConfig) -> dict[str, dict[str, Any]]:
    """Per system and variant, means over seeds: prediction MSE (and its ratio to joint's), extrapolation MSE, SSIM,
    reconstruction MSE, each learned parameter and its relative error, the object check, the exits."""
    out: dict[str, dict[str, Any]] = {}
    for system in cfg.systems:
        rows: dict[str, Any] = {}
        for variant in variants(cfg, system):
            runs = [records[job_name(system, variant, seed)] for seed in cfg.seeds]
            metrics = [r["metrics"] for r in runs]
            names = list((metrics[0].get("parameter_errors") or {}))
            rows[variant] = {
                "flags": " ".join(job_flags(cfg, variant)),
                "mse_prediction": _mean([m["frame_mse_mean"]["prediction"] for m in metrics]),
                "mse_extrapolation": _mean([m["frame_mse_mean"]["extrapolation"] for m in metrics]),
                "ssim_prediction": _mean([m["frame_ssim_mean"]["prediction"] for m in metrics]),
                "ssim_extrapolation": _mean([m["frame_ssim_mean"]["extrapolation"] for m in metrics]),
                "mse_reconstruction": _mean([r.get("reconstruction_mse") for r in runs]),
                "parameters": {k: {"learned": _mean([m["parameter_errors"][k]["learned"] for m in metrics]),
                                   "true": metrics[0]["parameter_errors"][k]["true"],
                                   "relative_error": _mean([m["parameter_errors"][k]["relative_error"] for m in metrics])}
                               for k in names},
                "objects_lost": [bool((m.get("objects") or {}).get("lost")) for m in metrics],
                # None: a record from before the empty-slot check
                "empty_slots": [(m.get("objects") or {}).get("empty_slots") for m in metrics],
                "object_ratio": _mean([(m.get("objects") or {}).get("ratio") for m in metrics]),
                "exits": [r["exit"] for r in runs],
                "outcomes": [r["convergence"].get("outcome") for r in runs],
                "train_minutes": [r["train_seconds"] / 60 for r in runs],
            }
        reference = rows[REFERENCE]["mse_prediction"]
        for row in rows.values():
            row["ratio_to_joint"] = row["mse_prediction"] / reference if reference else None
        out[system] = rows
    return out


def _fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _parameters(row: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {p['learned']:.3g} ({100 * p['relative_error']:.1f}% off {p['true']:g})"
                     for k, p in row["parameters"].items()) or "-"


#: The paper's Table 2 (3-body gravity): test L_pred and L_rec per training scheme, in its own units.
PAPER_TABLE2 = {"pred-only": (31.4, 20.5), "separate": (28.1, 0.22), "joint": (1.39, 0.63), "mlp": (30.9, 2.87)}
ROW_NAMES = {"joint": "joint L_pred + α·L_rec", "pred-only": "only L_pred", "separate": "separate gradients",
             "mlp": "black-box (MLP) decoder, joint"}


def markdown(record: dict[str, Any], out: Path) -> str:
    cfg = record["config"]
    seeds = ", ".join(map(str, cfg["seeds"]))
    lines = ["# Ablations: training scheme and decoder (the paper's Table 2), object slots (its Appendix E)", "",
             f"Reproduce (resumable: kept job records are reused): `{record['command']}`.", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Each system: one data set, `piga-collect --system SYSTEM --sequences {cfg['sequences']} --seed "
             f"{cfg['data_seed']}` (split 80/10/10). Every variant trained on it with `piga-train-model DATA FLAGS "
             f"--seed SEED --budget-steps {cfg['budget_steps']} --seed-retries 0 --threads 1` (the scene's `fast` recipe "
             f"otherwise: the same windows, seed and budget for every variant, one training each), seeds {seeds}"
             + (" (means over seeds)." if len(cfg["seeds"]) > 1 else ", one seed.")
             + ("" if cfg.get("curriculum", True) else
                f" Every run here trains without the fast recipe's autoencoder warm-up and rollout curriculum "
                f"(`{' '.join(NO_CURRICULUM)}`): the full prediction horizon from the first step, as the paper's recipe "
                "trains.")
             + " Scores are on the test split: prediction MSE and SSIM over the T_pred predicted frames "
             "(`piga-train-model`'s metrics.json), reconstruction MSE of single frames through the encoder and "
             "decoder (L_rec without its weight). MSE is per pixel channel, frames in [0, 1]."]
    for system, rows in record["summary"].items():
        table = [name for name in rows if not name.startswith("slots")]
        lines += ["", f"## {system}: training scheme and decoder (Table 2)", "",
                  "| trained with | flags | prediction MSE | / joint | reconstruction MSE | learned parameters | "
                  "prediction SSIM | exit (outcome) | train min |" + (" paper L_pred, L_rec |" if system == "gravity" else ""),
                  "|---|---|---|---|---|---|---|---|---|" + ("---|" if system == "gravity" else "")]
        for name in table:
            r = rows[name]
            paper = PAPER_TABLE2.get(name)
            lines.append(f"| {ROW_NAMES.get(name, name)} | `{r['flags']}` | {_fmt(r['mse_prediction'], '.5f')} | "
                         f"{_fmt(r['ratio_to_joint'], '.2f')} | {_fmt(r['mse_reconstruction'], '.5f')} | {_parameters(r)} | "
                         f"{_fmt(r['ssim_prediction'], '.3f')} | "
                         + ", ".join(f"{e} ({o})" for e, o in zip(r["exits"], r["outcomes"]))
                         + f" | {', '.join(f'{m:.1f}' for m in r['train_minutes'])} |"
                         + (f" {paper[0]:g}, {paper[1]:g} |" if system == "gravity" and paper else
                            (" - |" if system == "gravity" else "")))
        slots = [name for name in rows if name.startswith("slots")]
        if slots:
            own = SYSTEM_SHAPES[system][0]
            lines += ["", f"## {system}: object slots (Appendix E; the scene has {own} objects)", "",
                      "| slots | learned parameters | prediction SSIM | prediction MSE | extrapolation MSE | "
                      "reconstruction MSE | object check (residual / objects; empty slots) | exit (outcome) |",
                      "|---|---|---|---|---|---|---|---|"]
            for name in [REFERENCE, *slots]:
                r = rows[name]
                n = own if name == REFERENCE else int(name[len("slots"):])
                lost = "lost" if any(r["objects_lost"]) else "all found"
                empty = r.get("empty_slots") or [None]
                lost += "; " + (" / ".join("not measured" if e is None else (", ".join(map(str, e)) or "none") for e in empty))
                lines.append(f"| {n} | {_parameters(r)} | {_fmt(r['ssim_prediction'], '.3f')} | "
                             f"{_fmt(r['mse_prediction'], '.5f')} | {_fmt(r['mse_extrapolation'], '.5f')} | "
                             f"{_fmt(r['mse_reconstruction'], '.5f')} | {_fmt(r['object_ratio'], '.2f')} ({lost}) | "
                             + ", ".join(f"{e} ({o})" for e, o in zip(r["exits"], r["outcomes"])) + " |")
            lines += ["", f"![contents and masks per slot]({out.name}-slots.png)"]
    lines += ["", "Exit is `piga-train-model`'s status: 0 converged, 3 not converged (a parameter still moving over the "
              "last 10% of steps), 1 its check failed (the physics did not train, or the label-free object check found "
              "a moving object that no slot renders, with fewer slots than objects that is expected, or a slot that renders "
              "nothing, which the physics still moves). The object check "
              f"is the ratio of the blurred reconstruction residual's peak to the moving content's (above {LOST_RATIO:g}: an "
              "object lost), and the slots whose removal from the reconstruction changes the frames by less than "
              f"{EMPTY_RATIO:g} of the content's peak (empty). The paper's numbers are in units it does not state, so only ratios compare with them. Training minutes are wall-clock with one torch thread on the machine above (which may "
              "be shared).", ""]
    return "\n".join(lines)


def slots_figure(record: dict[str, Any]) -> Any:
    """Per system with slot runs: a row per run (the scene's own count, then each --slots), a column per slot:
    its content⊙mask above its mask (seed = the first), as templates.png draws them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = []  # (title, objects, masks)
    seed = record["config"]["seeds"][0]
    for system, rows in record["summary"].items():
        names = [name for name in rows if name.startswith("slots")]
        for name in ([REFERENCE, *names] if names else []):
            run = record["runs"][job_name(system, name, seed)]
            if run.get("templates"):
                n = SYSTEM_SHAPES[system][0] if name == REFERENCE else int(name[len("slots"):])
                g = _parameters(rows[name])
                panels.append((f"{system}, {n} slots: {g}", *read_templates(run["templates"])))
    cols = max((len(p[1]) for p in panels), default=1)
    fig = plt.figure(figsize=(1.5 * cols + 0.3, 3.4 * max(len(panels), 1)), layout="constrained")
    for sub, (title, objects, masks) in zip(fig.subfigures(max(len(panels), 1), 1, squeeze=False)[:, 0], panels):
        axes = sub.subplots(2, cols, squeeze=False)
        for ax in axes.flat:
            ax.axis("off")
        for j in range(len(objects)):
            axes[0, j].imshow(objects[j], cmap="gray" if objects[j].ndim == 2 else None, vmin=0, vmax=1)
            axes[1, j].imshow(masks[j], cmap="gray", vmin=0, vmax=1)
            axes[0, j].set_title(f"slot {j}: m⊙c", fontsize=7)
            axes[1, j].set_title(f"slot {j}: mask m", fontsize=7)
        sub.suptitle(title, fontsize=8)
    return fig


def parser() -> argparse.ArgumentParser:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default=Path("results/ablations"),
                   help="output prefix: OUT.json, OUT.md, OUT-slots.png; runs and records in OUT_runs/ (default %(default)s)")
    p.add_argument("--systems", nargs="+", choices=SYSTEMS, default=list(DEFAULTS.systems), help="default %(default)s")
    p.add_argument("--schemes", nargs="+", choices=SCHEMES, default=list(DEFAULTS.schemes),
                   help="Table 2's rows: a --loss scheme, or 'mlp' (joint with --decoder mlp); joint always runs "
                        "(default %(default)s)")
    p.add_argument("--slots", nargs="*", type=positive_int, default=list(DEFAULTS.slots),
                   help="object slot counts to train besides the scene's own (--objects N; none: no slot runs) "
                        "(default %(default)s)")
    p.add_argument("--seeds", nargs="+", type=seed_int, default=list(DEFAULTS.seeds), help="training seeds (default %(default)s)")
    p.add_argument("--budget-steps", type=positive_int, default=DEFAULTS.budget_steps,
                   help="optimiser steps of every run (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=DEFAULTS.sequences,
                   help="sequences per data set, split 80/10/10 (default %(default)s)")
    p.add_argument("--jobs", type=positive_int, default=DEFAULTS.jobs,
                   help="runs trained at once, each in its own process with one torch thread (default %(default)s)")
    p.add_argument("--no-curriculum", action="store_true",
                   help=f"train every run with {' '.join(NO_CURRICULUM)}: no autoencoder warm-up, the full prediction "
                   "horizon from the first step, as the paper's recipe trains")
    add_ray_option(p, "the training runs (OUT_runs/ shared by every machine)")
    return p


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = p.parse_args(argv)
    cfg = BenchConfig(systems=tuple(dict.fromkeys(args.systems)), schemes=tuple(dict.fromkeys(args.schemes)),
                      slots=tuple(dict.fromkeys(args.slots)), seeds=tuple(dict.fromkeys(args.seeds)),
                      budget_steps=args.budget_steps, sequences=args.sequences, jobs=args.jobs,
                      curriculum=not args.no_curriculum)
    backend = ray_backend(p, args)
    folder = args.out.parent / f"{args.out.name}_runs"
    records = JobRecords(folder / "records")
    jobs = jobs_for(cfg, folder)
    for system in dict.fromkeys(job.spec["system"] for job in jobs if records.kept(job.name, job.spec) is None):
        collect_data(system, cfg, folder)  # only for the jobs still to run
    done = run_recorded(train_job, jobs, records, cfg.jobs, progress=False, backend=backend)
    from piga.evaluation.plots import save_figure

    record = {"command": " ".join(["python", "benchmarks/ablations.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "config": asdict(cfg),
              "runs": done,
              "summary": summary(done, cfg)}
    if any(name.startswith("slots") for rows in record["summary"].values() for name in rows):  # else nothing to draw
        save_figure(slots_figure(record), args.out.parent / f"{args.out.name}-slots.png")
    write_page(args.out, record, markdown(record, args.out))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
