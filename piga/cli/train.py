"""``piga-train-model DATA.h5 --out RUN_DIR``: learn the world model (and g, a) from frames and actions."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path

from piga.cli.common import ArgumentParser, PigaError, command_line, nonnegative_int, positive_float, positive_int, run_cli

PROG = "piga-train-model"
OUTPUTS = ("checkpoint.pt", "metrics.json", "config.json", "rollout.png", "templates.png", "curves.png")


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=PROG, description="Train the physics-as-inverse-graphics model on a piga data file. "
                       "Writes RUN_DIR/checkpoint.pt (every epoch), metrics.json, rollout.png, templates.png, "
                       "curves.png and TensorBoard scalars in RUN_DIR/tensorboard.")
    p.add_argument("data", help="HDF5 file of piga's schema (only /frames and /actions are used for training)")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--preset", choices=["fast", "paper"], default="fast",
                   help="'fast' (default): the CPU recipe; 'paper': the paper's (RMSProp 3e-4, 1000 epochs, M=5)")
    p.add_argument("--epochs", type=positive_int, help="passes over the training windows (fast: 16)")
    p.add_argument("--max-minutes", type=positive_float, help="stop after the epoch that ends past this budget")
    p.add_argument("--batch-size", type=positive_int, help="windows per step (fast: 32)")
    p.add_argument("--lr", type=positive_float, help="network learning rate (fast: 1e-3)")
    p.add_argument("--lr-physics", type=positive_float, help="physical-parameter learning rate, log space (fast: 2e-2)")
    p.add_argument("--warmup-steps", type=nonnegative_int, help="autoencoder-only steps first (fast: 200)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of initialisation and sampling (default 0)")
    p.add_argument("--threads", type=nonnegative_int, default=0, help="torch CPU threads (default: torch's choice)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out exactly where it stopped")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier run in --out")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from piga.data import inspect_dataset
    from piga.report import write_run_report
    from piga.atomic import write_json
    from piga.runs import load_model
    from piga.train import PRESETS, TrainConfig, TrainingDiverged, model_config_for, train

    info = inspect_dataset(args.data)
    run_dir = Path(args.out)
    if run_dir.exists() and not run_dir.is_dir():
        raise PigaError(f"--out {run_dir} is a file, not a folder")
    existing = [name for name in OUTPUTS if (run_dir / name).exists()]
    if args.resume:
        if not (run_dir / "checkpoint.pt").exists():
            raise PigaError(f"--resume: {run_dir / 'checkpoint.pt'} does not exist")
        saved_model, ckpt = load_model(run_dir)
        if tuple(ckpt["data"]["image_shape"]) != info.image_shape or ckpt["data"]["system"] != info.system:
            raise PigaError(f"--resume: {args.data} ({info.system}, {info.image_shape}) does not match the run's data "
                            f"({ckpt['data']['system']}, {tuple(ckpt['data']['image_shape'])})")
    elif existing and not args.overwrite:
        raise PigaError(f"{run_dir} already holds a run ({', '.join(existing)}); pass --resume to continue it or --overwrite to replace it")
    preset = PRESETS[args.preset]
    overrides = {k: getattr(args, k) for k in ("epochs", "max_minutes", "batch_size", "lr", "lr_physics", "warmup_steps")
                 if getattr(args, k) is not None}
    if args.resume:  # the run's own recipe; only the length and the budget may change
        changed = sorted(set(overrides) - {"epochs", "max_minutes"})
        if changed:
            raise PigaError(f"--resume keeps the run's recipe; drop {', '.join('--' + c.replace('_', '-') for c in changed)}")
        train_config = replace(TrainConfig(**ckpt["train_config"]), **overrides)
        model_overrides = {}
        model_config = saved_model.config
    else:
        train_config = replace(TrainConfig(seed=args.seed, threads=args.threads), **preset.get("train", {}), **overrides)
        model_overrides = dict(preset.get("model", {}))
        model_config = model_config_for(info, model_overrides)
    needed = model_config.window
    if info.steps < needed:
        raise PigaError(f"{args.data}: sequences have {info.steps} frames; training needs at least L + T_pred = {needed}")
    if not info.split_counts["train"]:
        raise PigaError(f"{args.data}: the train split is empty")
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json(run_dir / "config.json", {"command": command_line(PROG, argv),
                                         "data": str(args.data), "train": asdict(train_config), "model": model_config.to_dict()})
    print(f"training on {args.data} ({info.split_counts['train']} train sequences x {info.steps} frames); "
          f"g and a start at {model_overrides.get('physics_init') or 'g=1, a=0.3'} -> {run_dir}")
    try:
        model, state = train(args.data, run_dir, train_config, model_overrides, resume=args.resume, progress=not args.quiet)
    except TrainingDiverged as exc:
        raise PigaError(f"training diverged: {exc}") from None
    metrics = write_run_report(model, state, args.data, run_dir)
    from piga.evaluate import summary_line

    print(f"learned: {summary_line(metrics)}")
    ssim = metrics["frame_ssim_mean"]
    print(f"SSIM: prediction {ssim['prediction']:.3f}" + (f", extrapolation {ssim['extrapolation']:.3f}" if ssim["extrapolation"] is not None else "")
          + (f"; encoder angle error {metrics['angle']['mean_abs_error_deg']:.2f} deg" if "angle" in metrics else ""))
    print(f"trained {state.epoch} epochs in {state.elapsed / 60:.1f} min; wrote {run_dir}/metrics.json and figures")
    return 0


def entry() -> None:
    run_cli(PROG, main)
