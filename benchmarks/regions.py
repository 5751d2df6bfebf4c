"""Benchmark: the paper's Appendix D, extrapolation to unseen image regions: piga's spatial-transformer decoder
against black-box decoders of the same object coordinates.

It collects one spring data set with ``piga-collect --system spring --half``: the balls stay in the top half of the
image in every frame of the train and valid sequences and in the input and prediction frames of the test ones, whose
extrapolation frames take a ball into the bottom half. It trains piga on it once per decoder of
``piga-train-model --decoder`` (``st``, ``deconv``, ``broadcast``, ``mlp``: the same encoder, velocity estimator,
physics, recipe and budget of optimiser steps), then scores each run's rollout of the test split: SSIM and MSE per
frame over the whole frame and over its bottom half, in the extrapolation frames, and over the bottom half of the
extrapolation frames where a ball is there (its truth has a ball pixel in the bottom half).

    python benchmarks/regions.py --out results/regions --seeds 0 --budget-steps 1650 --jobs 1

Each (decoder, seed) is one job of piga's job runner (:func:`piga.io.pool.run_recorded`), as in
``benchmarks/prediction.py``: its record, ``OUT_runs/records/NAME.json`` (settings, scores, the strip's frames,
exit status, minutes, machine and commit), is written as the job ends and kept while its settings are the job's, so
that the same command continues a stopped benchmark. Writes ``OUT.json``, ``OUT.md`` and ``OUT-strip.png`` (the
truth and each decoder's extrapolated frames of one test sequence where a ball is in the bottom half).
"""

from __future__ import annotations

import argparse
import base64
import json
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, get_args, get_type_hints

import numpy as np
from common import (add_training_options, farm_main, logged_command, machine, machine_words, out_prefix, ray_backend,
                    TrainingBenchConfig, write_page)

from prediction import run_training

from piga.cli.common import ArgumentParser, int_up_to
from piga.io.pool import JobRecords, RecordedJob, run_recorded
from piga.training.train import MAX_SEED_RETRIES
from piga.world.model import ModelConfig

#: The decoders of ``piga-train-model --decoder`` (one source: :class:`ModelConfig`'s ``decoder``).
DECODERS: tuple[str, ...] = get_args(get_type_hints(ModelConfig)["decoder"])
#: Variants beyond ``--decoder``: their ``piga-train-model`` options in its place. broadcast-w32 is the
#: spatial-broadcast decoder at twice its channels (``--broadcast-width 32``): a capacity check.
VARIANTS: dict[str, list[str]] = {"broadcast-w32": ["--decoder", "broadcast", "--broadcast-width", "32"]}
#: Frames of the strip: extrapolation frames of one test sequence with a ball in the bottom half.
STRIP_FRAMES = 6


@dataclass(frozen=True)
class BenchConfig(TrainingBenchConfig):
    """The benchmark's settings; a job's record is kept while its part of them is unchanged."""

    decoders: tuple[str, ...] = ("st", "deconv", "broadcast", "mlp")
    seed_retries: int = 1
    """``piga-train-model --seed-retries`` of every run: 1, with which the regions pages were made (the command's
    default is 3)."""


DEFAULTS = BenchConfig()


@dataclass(frozen=True)
class Job:
    """One training run: what its worker needs."""

    name: str
    decoder: str
    seed: int
    budget_steps: int
    data: Path
    run_dir: Path
    strip: tuple[int, tuple[int, ...]]
    """The strip's test sequence (its index in the split) and extrapolation steps (after the L input frames)."""
    seed_retries: int = 1


def decoder_options(decoder: str) -> list[str]:
    """``piga-train-model``'s options for a decoder of ``--decoders``: ``--decoder NAME``, or a variant's."""
    return VARIANTS.get(decoder, ["--decoder", decoder])


def job_name(decoder: str, seed: int) -> str:
    return f"spring-half-{decoder}-s{seed}"


def collect_command(cfg: BenchConfig, path: Path) -> list[str]:
    return ["piga-collect", "--system", "spring", "--half", "--sequences", str(cfg.sequences), "--seed",
            str(cfg.data_seed), "--out", str(path), "--quiet"]


def train_command(job: Job) -> list[str]:
    return ["piga-train-model", str(job.data), "--out", str(job.run_dir),
            *decoder_options(job.decoder), "--seed",
            str(job.seed), "--budget-steps", str(job.budget_steps), "--seed-retries", str(job.seed_retries), "--threads",
            "1", "--device", "cpu", "--quiet", "--overwrite"]


def data_path(cfg: BenchConfig, folder: Path) -> Path:
    return folder / "data" / f"spring-half-n{cfg.sequences}-seed{cfg.data_seed}.h5"


def collect_data(cfg: BenchConfig, folder: Path) -> Path:
    """Collects the half-spring data set once with ``piga-collect`` (reused while its file exists)."""
    path = data_path(cfg, folder)
    if not path.exists():
        log = path.with_suffix(".log")
        code = logged_command(collect_command(cfg, path), log)
        if code:
            raise RuntimeError(f"'piga-collect --system spring --half ...' failed (exit {code}); see {log}")
    return path


def bottom_occupied(frames: np.ndarray) -> np.ndarray:
    """Whether a ball shows in the bottom half of each frame, uint8 (..., H, W, C) on the black background -> (...,)."""
    half = frames.shape[-3] // 2
    return frames[..., half:, :, :].max(axis=(-3, -2, -1)) > 0


def strip_choice(data: Path, input_frames: int, pred_frames: int) -> tuple[int, tuple[int, ...]]:
    """The test sequence with the most extrapolation frames showing a ball in the bottom half, and up to
    :data:`STRIP_FRAMES` of those frames (evenly spread), as steps after the L input frames."""
    from piga.data.schema import read_sequences

    frames, _ = read_sequences(data, "test")  # (n, T, H, W, 3)
    ext = frames[:, input_frames + pred_frames :]
    occupied = bottom_occupied(ext)  # (n, T_ext)
    sequence = int(occupied.sum(axis=1).argmax())
    steps = np.flatnonzero(occupied[sequence]) + pred_frames
    picked = steps[np.linspace(0, len(steps) - 1, min(STRIP_FRAMES, len(steps))).round().astype(int)]
    return sequence, tuple(int(s) for s in dict.fromkeys(picked.tolist()))


def reference(data: Path, strip: tuple[int, tuple[int, ...]], input_frames: int,
              pred_frames: int) -> tuple[np.ndarray, dict[str, Any]]:
    """The strip's true frames (F, H, W, C) uint8, and the scores of the truth with its bottom half left empty (the
    background alone) over the test extrapolation frames whose truth shows a ball there: what a decoder that draws
    nothing in the bottom half scores."""
    from skimage.metrics import structural_similarity

    from piga.data.schema import read_sequences

    frames, _ = read_sequences(data, "test")  # (n, T, H, W, 3)
    truth = frames[strip[0], [input_frames + s for s in strip[1]]]
    ext = frames[:, input_frames + pred_frames :] / 255.0  # (n, T_ext, H, W, 3)
    half = ext.shape[2] // 2
    bottoms = ext[bottom_occupied(frames[:, input_frames + pred_frames :])][:, half:]  # (F, H/2, W, 3)
    ssim = [structural_similarity(np.zeros_like(b), b, data_range=1.0, channel_axis=-1) for b in bottoms]
    return truth, {"ssim_bottom_with_ball": float(np.mean(ssim)), "mse_bottom_with_ball": float((bottoms**2).mean())}


def score_run(run_dir: Path, data: Path, strip: tuple[int, tuple[int, ...]]) -> dict[str, Any]:
    """The run's rollout of the test split, scored per step over the whole frame and over its bottom half, and over
    the bottom halves that show a ball in truth; the decoder's parameter count; the strip's predicted frames."""
    from skimage.metrics import structural_similarity

    from piga.data.schema import read_sequences
    from piga.evaluation.evaluate import EvalConfig, rollout_frames
    from piga.io.runs import load_model

    model, _ = load_model(run_dir, any_model=True)
    cfg = model.config
    frames, actions = read_sequences(data, "test")  # (n, T, H, W, 3)
    steps = EvalConfig().frames_after_input(model, frames.shape[1])
    pred, _ = rollout_frames(model, frames, actions, steps)  # (n, S, C, H, W)
    pred = np.clip(pred.transpose(0, 1, 3, 4, 2), 0, 1)  # (n, S, H, W, C)
    truth = frames[:, cfg.input_frames : cfg.input_frames + steps] / 255.0  # (n, S, H, W, C)
    half = truth.shape[2] // 2

    def ssim(a: np.ndarray, b: np.ndarray) -> float:
        return float(structural_similarity(a, b, data_range=1.0, channel_axis=-1))

    ssim_whole = np.array([[ssim(p, t) for p, t in zip(ps, ts)] for ps, ts in zip(pred, truth)])  # (n, S)
    ssim_bottom = np.array([[ssim(p[half:], t[half:]) for p, t in zip(ps, ts)] for ps, ts in zip(pred, truth)])
    mse_whole = ((pred - truth) ** 2).mean(axis=(2, 3, 4))  # (n, S)
    mse_bottom = ((pred[:, :, half:] - truth[:, :, half:]) ** 2).mean(axis=(2, 3, 4))
    ext = slice(cfg.pred_frames, steps)
    occupied = bottom_occupied(frames[:, cfg.input_frames : cfg.input_frames + steps])[:, ext]  # (n, T_ext)
    sequence, strip_steps = strip
    return {
        "decoder_parameters": sum(p.numel() for p in model.decoder.parameters()),
        "input_frames": cfg.input_frames, "pred_frames": cfg.pred_frames, "extrapolate_frames": steps - cfg.pred_frames,
        "test_sequences": len(frames), "bottom_frames": int(occupied.sum()),
        "ssim_per_step": {"whole": ssim_whole.mean(0).tolist(), "bottom": ssim_bottom.mean(0).tolist()},
        "scores": {
            "ssim_prediction": float(ssim_whole[:, : cfg.pred_frames].mean()),
            "ssim_extrapolation": float(ssim_whole[:, ext].mean()),
            "mse_extrapolation": float(mse_whole[:, ext].mean()),
            "ssim_bottom_extrapolation": float(ssim_bottom[:, ext].mean()),
            "mse_bottom_extrapolation": float(mse_bottom[:, ext].mean()),
            "ssim_bottom_with_ball": float(ssim_bottom[:, ext][occupied].mean()) if occupied.any() else None,
            "mse_bottom_with_ball": float(mse_bottom[:, ext][occupied].mean()) if occupied.any() else None,
        },
        "strip": encode_frames((pred[sequence, list(strip_steps)] * 255).round().astype(np.uint8)),
    }


def encode_frames(frames: np.ndarray) -> dict[str, Any]:
    """uint8 frames (F, H, W, C) as a record keeps them: their shape and their bytes in base64 (a few kB, not a list
    of numbers)."""
    return {"shape": list(frames.shape), "base64": base64.b64encode(frames.tobytes()).decode("ascii")}


def decode_frames(stored: dict[str, Any]) -> np.ndarray:
    """:func:`encode_frames`' frames back, uint8 (F, H, W, C)."""
    return np.frombuffer(base64.b64decode(stored["base64"]), np.uint8).reshape(stored["shape"])


def train_job(job: Job) -> dict[str, Any]:
    """A job of the runner: trains ``job`` with ``piga-train-model``, scores its run and returns its record's fields."""
    started = time.time()
    code, m = run_training(train_command(job), job.run_dir, job.run_dir.parent / f"{job.name}.log",
                           f"piga-train-model {' '.join(decoder_options(job.decoder))}")
    scored = score_run(job.run_dir, job.data, job.strip)
    written = json.loads((job.run_dir / "config.json").read_text())  # piga-train-model's record of the run
    seeds = [*written.get("retried_seeds", []), written["train"]["seed"]]
    s = scored["scores"]
    print(f"{job.name}: SSIM extrapolation {s['ssim_extrapolation']:.3f}, bottom half with a ball "
          f"{_fmt(s['ssim_bottom_with_ball'])}, {m['training']['seconds'] / 60:.1f} min (exit {code})", flush=True)
    return {"command": " ".join(train_command(job)), "exit": code, "seeds_trained": seeds, **scored,
            "parameter_errors": m.get("parameter_errors"), "train_seconds": m["training"]["seconds"],
            "steps": m["training"].get("steps"), "wall_seconds": time.time() - started, "machine": machine()}


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def jobs_for(cfg: BenchConfig, folder: Path, strip: tuple[int, tuple[int, ...]]) -> list[RecordedJob]:
    """Every (decoder, seed) as a recorded job."""
    out = []
    for seed in cfg.seeds:
        for decoder in cfg.decoders:
            name = job_name(decoder, seed)
            spec = {"decoder": decoder, "seed": seed, "budget_steps": cfg.budget_steps,
                    "data": " ".join(collect_command(cfg, Path("spring-half.h5"))),
                    "strip": [strip[0], list(strip[1])]}
            if cfg.seed_retries != DEFAULTS.seed_retries:  # absent at 1: the records made before the option ran with 1
                spec["seed_retries"] = cfg.seed_retries
            out.append(RecordedJob(name, spec, Job(name, decoder, seed, cfg.budget_steps, data_path(cfg, folder),
                                                   folder / name, strip, cfg.seed_retries)))
    return out


def summary(records: dict[str, dict[str, Any]], cfg: BenchConfig) -> dict[str, dict[str, Any]]:
    """Per decoder: each score's mean over seeds (and the seeds' values), parameters, exits and minutes."""
    out: dict[str, dict[str, Any]] = {}
    for decoder in cfg.decoders:
        rows = [records[job_name(decoder, seed)] for seed in cfg.seeds]
        entry: dict[str, Any] = {"decoder_parameters": rows[0]["decoder_parameters"], "exits": [r["exit"] for r in rows],
                                 "train_minutes": [r["train_seconds"] / 60 for r in rows],
                                 "wall_minutes": [r["wall_seconds"] / 60 for r in rows],
                                 "parameter_errors": [r["parameter_errors"] for r in rows]}
        for key in rows[0]["scores"]:
            values = [r["scores"][key] for r in rows if r["scores"][key] is not None]
            entry[key] = {"mean": statistics.fmean(values) if values else None, "per_seed": values}
        out[decoder] = entry
    return out


def _params(errors: dict[str, Any] | None) -> str:
    """Learned physical parameters, e.g. "k 3.98, l 6.01" (``metrics.json``'s ``parameter_errors``)."""
    return ", ".join(f"{k} {v['learned']:.2f}" for k, v in errors.items()) if errors else "-"


def markdown(record: dict[str, Any], out: Path) -> str:
    cfg = record["config"]
    first = next(iter(record["runs"].values()))
    seeds = ", ".join(map(str, cfg["seeds"]))
    lines = ["# Extrapolation to unseen image regions (the paper's Appendix D)", "",
             f"Reproduce (resumable: kept job records are reused): `{record['command']}`.", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Data: `piga-collect --system spring --half --sequences {cfg['sequences']} --seed {cfg['data_seed']}` "
             "(split 80/10/10): in every frame of the train and valid sequences, and in the input and prediction "
             "frames of the test ones, the balls are wholly in the top half of the image; each test sequence's "
             f"extrapolation frames take a ball wholly into the bottom half ({first['bottom_frames']} of its "
             f"{first['test_sequences']} x {first['extrapolate_frames']} test extrapolation frames show a ball there). "
             f"Each decoder: `piga-train-model DATA --decoder DECODER --seed SEED --budget-steps {cfg['budget_steps']} "
             "--threads 1` (the spring's `fast` recipe otherwise: the same encoder, velocity estimator, physics, windows "
             f"and budget for every decoder), seeds {seeds}. Scores: the rollout of the test split from its L = "
             f"{first['input_frames']} input frames, T_pred = {first['pred_frames']}, T_ext = "
             f"{first['extrapolate_frames']}; SSIM and MSE per frame, over the whole frame and over its bottom half "
             "(16 x 32 pixels), in the extrapolation frames; 'bottom, with a ball' keeps only the extrapolation frames "
             "whose truth shows a ball in the bottom half"
             + (", means over seeds." if len(cfg["seeds"]) > 1 else ", one seed."), "",
             "| decoder | decoder parameters | SSIM prediction | SSIM extrapolation | SSIM bottom, extrapolation | "
             "SSIM bottom, with a ball | MSE extrapolation | MSE bottom, with a ball | k, l learned (true 4, 6) | train min | job min | exit |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for decoder, e in record["summary"].items():
        lines.append(f"| {decoder} | {e['decoder_parameters']:,} | {_fmt(e['ssim_prediction']['mean'])} | "
                     f"{_fmt(e['ssim_extrapolation']['mean'])} | {_fmt(e['ssim_bottom_extrapolation']['mean'])} | "
                     f"{_fmt(e['ssim_bottom_with_ball']['mean'])} | {_fmt(e['mse_extrapolation']['mean'], 4)} | "
                     f"{_fmt(e['mse_bottom_with_ball']['mean'], 4)} | "
                     f"{'; '.join(_params(p) for p in e['parameter_errors'])} | "
                     f"{', '.join(f'{m:.1f}' for m in e['train_minutes'])} | {', '.join(f'{m:.1f}' for m in e['wall_minutes'])} | "
                     f"{', '.join(map(str, e['exits']))} |")
    empty = record["empty_bottom"]
    lines.append(f"| (the bottom half left empty) | - | - | - | - | {_fmt(empty['ssim_bottom_with_ball'])} | - | "
                 f"{_fmt(empty['mse_bottom_with_ball'], 4)} | - | - | - | - |")
    tried = {name: run["seeds_trained"] for name, run in record["runs"].items() if "seeds_trained" in run}
    if tried:
        lines += ["", "Seeds trained, in turn (a try whose object check found a ball missing stopped there, at the "
                  "first checkpoint after the autoencoder's warm-up while a retry was left, or at its end): "
                  + "; ".join(f"{name}: {', '.join(map(str, seeds))}" for name, seeds in tried.items()) + "."]
    lines += ["", "The last row scores the truth with its bottom half blanked out: what drawing nothing there scores "
              "(the balls are small on a black background, so SSIM stays high; MSE tells a missing ball apart).", "",
              "The decoders (`piga-train-model --decoder`): `st`, piga's spatial-transformer decoder (its parameters "
              "are mostly the output layers of the small networks that generate its templates, as in the paper); "
              "`deconv`, an MLP to a 64 x 8 x 8 feature map and two stride-2 transposed convolutions; `broadcast`, a "
              "spatial-broadcast decoder (each object's coordinates and index tiled over the image with fixed x, y "
              "channels, stride-1 convolutions of 16 channels, objects composed by masks); `mlp`, an MLP to the frame. "
              + ("`broadcast-w32` is the spatial-broadcast decoder with 32 channels (`--broadcast-width 32`): a "
                 "capacity check. " if "broadcast-w32" in cfg["decoders"] else "")
              + "MSE is per pixel channel, frames in [0, 1]. Exit is `piga-train-model`'s status: 0 converged, 3 not "
              "converged, 1 its check failed (here: its object check found a blob the decoder does not draw, so "
              "it trained again from the start with the next seed, "
              f"`--seed-retries {cfg.get('seed_retries', 1)}`, and failed again; the scores are the last run's). Train "
              "minutes are the last run's, job minutes the whole job's (retry and scoring included), wall-clock with "
              "one torch thread, "
              f"{cfg['jobs']} run(s) at once on the machine above (which may be shared).", "",
              f"![truth and each decoder's extrapolated frames]({out.name}-strip.png)", "",
              f"The strip: test sequence {record['strip'][0]}, extrapolation steps "
              f"{', '.join(str(s + 1) for s in record['strip'][1])} after the input frames (the top row is the "
              "truth; the dotted line is the middle of the image).", ""]
    return "\n".join(lines)


def strip_figure(truth: np.ndarray, records: dict[str, np.ndarray], steps: tuple[int, ...]) -> Any:
    """Rows: the truth, then each decoder's frames (F, H, W, C) uint8; columns: the strip's steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = {"truth": truth, **records}
    fig, axes = plt.subplots(len(rows), len(steps), figsize=(1.1 * len(steps) + 0.8, 1.15 * len(rows)), squeeze=False)
    for r, (name, frames) in enumerate(rows.items()):
        for c, step in enumerate(steps):
            ax = axes[r][c]
            ax.imshow(frames[c], interpolation="nearest")
            ax.axhline(frames.shape[1] / 2 - 0.5, color="white", ls=":", lw=0.6)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f"+{step + 1}", fontsize=7)
        axes[r][0].set_ylabel(name, fontsize=8)
    fig.tight_layout()
    return fig


def parser() -> argparse.ArgumentParser:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default=Path("results/regions"),
                   help="output prefix: OUT.json, OUT.md, OUT-strip.png; runs and records in OUT_runs/ "
                        "(default %(default)s)")
    p.add_argument("--decoders", nargs="+", choices=[*DECODERS, *VARIANTS], default=list(DEFAULTS.decoders),
                   help="default %(default)s; " + "; ".join(f"{name}: {' '.join(options)}" for name, options in VARIANTS.items()))
    add_training_options(p, DEFAULTS, "sequences of the data set, split 80/10/10")
    p.add_argument("--seed-retries", type=int_up_to(MAX_SEED_RETRIES, "each retry can cost a whole run", least=0),
                   default=DEFAULTS.seed_retries,
                   help="piga-train-model --seed-retries of every run (default %(default)s, as the pages were made; "
                   "the command's own default is 3)")
    return p


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = p.parse_args(argv)
    cfg = BenchConfig(decoders=tuple(dict.fromkeys(args.decoders)), seeds=tuple(dict.fromkeys(args.seeds)),
                      budget_steps=args.budget_steps, sequences=args.sequences, jobs=args.jobs,
                      seed_retries=args.seed_retries)
    backend = ray_backend(p, args)
    folder = args.out.parent / f"{args.out.name}_runs"
    data = collect_data(cfg, folder)  # the strip's truth comes from it, so it is kept
    from piga.training.train import SCENE_PRESETS

    recipe = SCENE_PRESETS["spring"]["fast"].model
    strip = strip_choice(data, recipe.input_frames, recipe.pred_frames)
    done = run_recorded(train_job, jobs_for(cfg, folder, strip), JobRecords(folder / "records"), cfg.jobs,
                        progress=False, backend=backend)
    from piga.evaluation.plots import save_figure

    truth, empty = reference(data, strip, recipe.input_frames, recipe.pred_frames)
    first_seed = {d: decode_frames(done[job_name(d, cfg.seeds[0])]["strip"]) for d in cfg.decoders}
    runs = {name: {k: v for k, v in r.items() if k != "strip"} for name, r in done.items()}  # the frames: in the records
    record = {"command": " ".join(["python", "benchmarks/regions.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "config": asdict(cfg), "strip": [strip[0], list(strip[1])],
              "runs": runs, "summary": summary(done, cfg), "empty_bottom": empty}
    save_figure(strip_figure(truth, first_seed, strip[1]), args.out.parent / f"{args.out.name}-strip.png")
    write_page(args.out, record, markdown(record, args.out))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
