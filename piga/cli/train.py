"""``piga-train-model DATA.h5 --out RUN_DIR``: learn the world model (and g, a) from frames and actions."""

from __future__ import annotations

import contextlib
import errno
import math
import os
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, fields, replace
from pathlib import Path

from typing import TYPE_CHECKING, Any

from envs.fields import counted
from piga.cli.common import (NOT_CONVERGED, ArgumentParser, Interrupted, PigaError, add_device_option,
                             add_preset_option, check_not_demo_folder, command_line, format_default, given_options,
                             held_run_error, int_up_to, missing_folders, number_type, positive_float, positive_int,
                             record_resume, recorded_options, remove_empty_folders, remove_outputs, resume_option, run_cli,
                             seed_int, started_record, thread_count, unit_fraction)
from piga.io.atomic import OutputFolder, check_folder_target
from piga.io.checkpoint import (CHECKPOINT, RunKind, check_record_matches, check_run_files, read_run_record,
                                record_divergence, recorded_data_path, require_piga_run)
from piga.io.lock import lock_run_folder
from piga.io.replaced import ReplacedRun, replacing, settle_replaced
from piga.training.convergence import SPLIT_FIX, Need, data_fix, length_fix

if TYPE_CHECKING:
    from piga.world.model import ModelConfig

#: The recipe options a user may give; each is a TrainConfig field of the same name.
RECIPE_OPTIONS = ("epochs", "budget_steps", "max_minutes", "batch_size", "lr", "lr_physics", "warmup_fraction",
                  "curriculum_fraction", "window_stride")

PROG = "piga-train-model"
#: ``--objects``' help: the first sentence of :attr:`piga.world.model.ModelConfig.n_objects`' doc (a test checks it).
OBJECTS_HELP = "N, the object slots of the encoder, decoder and physics (balls, digits)"
#: ``--video-lstm-scale``'s help: the first sentence of :attr:`piga.world.model.ModelConfig.video_lstm_scale`' doc.
VIDEO_LSTM_SCALE_HELP = ("VideoLSTM's size: its convolution channels (32 and 64), frame latent (128) and LSTM units "
                         "(256) times this")
#: ``--broadcast-width``'s help: the first sentence of :attr:`piga.world.model.ModelConfig.broadcast_width`' doc.
BROADCAST_WIDTH_HELP = ("The spatial-broadcast decoder's convolution channels (16: the per-pixel work of every object's "
                        "maps at full resolution that a CPU affords; wider, a capacity check)")
#: ``--broadcast-width``'s largest: 256 channels of every object's full-resolution maps take about 4 GB per batch
#: of 32 windows of 32x32 frames.
MAX_BROADCAST_WIDTH = 256
#: The model options a user may give: argparse dest -> the ModelConfig field it sets (a run's own, on --resume).
MODEL_OPTIONS = {"model": "architecture", "loss": "loss", "decoder": "decoder", "objects": "n_objects",
                 "video_lstm_scale": "video_lstm_scale", "broadcast_width": "broadcast_width"}
OUTPUTS = (CHECKPOINT, "metrics.json", "config.json", "rollout.png", "templates.png", "curves.png", "tensorboard")
#: The outputs that report on a finished state of the run (written at its end, from its checkpoint).
REPORT_OUTPUTS = ("metrics.json", "rollout.png", "templates.png", "curves.png")


def build_parser() -> ArgumentParser:
    from piga.world.physics import GravityOptions  # noqa: PLC0415 (torch loads only when the command runs)
    from piga.world.physics.systems import FIXED_G_RANGE  # noqa: PLC0415
    from piga.training.train import MAX_LR, MAX_SEED_RETRIES, PRESETS, TrainConfig  # noqa: PLC0415
    from piga.io.choices import literal_fields  # noqa: PLC0415
    from piga.world.model import MAX_VIDEO_LSTM_SCALE, ModelConfig  # noqa: PLC0415
    from piga.world.encoder import MAX_OBJECTS  # noqa: PLC0415

    fast, paper = TrainConfig(), PRESETS["paper"].train

    def recipe(flag: str, field: str, type_: Any, text: str, shown: str | None = None) -> None:
        value = getattr(fast, field)
        also = f"; paper preset: {format_default(getattr(paper, field))}" if getattr(paper, field) != value else ""
        add_preset_option(p, flag, default=value, type=type_, shown=(shown or format_default(value)) + also, help=text)

    p = ArgumentParser(prog=PROG, description="Train the physics-as-inverse-graphics model (or, with --model, a "
                       "black-box baseline) on a piga data file. Writes RUN_DIR/checkpoint.pt (every epoch), metrics.json, rollout.png, templates.png, "
                       "curves.png and TensorBoard scalars in RUN_DIR/tensorboard.")
    p.add_argument("data", help="HDF5 file of piga's schema (only /frames and /actions are used for training)")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--preset", choices=sorted(PRESETS), default="fast",
                   help="'fast' (default): the CPU recipe; 'paper': the paper's (RMSProp 3e-4, 1000 epochs, M=5); "
                   "'continuous': the fast recipe for a system that moves within the frame (RK4 with the action held, "
                   "velocities read through it, a learnable damping b). For a scene (spring, gravity, ...) 'fast' and "
                   "'paper' are the scene's own (docs: Systems); the defaults shown are the pendulum's. "
                   "Explicit options override the preset.")
    recipe("--epochs", "epochs", positive_int, "passes over the training windows; the cosine schedule is planned over them",
           shown="sized from the data: the fewest that reach --budget-steps")
    recipe("--budget-steps", "budget_steps", positive_int, "optimiser steps the run is sized to when --epochs is not given "
           "(a scene's fast preset: 1650)")
    recipe("--max-minutes", "max_minutes", positive_float, "stop after the epoch that ends past this budget",
           shown="no limit")
    recipe("--batch-size", "batch_size", positive_int, "windows per step")
    learning_rate = number_type(float, lambda v: 0 < v <= MAX_LR, f"a number in (0, {MAX_LR:g}]")
    recipe("--lr", "lr", learning_rate, f"network learning rate, in (0, {MAX_LR:g}]")
    recipe("--lr-physics", "lr_physics", learning_rate, f"physical-parameter learning rate, log space, in (0, {MAX_LR:g}]")
    recipe("--warmup-fraction", "warmup_fraction", unit_fraction, "fraction of the run's steps that train the autoencoder "
           "alone, first")
    recipe("--curriculum-fraction", "curriculum_fraction", unit_fraction, "fraction of the run's steps, after the "
           "warm-up, over which the prediction horizon grows from 1 frame to T_pred (0: the full horizon at once)")
    recipe("--window-stride", "window_stride", positive_int, "frames between the start frames of a sequence's training "
           "windows: a stride of T - L - T_pred + 1 takes one window per sequence, for a file of many sequences",
           shown="1; paper preset: one window per sequence, the first, as the paper's epochs pass over its sequences")
    add_preset_option(p, "--model", choices=dict(literal_fields(ModelConfig))["architecture"],
                      default=ModelConfig().architecture,
                      help="which model: 'piga' (the physics); 'video-lstm', a black-box frame predictor (conv encoder, "
                      "LSTM over the frames' codes and the actions, deconv decoder); 'in-ig', piga's encoder, velocity "
                      "estimator and decoder with an Interaction Network in place of the physics. Both baselines train on "
                      "the same windows with the same loss and are evaluated alike, and have no physical parameters "
                      "(metrics.json says so; piga-control and piga-diagnose refuse their runs)")
    choices = dict(literal_fields(ModelConfig))
    add_preset_option(p, "--loss", choices=choices["loss"], default=ModelConfig().loss,
                      help="training scheme (the paper's Table 2 ablation): 'joint', L_pred + alpha L_rec into every part; "
                      "'pred-only', L_pred alone (no autoencoder loss, no autoencoder warm-up); 'separate', the encoder "
                      "and decoder learn from L_rec only, the velocity estimator and the physics from L_pred only. "
                      "--model video-lstm takes 'joint' or 'pred-only'")
    add_preset_option(p, "--decoder", choices=choices["decoder"], default=ModelConfig().decoder,
                      help="'st': the coordinate-consistent spatial-transformer decoder; 'mlp': the paper's black-box "
                      "decoder ablation, an MLP from the objects' coordinates to the frame; 'deconv': an MLP to a small "
                      "feature map, then transposed convolutions; 'broadcast': a spatial-broadcast decoder (each object's "
                      "coordinates tiled over the image with fixed x, y channels, stride-1 convolutions, composed by "
                      "masks). Only 'st' writes templates.png. Not with --model video-lstm")
    add_preset_option(p, "--video-lstm-scale", type=int_up_to(MAX_VIDEO_LSTM_SCALE, "its weights grow with its square: "
                      "at 32 they take tens of gigabytes with Adam's moments"), metavar="S", default=ModelConfig().video_lstm_scale,
                      help=VIDEO_LSTM_SCALE_HELP + " (ModelConfig.video_lstm_scale). Only with --model video-lstm")
    add_preset_option(p, "--broadcast-width", type=int_up_to(MAX_BROADCAST_WIDTH, "every object's maps at full "
                      "resolution: wider ones take gigabytes per batch"), metavar="W", default=ModelConfig().broadcast_width,
                      help=BROADCAST_WIDTH_HELP + " (ModelConfig.broadcast_width). Only with --decoder broadcast")
    add_preset_option(p, "--objects", type=int_up_to(MAX_OBJECTS, "a model's most object slots"), metavar="N",
                      default=None, shown="the file's",
                      help=f"{OBJECTS_HELP}, ModelConfig.n_objects, at most {MAX_OBJECTS}: instead of the count "
                      "the data file records (its n_objects attribute). A scene only: fewer "
                      "than the scene's objects leaves some unmodelled (the object check then reports an object lost, "
                      "and no seed is retried), more leaves slots empty (the paper's Appendix E)")
    p.add_argument("--signed-actuation", action="store_true",
                   help="learn the sign of a too (a in linear space, from +0.3): for a camera on the other side of the "
                   "hinge or a motor wired the other way, which flip the actuation the frames show")
    low, high = FIXED_G_RANGE  # (the library's 0, "learn g", is the option left out)
    fixed_g = number_type(float, lambda v: low <= v <= high, f"a number from {low:g} to {high:g}")
    add_preset_option(p, "--fixed-g", type=fixed_g, default=GravityOptions().fixed_g, metavar="G",
                      shown="none: learn g with unit masses",
                      help="gravity data only, the paper's m run: hold g at G (your value; the file's parameters are "
                      "never read) and learn the bodies' shared mass m instead, starting from 1/G so that the force "
                      "g·m starts at 1 as in the g run")
    p.add_argument("--data-loading", choices=dict(literal_fields(TrainConfig))["data_loading"], default=None,
                   help="'memory': load the train split's frames whole; 'stream': read them from the file through a "
                   "bounded cache, for a file larger than memory; 'auto': load when they need under 2 GiB and under a "
                   f"quarter of the available memory (default {fast.data_loading})")
    p.add_argument("--stream-cache-mb", type=positive_int, default=None, metavar="MB",
                   help="the streaming reader's cache of decompressed sequences, capped at a quarter of the available "
                   f"memory (default {fast.stream_cache_mb})")
    p.add_argument("--seed", type=seed_int, default=fast.seed, help="seed of initialisation and sampling (default %(default)s)")
    p.add_argument("--threads", type=thread_count, default=fast.threads, help="torch CPU threads (default %(default)s: torch's choice)")
    add_device_option(p, fast.device)
    p.add_argument("--seed-retries", type=int_up_to(MAX_SEED_RETRIES, "each retry can cost a whole run", least=0),
                   default=fast.seed_retries, metavar="N",
                   help="a scene whose object check finds an object missing (or a slot that draws nothing where the scene "
                   "has an object for it) is trained again from the start with the next seed, up to N times (at most "
                   f"{MAX_SEED_RETRIES}: each retry can cost a whole run); while a retry is "
                   "left, an object missing after the autoencoder's warm-up restarts the run there (default %(default)s; "
                   "a run shorter than its preset plans, by --epochs or --budget-steps, retries only when it is given; "
                   "0: never; not with --resume, nor where there are no object slots: pendulum data, --model video-lstm)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out; it may raise --epochs, --budget-steps or --max-minutes "
                   "(docs: piga-train-model; resuming replans the cosine schedule)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier run in --out")
    p.add_argument("--quiet", action="store_true", help="no progress bars (a line per checkpoint is still printed)")
    return p


def main(argv: Sequence[str] | None = None, prog: str = PROG,
         longer: Callable[[int, int, Need, int], str] | None = None) -> int:
    """``prog``: the command that trains through this one (piga-demo), which names itself in warnings and errors;
    ``longer(planned, steps, need, epochs)``: that command's own way to train longer than the ``planned`` steps in
    ``epochs`` epochs, said in place of this command's (:func:`~piga.training.convergence.length_fix`) where a run did
    not converge; or, as ``need`` says, its way to more data and then longer training (in place of
    :func:`~piga.training.convergence.data_fix`), or to a file with a test split (in place of
    :data:`~piga.training.convergence.SPLIT_FIX`)."""
    with replacing() as replaced:  # the run that --overwrite replaces: back in place if this one ends before a checkpoint
        return _main(argv, prog, replaced, longer)


def _main(argv: Sequence[str] | None, prog: str, replaced: ReplacedRun,
          longer: Callable[[int, int, Need, int], str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    options_given = given_options(parser, argv)  # the options written, at the default's value too
    from piga.io.device import resolve_device

    device = resolve_device(args.device)  # --device cuda without a GPU: one line, before anything is read
    run_dir = Path(args.out)
    check_folder_target(run_dir)
    check_not_demo_folder(run_dir)
    lock_run_folder(run_dir)  # a second command on this folder is refused until this one ends
    if (settled := settle_replaced(run_dir)) is not None:
        print(settled)
    if args.data_loading == "memory" and args.stream_cache_mb is not None:
        raise PigaError("--stream-cache-mb sizes the cache of --data-loading stream; --data-loading memory reads the "
                        "frames whole, so drop one of them")
    if args.resume and args.overwrite:
        raise PigaError("--resume continues the run in --out and --overwrite replaces it; give one of them")
    check_run_files(run_dir)  # a pipe as its checkpoint: refused now, not at the first checkpoint after an epoch
    existing = [name for name in OUTPUTS if (run_dir / name).exists()]
    has_checkpoint = (run_dir / CHECKPOINT).exists()
    if args.resume and not has_checkpoint:
        raise PigaError(f"--resume: {run_dir / CHECKPOINT} does not exist")
    if not args.resume and existing and not args.overwrite:
        if has_checkpoint:
            raise held_run_error(run_dir, RunKind.PIGA)
        raise PigaError(f"{run_dir} holds outputs of an earlier run but no checkpoint ({', '.join(existing)}); "
                        "pass --overwrite to replace them")
    from piga.io.atomic import write_json
    from piga.data.schema import DataFormatError, fingerprint, has_fingerprint, inspect_dataset
    from piga.training import report
    from piga.training.report import scene_objects, write_run_report
    from piga.io.runs import load_model
    from piga.world.physics.systems import SYSTEMS
    from piga.training.train import (TrainConfig, TrainingDiverged, check_trainable, model_config_for, physics_lr,
                                     preset_for, resolve_loading, train)

    info = inspect_dataset(args.data)
    data_at_start = fingerprint(args.data)  # a file replaced while the run trains must not be what it is scored on
    overrides = {k: getattr(args, k) for k in RECIPE_OPTIONS if getattr(args, k) is not None}
    command = command_line(PROG, argv)
    if args.resume:  # the run's own recipe and data; only the length and the budget may change
        require_piga_run(run_dir, "--resume continues a training run of the world model")
        saved_model, ckpt = load_model(run_dir, any_model=True)
        for dest, field in MODEL_OPTIONS.items():
            flag, given, own = "--" + dest.replace("_", "-"), getattr(args, dest), getattr(saved_model.config, field)
            if given is not None and given != own:
                raise PigaError(f"--resume continues the run's own {flag[2:]} ({own}); drop {flag} {given}, or train "
                                "a new run in another --out")
        data = ckpt["data"]
        trained_on = recorded_data_path(data)  # the path from here (it was recorded relative to its command's folder)
        if tuple(data["image_shape"]) != info.image_shape or data["system"] != info.system:
            raise PigaError(f"--resume: {args.data} ({info.system}, {info.image_shape}) does not match the run's data "
                            f"({data['system']}, {tuple(data['image_shape'])})")
        if "fingerprint" in data:  # a moved or copied file keeps its contents; another file is another run
            # (a run of an earlier version kept a fingerprint of the first frames only: the file is hashed as it was)
            same_data = data["fingerprint"] == data_at_start or has_fingerprint(args.data, data["fingerprint"])
        else:  # a checkpoint from before fingerprints: the same path, or a file of the same shape
            same_data = Path(trained_on).resolve() == Path(args.data).resolve() or (
                data.get("sequences") == info.n_sequences and data.get("steps") == info.steps and data["dt"] == info.dt)
        if not same_data and Path(trained_on).resolve() == Path(args.data).resolve():
            raise PigaError(f"--resume: {args.data} has changed since the run trained on it (its actions, split or "
                            "frames differ); train a new run (without --resume) to learn from the changed file")
        if not same_data:
            raise PigaError(f"--resume continues on the file the run trained on ({trained_on}), not {args.data}; "
                            "train a new run (without --resume) to learn from another file")
        if "dt" in data and not math.isclose(float(data["dt"]), info.dt, rel_tol=1e-9):  # an attribute, outside the fingerprint
            raise PigaError(f"--resume: {args.data} now says its frames are {info.dt:g} s apart; the run trained on them "
                            f"as {float(data['dt']):g} s apart (its physics steps that long): restore the file's 'dt', or "
                            "train a new run (without --resume)")
        saved = TrainConfig.from_dict(ckpt["train_config"])
        stored, why = read_run_record(run_dir)
        try:  # an edited record (training follows the checkpoint: the edit was lost without a word), or another run's
            # checkpoint put in the folder
            check_record_matches(run_dir, [(stored.get("train"), ckpt["train_config"]),
                                           (stored.get("model"), ckpt.get("model_config"))])
        except ValueError as exc:
            raise PigaError(str(exc)) from None
        started = recorded_options(build_parser(), stored.get("command")) or {}
        started_preset = started.get("preset", build_parser().get_default("preset"))  # the run's, as its command gave it
        changed = (sorted(set(overrides) - {"epochs", "budget_steps", "max_minutes"}) + (["signed_actuation"] if args.signed_actuation else [])
                   + (["fixed_g"] if args.fixed_g is not None else [])
                   + (["preset"] if "preset" in options_given and args.preset != started_preset else [])
                   # the seed it trains with, or, where retries moved it there, the one it was started with
                   + (["seed"] if "seed" in options_given and args.seed not in
                      (saved.seed, *(stored.get("retried_seeds") or [])[:1]) else [])
                   + (["seed_retries"] if "seed_retries" in options_given else [])
                   + [name for name in ("data_loading", "stream_cache_mb")
                      if getattr(args, name) is not None and getattr(args, name) != getattr(saved, name)])
        # the starting command's own values may be repeated (that command plus --resume continues the run), and the
        # checkpoint's recipe values too (a run whose config.json is lost has no starting command to read)
        changed = [name for name in changed if not (name in started and started[name] == getattr(args, name))
                   and not (name in overrides and overrides[name] == getattr(saved, name, object()))
                   # "auto", the default, on a run started without the option: the value it was started with
                   and not (name == "data_loading" and args.data_loading == "auto" and name not in started)]
        if changed:
            raise PigaError(f"--resume keeps the run's recipe; drop {', '.join('--' + c.replace('_', '-') for c in changed)}")
        # the device and the threads are not the recipe's
        train_config = replace(saved, device=args.device, **overrides,
                               **({"threads": args.threads} if "threads" in options_given else {}))
        model_config = saved_model.config
        record = _record_or_rebuilt(run_dir, stored, why)
        record_resume(record, command)
        preset = started_preset
        recipe = preset_for(preset, info)  # the length it plans, which a run started shorter is still judged by
    else:
        preset = args.preset
        recipe = preset_for(preset, info)
        reading = {name: getattr(args, name) for name in ("data_loading", "stream_cache_mb") if getattr(args, name) is not None}
        train_config = replace(recipe.train, seed=args.seed, threads=args.threads, device=args.device,
                               seed_retries=args.seed_retries, **overrides, **reading)  # explicit options win
        train_config = resolve_loading(train_config, info)  # as the run records it
        if args.stream_cache_mb is not None and train_config.data_loading == "memory":  # (it was ignored silently)
            print(f"note: --data-loading {args.data_loading or 'auto'} reads {args.data} whole (it fits in memory), so "
                  f"--stream-cache-mb {args.stream_cache_mb} is not used; give --data-loading stream to read it "
                  "through that cache")
        model_config = model_config_for(info, recipe.model)
        chosen = {field: getattr(args, dest) for dest, field in MODEL_OPTIONS.items() if getattr(args, dest) is not None}
        if args.objects is not None and info.system == "pendulum":
            raise PigaError(f"--objects: {args.data} holds pendulum data, whose model has one object (its angle); "
                            "drop --objects")
        _refuse_options_that_do_not_apply(chosen, model_config)
        # a choice another one excludes (video-lstm with --loss separate) is ModelConfig's ValueError: run_cli's one line
        model_config = replace(model_config, **chosen)
        if args.objects is not None and not report.checks_objects(model_config):  # (it was recorded, then enforced)
            raise PigaError(f"--objects sets the object slots of an object model; --model {model_config.architecture} "
                            "has none: drop --objects")
        for flag, option, value in (("--signed-actuation", "signed_actuation", args.signed_actuation or None),
                                    ("--fixed-g", "fixed_g", args.fixed_g)):
            if value is not None:
                if model_config.architecture != "piga":
                    raise PigaError(f"{flag} is an option of piga's physics; --model {model_config.architecture} has none")
                owners = [name for name, cls in SYSTEMS.items() if option in {f.name for f in fields(cls.Options)}]
                if info.system not in owners:
                    raise PigaError(f"{flag} is an option for {' and '.join(owners)} models; {args.data} holds "
                                    f"{info.system} data: drop {flag}")
                model_config = model_config.with_options(**{option: value})
        if "seed_retries" in options_given and not report.checks_objects(model_config):  # the retries follow it
            why = (f"{args.data} holds pendulum data, whose model has no object slots" if info.system == "pendulum"
                   else f"--model {model_config.architecture} has no object slots")
            raise PigaError(f"--seed-retries retries a run whose object check finds an object missing; {why} to check: "
                            "drop --seed-retries")
        record = started_record(command)
    if "budget_steps" in overrides and train_config.epochs:  # a step budget sizes only a run not given in epochs
        if "epochs" in overrides:
            raise PigaError("--epochs and --budget-steps both set the run's length (--budget-steps only when --epochs "
                            "is not given); give one of them")
        source = "the run was planned" if args.resume else f"the {args.preset} preset plans"
        raise PigaError(f"--budget-steps {train_config.budget_steps}: {source} in epochs ({train_config.epochs}), which "
                        "take the place of a step budget; give --epochs instead")
    plan = check_trainable(info, model_config, train_config)
    # a run planned shorter than its recipe (--epochs, --budget-steps): an object that its seeds did not find is first
    # the length's (a spring file trained for 20 steps was blamed on the seed alone); a resumed run too, as long as it
    # stays shorter (its advice turned to "another --seed" once resumed for a few steps more)
    recipe_steps = None
    if (args.resume or {"epochs", "budget_steps"} & set(overrides)) and report.checks_objects(model_config):
        full = check_trainable(info, model_config, replace(train_config, epochs=recipe.train.epochs,
                                                            budget_steps=recipe.train.budget_steps))
        recipe_steps = full.total_steps if full.total_steps > plan.total_steps else None
        # another seed cannot make up the length (a resumed run keeps the retries it was started with)
        if recipe_steps is not None and not args.resume and "seed_retries" not in options_given:
            train_config = replace(train_config, seed_retries=0)
    planned = ckpt.get("plan") or {} if args.resume else {}  # (a checkpoint from before plans were saved has none)
    if plan.epochs < planned.get("epochs", 0):  # the baselines' --resume refuses the same
        given = " ".join(f"--{name.replace('_', '-')} {overrides[name]}" for name in ("epochs", "budget_steps")
                         if name in overrides)
        raise PigaError(f"--resume {given}: the run already planned {planned['epochs']} epochs "
                        f"({planned['epochs'] * planned.get('steps_per_epoch', 0)} steps); --resume may raise "
                        + ("--epochs or --budget-steps" if prog == PROG else "--epochs")  # (piga-demo takes --epochs)
                        + ", never lower them")
    stood = (ckpt.get("state") or {}) if args.resume else {}  # where the resumed run stands
    trained = float(stood.get("elapsed", 0.0))
    if train_config.max_minutes and trained > train_config.max_minutes * 60 \
            and int(stood.get("epoch", 0)) < plan.epochs:  # it would stop before its first step
        raise PigaError(f"--resume: the run has trained {trained / 60:.3g} min, past its --max-minutes "
                        f"{train_config.max_minutes:g} (a budget over the run's whole life, resumes included); give a "
                        "larger --max-minutes to continue it")
    from piga.io.resources import adam_checkpoint_bytes, check_run_disk
    from piga.training.memory import check_training_fits
    from piga.world.model import ModelConfig
    from piga.world.variants import activation_bytes, build_model, parameter_count

    # sized before it is built: a model and batch too large for the memory are refused here, not killed by the kernel
    # later (frames of 1024x1024 and a batch of 4 took 24 GB)
    raised = tuple(f"--{dest.replace('_', '-')}" for dest in ("video_lstm_scale", "broadcast_width")
                   if getattr(model_config, dest) > getattr(ModelConfig, dest))
    check_training_fits(parameter_count(model_config), activation_bytes(model_config), train_config.batch_size,
                        train_config.average_fraction > 0, f"{model_config.image_size}x{model_config.image_size}", raised)
    fresh = build_model(model_config)  # its size and start values, before training builds its own
    check_run_disk(run_dir, (run_dir / CHECKPOINT).stat().st_size if args.resume else adam_checkpoint_bytes(fresh),
                   "the training run", resume=args.resume, overwrite=args.overwrite)
    record.update({"data": str(args.data), "data_folder": os.getcwd(), "train": asdict(train_config), "plan": asdict(plan),
                   "model": model_config.to_dict()})
    start = (f"{info.system} parameters start at {_start_values(fresh)}" if fresh.has_physics
             else f"a {model_config.architecture} model (no physical parameters)")
    if args.resume:  # (its first lines looked like a fresh run's)
        start = (f"continuing from epoch {int(stood.get('epoch', 0))} (step {int(stood.get('step', 0)):,}, "
                 f"{trained / 60:.1f} min trained)")
    # said here, not as a warning line on stderr: a run that then fails its checks says so in one line there
    untested = ("" if info.split_counts["test"] else "; no test sequences, so metrics.json and the figures measure the "
                "train split, which is not held out")
    print(f"training on {args.data} ({counted(info.split_counts['train'], 'train sequence')} x {info.steps} frames"
          f"{untested}); {start} -> {run_dir} (device {device})")
    print(f"plan: {plan.describe(model_config.pred_frames, fresh.has_physics, model_config.loss != 'pred-only')}")
    if train_config.data_loading == "stream":
        print(f"reading: the frames are streamed from {args.data} through a {train_config.stream_cache_mb} MiB cache, in "
              "blocks of the sequences it holds")
    if not args.resume and model_config.pred_frames < recipe.model.pred_frames:
        print(f"note: sequences of {info.steps} frames: the physics predicts {model_config.pred_frames} frames "
              f"per window, not the recipe's {recipe.model.pred_frames}")  # stdout: stderr is for what went wrong
    written: list[int] = []
    if args.overwrite and not args.resume:  # deleted at the first checkpoint; until then, put back if this run ends
        replaced.set_aside(run_dir)

    # seeds whose run lost an object and was trained again (a resumed run's too: the retries of a run interrupted
    # before its end go on after the resume; a finished run resumed for longer is the user's, and no retry drops it)
    tried: list[int] = [int(seed) for seed in record.get("retried_seeds") or []] if args.resume else []
    finished = bool(args.resume and (run_dir / "metrics.json").exists())  # its report: of this checkpoint (a later
    # command's first checkpoint removes it)
    resuming = args.resume  # this try continues the checkpoint (a retry after it starts afresh)
    early: list[int] = []  # the step of this try's object check after the warm-up, once made

    folder = OutputFolder(run_dir)  # moved or removed while the run trains: said, not made again by a later write

    def on_epoch(state: Any, model: Any) -> None:  # the first checkpoint of this command: the record goes with it
        if not written:
            with folder.kept():
                write_json(run_dir / "config.json", record)
            # the report of the state resumed from no longer describes the checkpoint: an interrupted resume left it
            # beside a newer model, which piga-diagnose then judged by the old report's numbers (and piga-control by
            # its convergence); the run that --overwrite replaces goes whole
            remove_outputs(run_dir, REPORT_OUTPUTS)
            replaced.drop()
        written.append(state.epoch)
        # with a retry left, a scene's objects are checked once the autoencoder's warm-up is over: an object not
        # found then is not found at the end either (benchmarks/warmup_objects.py), and the retry starts at once
        warmup = state.plan["warmup_steps"]
        if early or resuming or finished or not _retry_left(tried, train_config) or state.step < warmup or \
                warmup < report.WARMUP_CHECK_MIN_STEPS:
            return
        early.append(state.step)
        objects = scene_objects(model, args.data)
        if objects is not None and objects.lost and not objects.too_few_slots:
            raise _LostInWarmup(objects.ratio, state.step, state.plan["epochs"] * state.plan["steps_per_epoch"])

    def next_seed(check: str, what: str) -> None:
        """Trains again from the start with the next seed after ``check`` found ``what``: says so, and drops the
        lost try's outputs."""
        nonlocal train_config, resuming
        tried.append(train_config.seed)
        resuming = False
        train_config = replace(train_config, seed=train_config.seed + 1)
        print(f"{check}: {what}; training again from the start with seed {train_config.seed} "
              f"(retry {len(tried)} of --seed-retries {train_config.seed_retries})")
        remove_outputs(run_dir, OUTPUTS)
        record.update({"train": asdict(train_config), "retried_seeds": list(tried)})
        written.clear()

    def lost_with(ratio: float) -> str:
        return f"an object was not found with seed {train_config.seed} (a blob {ratio:.2f}x as strong as the objects)"

    missing = missing_folders(run_dir)  # what train() makes at its first checkpoint
    while True:
        # the checkpoint as it was before this try (saves replace the file, so a new one has a new identity; file
        # times alone come from a coarser clock than time.time())
        before = _identity(run_dir / CHECKPOINT)
        early.clear()
        try:
            model, state = train(args.data, run_dir, train_config, model_config, resume=resuming,
                                 progress=not args.quiet, on_epoch=on_epoch, n_objects=args.objects,
                                 data_fingerprint=data_at_start)
        except _LostInWarmup as lost_early:
            next_seed(f"object check after the autoencoder's warm-up (step {lost_early.step:,} of {lost_early.total:,})",
                      lost_with(lost_early.ratio))
            continue
        except TrainingDiverged as exc:
            if written or resuming:  # its checkpoint is this run's: the commands that read it say it diverged
                record_divergence(run_dir, f"training diverged: {exc}")
            raise PigaError(f"training diverged: {exc}") from None
        except KeyboardInterrupt:
            checkpoint = run_dir / CHECKPOINT
            if not written and checkpoint.exists() and _identity(checkpoint) != before:
                # interrupted between this command's first checkpoint and its on_epoch: the record goes with it
                write_json(run_dir / "config.json", record)
                written.append(_saved_epoch(run_dir))
                replaced.drop()
            if written or resuming:
                epoch = written[-1] if written else _saved_epoch(run_dir)
                raise Interrupted(f"{run_dir / CHECKPOINT} holds epoch {epoch}; continue with "
                                  f"{resume_option(args.overwrite)}") from None
            if tried:  # a retry stopped before its first checkpoint: the folders held only the lost try
                remove_empty_folders(missing)
            raise
        except OSError as exc:
            checkpoint = run_dir / CHECKPOINT
            if exc.errno != errno.ENOSPC or not checkpoint.exists() or not (
                    written or resuming or _identity(checkpoint) != before):
                raise
            # a full disk after this command's first checkpoint: the folder now holds a run, which the same command
            # refused ("already holds a run") where the generic line said to run it again
            replaced.drop()  # (the checkpoint is this run's)
            raise PigaError(f"the disk is full (no space left on device); {checkpoint} holds epoch "
                            f"{_saved_epoch(run_dir)}: free some space and continue with "
                            f"{resume_option(args.overwrite)}") from None
        try:
            now = fingerprint(args.data)
        except (DataFormatError, FileNotFoundError) as exc:  # removed or truncated while the run trained on it
            raise PigaError(f"{exc} now, after the run trained on it: the run in {run_dir} keeps its checkpoint, but "
                            "its evaluation reads the file; put the trained file back and run the same command with "
                            f"{resume_option(args.overwrite)}") from None
        if now != data_at_start:
            raise PigaError(f"{args.data} changed while the run trained (another file now has its name): the run in "
                            f"{run_dir} keeps its checkpoint, but its evaluation would read the new file; put the "
                            f"trained file back and run the same command with {resume_option(args.overwrite)}, or "
                            "train on the new one")
        with _report_interrupted(run_dir, state.epoch, resume=resume_option(args.overwrite)), folder.kept():
            metrics = write_run_report(model, state, args.data, run_dir,
                                       physics_lr=lambda step: physics_lr(step, state.plan, train_config))
        objects = metrics.get("objects", {})
        # another seed can find a lost object, or fill a slot that should draw one; not make room for more
        # objects than the slots, nor objects for slots beyond the scene's count
        # (not a try cut short by --max-minutes: it barely trained, and --resume continues it)
        cut_short = state.step < state.plan["epochs"] * state.plan["steps_per_epoch"]
        lost = objects.get("lost") and not objects.get("too_few_slots") and not cut_short
        empty = (objects.get("empty_slots") and not objects.get("too_many_slots") and not cut_short
                 and (metrics.get("convergence") or {}).get("outcome") == "untrained")
        if finished or not (lost or empty) or not _retry_left(tried, train_config):
            break
        next_seed("object check", lost_with(objects["ratio"]) if lost
                  else f"slot {objects['empty_slots'][0]} drew nothing with seed {train_config.seed}")
    if args.resume and not written:  # a resume that only wrote the report (no step left): its command is recorded too
        with folder.kept():
            write_json(run_dir / "config.json", record)
    convergence = metrics.get("convergence") or {"outcome": "converged"}
    from piga.evaluation.evaluate import summary_line

    with _report_interrupted(run_dir, state.epoch, written=True):  # the files are written: only the summary is cut
        print(f"learned: {summary_line(metrics)}")
        if (note := one_step_note(model, info.attrs)) is not None:
            print(note)
        if (metrics.get("parameters") or {}).get("a", 1.0) < 0:
            print("note: a < 0, the actuation is flipped: positive u turns the pendulum clockwise as the frames show it "
                  "(a camera on the other side of the hinge, or a motor wired the other way)")
        ssim = metrics["frame_ssim_mean"]
        print(f"SSIM ({metrics['split']} split): prediction {ssim['prediction']:.3f}"
              + (f", extrapolation {ssim['extrapolation']:.3f}" if ssim["extrapolation"] is not None else "")
              + (f"; encoder angle error {metrics['angle']['mean_abs_error_deg']:.2f} deg" if "angle" in metrics else "")
              # the centroid readout has no parameters: an untrained model reads 0.07 deg (the trained one 0.10)
              + (" (the centroid readout's, as small before any training: the prediction SSIM and the parameters "
                 "measure the training)" if "angle" in metrics and model_config.readout == "centroid" else ""))
        print(f"trained {counted(state.epoch, 'epoch')} ({counted(state.step, 'step')}) in {state.elapsed / 60:.1f} min; "
              f"wrote {run_dir}/metrics.json and figures")
        owner = f" (options of {PROG} {args.data} --out {run_dir})"
        reason, whose = _reason_for(convergence, prog, longer, owner, state.plan.get("epochs", state.epoch))
        if convergence["outcome"] == "untrained":
            seeds = f" (seeds {', '.join(map(str, tried))} and {train_config.seed} tried)" if tried else ""
            # (bouncing balls have physics but no parameter: it was refused as not identifying them)
            what = "identify its parameters" if model.learned_parameter_names() else "learn to predict"
            if recipe_steps is not None and (lost or empty):  # the cause, with the length's fix for the seed's
                steps = f"{state.step:,} step" + ("" if state.step == 1 else "s")
                reason = (f"{reason.split('; ')[0]}, in {'runs' if tried else 'a run'} of {steps} "
                          f"where the {preset} preset plans {recipe_steps:,} for this file: train it that long "
                          "(leave out --epochs and --budget-steps, with --overwrite or another --out) before another "
                          "--seed")
                whose = "" if prog == PROG else owner
            raise PigaError(f"the run did not {what}{seeds}: {reason}{whose}")
        if convergence["outcome"] == "unsettled":
            print(f"{prog}: warning: not converged: {reason}{whose}", file=sys.stderr)
            return NOT_CONVERGED
    return 0


def _reason_for(convergence: dict[str, Any], prog: str, longer: Callable[[int, int, Need, int], str] | None,
                whose: str, epochs: int) -> tuple[str, str]:
    """The verdict's reason as ``prog`` says it, and ``whose``, the note that names this command as the owner of the
    options it names, or "" where they are all ``prog``'s: another command training through this one (piga-demo)
    says its own way to train longer, ``longer``, and takes none of this command's options but the ones it names
    (``epochs``: the epochs the run planned)."""
    reason = convergence["reason"]
    if prog == PROG:
        return reason, ""
    own = ""
    if longer is not None:
        planned, steps = convergence["planned_steps"], convergence["steps"]
        fixes: dict[Need, str] = {"data": data_fix(planned, steps), "split": SPLIT_FIX,  # this command's own words
                                  "length": length_fix(planned, steps)}  # (the data's fix holds the length's: first)
        need = next((name for name, fix in fixes.items() if fix in reason), "length")
        own = longer(planned, steps, need, epochs)
        reason = reason.replace(fixes[need], own)
    options = set(re.findall(r"--[a-z][a-z-]*", reason)) - set(re.findall(r"--[a-z][a-z-]*", own))
    return reason, whose if options else ""


def one_step_note(model: Any, attrs: dict[str, Any]) -> str | None:
    """A note for a pendulum model of one Euler step per frame identified on a file that is not from Gymnasium's
    pendulum (dm_control's, or an imported recording): such a system moves under the held action between two frames,
    and that model reads its g and a a few percent low (dm_control's, with the fast preset: g 6.0% and a 6.4% low,
    results/dmc.md). None where the model is not such a model, or the file is Gymnasium's."""
    from piga.diagnostics.observe import from_gymnasium

    config = model.config
    if config.system != "pendulum" or config.integrator != "euler" or config.substeps != 1 or from_gymnasium(attrs):
        return None
    return ("note: this file is not from Gymnasium's pendulum, and the model steps once per frame (Euler): a system "
            "that keeps moving between frames reads g and a a few percent low this way (dm_control's: about 6%); "
            "--preset continuous models that motion, and piga-diagnose reads it off this model")


def _refuse_options_that_do_not_apply(chosen: dict[str, Any], model_config: ModelConfig) -> None:
    """Refuses a model option written for a model it does not apply to, at its default value too (``chosen``: the
    :data:`MODEL_OPTIONS` fields given; ``model_config``: the preset's, which they change). ModelConfig can only tell a
    value other than its default, so ``--decoder st --model video-lstm`` and ``--video-lstm-scale 1`` ran."""
    architecture = chosen.get("architecture", model_config.architecture)
    decoder = chosen.get("decoder", model_config.decoder)
    if "decoder" in chosen and architecture == "video-lstm":
        raise PigaError("--decoder does not apply to --model video-lstm, which draws its frames with its own network, "
                        "not an object decoder: drop --decoder")
    if "video_lstm_scale" in chosen and architecture != "video-lstm":
        raise PigaError(f"--video-lstm-scale sizes the video-lstm baseline; architecture {architecture!r} has its own "
                        "sizes: drop --video-lstm-scale, or give --model video-lstm")
    if "broadcast_width" in chosen and decoder != "broadcast":
        raise PigaError(f"--broadcast-width sizes the spatial-broadcast decoder; decoder {decoder!r} has its own sizes: "
                        "drop --broadcast-width, or give --decoder broadcast")


@contextlib.contextmanager
def _report_interrupted(run_dir: Path, epoch: int, written: bool = False, resume: str = "--resume") -> Iterator[None]:
    """Ctrl-C or SIGTERM (or a full disk) after the last checkpoint: the trained model is kept, and the line says so (not
    "nothing was written", which a rerun then contradicted: "already holds a run"). ``written``: the report is complete
    too."""
    try:
        yield
    except KeyboardInterrupt:
        if written:
            raise Interrupted(f"{run_dir} holds the finished run (epoch {epoch}) and its report") from None
        raise Interrupted(f"{run_dir / CHECKPOINT} holds the trained model (epoch {epoch}), but its report was not "
                          f"finished; run the same command with {resume} to write it") from None
    except OSError as exc:
        if exc.errno != errno.ENOSPC or written:
            raise
        raise PigaError(f"the disk is full (no space left on device); {run_dir / CHECKPOINT} holds the trained model "
                        f"(epoch {epoch}), but its report was not finished: free some space and run the same command "
                        f"with {resume} to write it") from None


def _start_values(model: Any) -> str:
    """The physical parameters a new (untrained) model starts from, e.g. "g=1, a=0.3"."""
    learned = model.learned_parameter_names()
    values = model.physical_parameters()
    return ", ".join(f"{k}={v:g}" + ("" if k in learned else " (fixed)") for k, v in values.items()
                     if k != "offset") or "(none to learn)"


def _record_or_rebuilt(run_dir: Path, record: dict[str, Any], why: str | None) -> dict[str, Any]:
    """The run's config.json as :func:`~piga.io.checkpoint.read_run_record` read it (``record``, and ``why`` it is
    unusable). When it is missing or unreadable, a record rebuilt from the checkpoint (which holds the recipe and the
    model: config.json only records them) whose first command is unknown, with a note saying so."""
    if why is None:
        return record
    print(f"{PROG}: note: {run_dir / 'config.json'} {why}; the resumed run rewrites it from the checkpoint, "
          "without the command that started the run")  # on stdout: stderr is kept for the one line of an error that may follow
    return {"command": None}


class _LostInWarmup(Exception):
    """A scene's object not found at the object check after the autoencoder's warm-up (``ratio``, the check's; at
    ``step`` of the ``total`` planned): the try stops there, and the next seed is tried."""

    def __init__(self, ratio: float, step: int, total: int):
        super().__init__(f"object lost at step {step}")
        self.ratio, self.step, self.total = ratio, step, total


def _retry_left(tried: list[int], config: Any) -> bool:
    """Whether ``--seed-retries`` allows another seed after the ``tried`` ones (and the next seed is valid)."""
    from piga.data.schema import MAX_SEED

    return len(tried) < config.seed_retries and config.seed < MAX_SEED


def _identity(path: Path) -> tuple[int, int] | None:
    """A file's inode and time in ns, or None when it is missing: a checkpoint saved since differs (saves are atomic
    replaces, so a new file has a new inode)."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns


def _saved_epoch(run_dir: Path) -> int:
    """Epochs completed in the run's checkpoint."""
    from piga.io.runs import load_model

    return int(load_model(run_dir, any_model=True)[1]["state"]["epoch"])


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
