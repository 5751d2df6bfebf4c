"""``piga-baseline {planet,ddpg}``: train a baseline into a run folder that ``piga-control --model`` evaluates.

- ``piga-baseline planet DATA.h5 --out RUN_DIR``: the PlaNet-style world model on a data file's
  random-action sequences (it needs ``/rewards``).
- ``piga-baseline ddpg --obs {pixels,latent,state} --steps N --out RUN_DIR``: SB3 DDPG with the SB3
  zoo's Pendulum-v1 hyperparameters; ``latent`` first trains an autoencoder on ``--data``'s frames.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import typing
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, get_args

from envs.fields import counted
from piga.cli.common import (NOT_CONVERGED, ArgumentParser, Interrupted, PigaError, add_device_option, add_preset_option,
                             check_not_demo_folder, command_line, format_default, given_options, held_run_error,
                             int_up_to, made_folder, nonnegative_float, nonnegative_int, number_type, positive_float, positive_int,
                             record_resume, recorded_options, remove_outputs, resume_option, run_cli, seed_int, started_record,
                             thread_count, with_flags)
from piga.io.atomic import check_folder_target
from piga.io.checkpoint import (CHECKPOINT, RUN_OUTPUTS, RunKind, check_run_files, checkpoint_kind, read_run_record,
                                record_divergence, recorded_path)
from piga.io.lock import lock_run_folder
from piga.io.replaced import ReplacedRun, replacing, settle_replaced

PROG = "piga-baseline"
OUTPUTS = (CHECKPOINT, "config.json", "metrics.json", "model.zip", "autoencoder.pt", "tensorboard", "collected.h5",
           "replay_buffers", "openloop.png")


def build_parser() -> ArgumentParser:
    from agents.planet.config import MAX_EXPLORATION_NOISE, IterativeConfig, PlanetTrainConfig, RewardAlignment, RSSMConfig
    from agents.sb3.autoencoder import MAX_STEPS as MAX_AUTOENCODER_STEPS
    from agents.sb3.autoencoder import AutoencoderConfig
    from agents.sb3.config import (ALGORITHM_PRESETS, ALGORITHMS, DRQV2_SEED_FRAMES, ENV_ACTION_REPEAT, LEARNED_RETURN,
                                   MAX_LEARNING_RATE, OBSERVATIONS, PRECISIONS, PRESETS, VIEWS, SB3Config)
    from envs import DMC_PENDULUM, ENV_IDS

    p = ArgumentParser(prog=PROG, description="Train a baseline (the PlaNet-style world model, or SB3 DDPG) into a run "
                       "folder that piga-control --model evaluates like a piga run.")
    sub = p.add_subparsers(dest="baseline", required=True, metavar="{planet,ddpg}")

    planet, rssm = PlanetTrainConfig(), RSSMConfig()
    q = sub.add_parser("planet", help="the PlaNet-style RSSM with latent CEM, trained on a data file's random-action sequences",
                       description="Train the PlaNet-style world model (RSSM) on DATA.h5's train split (frames, actions and "
                       "/rewards). Writes RUN_DIR/checkpoint.pt, config.json, metrics.json and tensorboard/. A run whose model "
                       "reconstructs the frames it filters no better than the average frame, or predicts rewards no "
                       "better than 0, keeps them and exits 1, saying it did not learn.")
    q.error = p.error  # type: ignore[method-assign]  (one-line usage errors, as the main parser's)
    q.add_argument("data", help="HDF5 file of piga's schema with /rewards (piga-collect writes them)")
    q.add_argument("--out", required=True, help="run folder")
    add_preset_option(q, "--steps", default=planet.steps, type=positive_int,
                      help="optimiser steps; with --resume, the run's own unless given")
    q.add_argument("--batch-size", type=positive_int, default=planet.batch_size, help="sequences per batch (default %(default)s)")
    q.add_argument("--chunk-length", type=positive_int, default=planet.chunk_length,
                   help="model steps per training sequence; times --action-repeat, <= the file's frames (default %(default)s)")
    q.add_argument("--action-repeat", type=positive_int, default=rssm.action_repeat,
                   help="env steps per model step: the model reads every R-th frame and the planner holds each "
                   "action R steps (PlaNet: 2 to 8) (default %(default)s)")
    q.add_argument("--max-sequences", type=nonnegative_int, default=planet.max_sequences,
                   help="train on the first N train sequences only (default %(default)s: all)")
    q.add_argument("--free-nats", type=nonnegative_float, default=planet.free_nats, help="KL free nats (default %(default)s)")
    q.add_argument("--deter-size", type=positive_int, default=rssm.deter_size, help="GRU state size (default %(default)s)")
    q.add_argument("--hidden-size", type=positive_int, default=rssm.hidden_size,
                   help="width of the MLPs around the GRU (PlaNet: 200) (default %(default)s)")
    q.add_argument("--depth", type=positive_int, default=rssm.depth,
                   help="channels of the first conv layer, doubled at each of four (PlaNet: 32) (default %(default)s)")
    q.add_argument("--reward-layers", type=positive_int, default=rssm.reward_layers,
                   help="hidden layers of the reward head (PlaNet: 3) (default %(default)s)")
    q.add_argument("--reward-units", type=nonnegative_int, default=rssm.reward_units,
                   help="width of the reward head's hidden layers (PlaNet: 300; 0: --hidden-size) (default %(default)s)")
    q.add_argument("--reward-alignment", choices=get_args(RewardAlignment), default=rssm.reward_alignment,
                   help="which state the reward head reads for a model step's reward: frame (the state before its actions) "
                   "or transition (PlaNet's: the state they lead to, which has seen them) (default %(default)s)")
    q.add_argument("--reward-scale", type=positive_float, default=planet.reward_scale,
                   help="weight of the reward term of the loss, from 0.001 to 1e6 (PlaNet's code: 10) (default %(default)s)")
    q.add_argument("--stoch-size", type=positive_int, default=rssm.stoch_size, help="stochastic state size (default %(default)s)")
    add_preset_option(q, "--max-minutes", default=planet.max_minutes, type=positive_float, shown="no limit",
                      help="stop at the first checkpoint past this budget")
    q.add_argument("--seed", type=seed_int, default=planet.seed, help="seed (default %(default)s)")
    q.add_argument("--threads", type=thread_count, default=planet.threads, help="torch CPU threads (default %(default)s: torch's choice)")
    add_device_option(q, planet.device)
    iterative = IterativeConfig()
    q.add_argument("--iterative", type=nonnegative_int, default=0, metavar="EPISODES",
                   help="after training, PlaNet's own loop: each round collects EPISODES episodes with the planner plus "
                   "exploration noise into RUN_DIR/collected.h5 (DATA.h5 is only read), then trains --round-steps more "
                   "steps on both (default %(default)s: off)")
    add_preset_option(q, "--rounds", default=iterative.rounds, type=positive_int,
                      help="with --iterative: collect-then-train rounds; with --resume, the run's own unless given")
    q.add_argument("--round-steps", type=positive_int, default=iterative.steps_per_round,
                   help="with --iterative: optimiser steps per round (default %(default)s)")
    q.add_argument("--episode-steps", type=positive_int, default=iterative.episode_steps,
                   help="with --iterative: env steps per collected episode (default %(default)s)")
    noise = number_type(float, lambda v: 0 <= v <= MAX_EXPLORATION_NOISE, f"a number in [0, {MAX_EXPLORATION_NOISE:g}]")
    q.add_argument("--exploration-noise", type=noise, default=iterative.noise,
                   help="with --iterative: std of the Gaussian action noise, a fraction of the action bound (default %(default)s)")
    _common(q)

    ddpg = SB3Config()
    sac = ALGORITHM_PRESETS["sac"]
    drqv2 = ALGORITHM_PRESETS["drqv2"]
    marks = ", ".join(f"{mark:g} on {env}" for env, mark in LEARNED_RETURN.items())
    d = sub.add_parser("ddpg", help="SB3 DDPG (or SAC) from pixels, an autoencoder's latent, or the true state",
                       description="Train SB3 DDPG (or, with --algo sac, SAC; with --algo drqv2, DrQ-v2 from pixels) with the SB3 zoo's Pendulum-v1 hyperparameters "
                       "on the pixel pendulum (or, from pixels, dm_control's: --env). Writes RUN_DIR/checkpoint.pt, model.zip, config.json, metrics.json "
                       "(EvalCallback's learning curve) and tensorboard/. A run whose evaluation return never reached the mark of learning "
                       f"({marks}) keeps them and exits 1, saying it did not learn.")
    d.error = p.error  # type: ignore[method-assign]
    d.add_argument("--env", choices=ENV_IDS, default=ddpg.env,
                   help="the env: Gymnasium's pixel pendulum, or dm_control's pendulum-swingup through a face-on camera "
                   "(needs piga[dmc]; --obs pixels; action repeat 2, episodes of 500 frames, DMC's reward: evaluation "
                   "returns are DMC scores, max 1000) (default %(default)s)")
    d.add_argument("--view", choices=VIEWS, default=ddpg.view,
                   help=f"with --env {DMC_PENDULUM}: face (piga's face-on camera, 64x64 gray), fixed (dm_control's "
                   "camera 0, looking down at 45 degrees, 64x64 gray) or drqv2 (DrQ-v2's own view: camera 0 in 84x84 "
                   "RGB; its replay buffer takes 5x the memory) (default %(default)s)")
    d.add_argument("--obs", required=True, choices=OBSERVATIONS,
                   help="pixels: stacked frames (CnnPolicy); latent: stacked autoencoder codes (needs --data); "
                   "state: (cos θ, sin θ, θ̇), the reference point")
    add_preset_option(d, "--steps", default=ddpg.steps, type=positive_int,
                      help="env steps; with --resume, the run's own unless given")
    d.add_argument("--out", required=True, help="run folder")
    d.add_argument("--data", help="with --obs latent: HDF5 file whose train frames the autoencoder learns")
    d.add_argument("--algo", choices=ALGORITHMS, default=ddpg.algo,
                   help="the algorithm: ddpg (the paper's), or sac, its stronger sibling with the zoo's Pendulum-v1 "
                   "settings, or drqv2 (DrQ-v2: an encoder trained by the critic, augmentation, 3-step returns; "
                   "--obs pixels; its paper's settings) (default %(default)s; with --resume, the run's own unless given)")
    d.add_argument("--eval-every", type=positive_int, default=ddpg.eval_every,
                   help="env steps between evaluations and checkpoints, a multiple of the episode length (200; DMC's 500), "
                   "of which --steps is a multiple "
                   "(default %(default)s)")
    d.add_argument("--eval-episodes", type=positive_int, default=ddpg.eval_episodes, help="episodes per evaluation (default %(default)s)")
    add_preset_option(d, "--learning-starts", default=ddpg.learning_starts, type=nonnegative_int,
                      shown=f"{ddpg.learning_starts}; sac: {sac['learning_starts']}; drqv2: its {DRQV2_SEED_FRAMES} "
                      f"frames, {DRQV2_SEED_FRAMES // ENV_ACTION_REPEAT[DMC_PENDULUM]} steps on {DMC_PENDULUM}",
                      help="random-action steps before learning")
    add_preset_option(d, "--learning-rate", default=ddpg.learning_rate, type=positive_float,
                      shown=f"{ddpg.learning_rate}; drqv2: {drqv2['learning_rate']}",
                      help=f"Adam's learning rate for actor and critic (and DrQ-v2's encoder), in (0, {MAX_LEARNING_RATE:g}]")
    add_preset_option(d, "--batch-size", default=ddpg.batch_size, type=positive_int, help="minibatch")
    add_preset_option(d, "--noise-std", default=ddpg.noise_std, type=nonnegative_float,
                      shown=f"{ddpg.noise_std}; sac: {format_default(sac['noise_std'])}; drqv2: {drqv2['noise_std']}, "
                            f"falling to {ddpg.noise_final_std} over {ddpg.noise_decay_steps} steps",
                      help="std of the Gaussian action noise added to the policy's, in SB3's [-1, 1] action scale")
    add_preset_option(d, "--buffer-size", default=ddpg.buffer_size, type=positive_int,
                      shown=f"{ddpg.buffer_size}; sac: {sac['buffer_size']}; pixels: {format_default(PRESETS['pixels']['buffer_size'])}; "
                            f"drqv2: {drqv2['buffer_size']}",
                      help="replay buffer capacity")
    d.add_argument("--autoencoder-steps", type=int_up_to(MAX_AUTOENCODER_STEPS, "more trains for weeks on a CPU"),
                   default=AutoencoderConfig.steps,
                   help="with --obs latent: the autoencoder's training steps (default %(default)s)")
    d.add_argument("--torque-arrow", action="store_true", help="show Gymnasium's torque arrow in the frames (off by default, as in piga-control)")
    d.add_argument("--encoder-precision", choices=PRECISIONS, default=ddpg.encoder_precision,
                   help="with --algo drqv2: the encoder's convolutions in float32 or bfloat16 (autocast; the actor and "
                   "the critic stay float32); auto: bfloat16 on a CPU with bfloat16 hardware (AMX, AVX-512 BF16), "
                   "float32 elsewhere (default %(default)s)")
    d.add_argument("--seed", type=seed_int, default=ddpg.seed, help="seed (default %(default)s)")
    d.add_argument("--threads", type=thread_count, default=ddpg.threads,
                   help="torch CPU threads, 0: torch's choice (default %(default)s)")
    add_device_option(d, ddpg.device)
    _common(d)
    return p


def _common(p: ArgumentParser) -> None:
    p.add_argument("--resume", action="store_true", help="continue the run in --out exactly; it may raise --steps")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier run in --out")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


#: What a run of this command killed (SIGKILL, a power cut) before its first checkpoint leaves, and nothing of
#: value: TensorBoard's first events, the record written before the checkpoint, a replay buffer's folder.
DISPOSABLE = ("tensorboard", "config.json", "replay_buffers")


def _left_before_a_checkpoint(run_dir: Path, existing: list[str], kind: RunKind) -> bool:
    """Whether ``existing`` (no checkpoint among them) is only what a run of ``kind`` killed before its first
    checkpoint leaves (:data:`DISPOSABLE`; a config.json only if it is such a run's record), so that rerunning the
    command replaces it without ``--overwrite``; anything else (an autoencoder, collected data) is the user's to keep."""
    if not set(existing) <= set(DISPOSABLE):
        return False
    if "config.json" in existing:
        record, _ = read_run_record(run_dir)
        return bool(record) and record.get("kind") == kind.value and isinstance(record.get("command"), str)
    return True


def _check_run_dir(run_dir: Path, resume: bool, overwrite: bool, kind: RunKind, replaced: ReplacedRun) -> None:
    """Refuses to clobber a run, or to resume what is not one of this kind; with ``overwrite``, sets it aside
    (``replaced``: deleted at the new run's first checkpoint, put back if the command ends before it)."""
    check_folder_target(run_dir)
    check_not_demo_folder(run_dir)
    lock_run_folder(run_dir)  # a second command on this folder is refused until this one ends
    if (settled := settle_replaced(run_dir)) is not None:
        print(settled)
    if resume and overwrite:
        raise PigaError("--resume continues the run in --out and --overwrite replaces it; give one of them")
    check_run_files(run_dir)  # a pipe as its checkpoint: refused, neither read nor removed
    existing = [name for name in OUTPUTS if (run_dir / name).exists()]
    if resume:
        if not (run_dir / CHECKPOINT).exists():
            raise PigaError(f"--resume: {run_dir / CHECKPOINT} does not exist")
        record, _ = read_run_record(run_dir)
        if not record:  # missing or unreadable: rebuilt from the checkpoint (:func:`_resumed_record`), which names its kind
            return
        recorded = record.get("kind")
        if recorded == kind.value:
            return
        if not recorded:  # piga-train-model's record names no kind, nor does a damaged one: the checkpoint tells them apart
            found = checkpoint_kind(run_dir)
            if found is None or found is kind:  # this kind's, or unreadable: the record is rebuilt from it, or its
                return  # loader says what is wrong with it (:func:`_resumed_record`)
            raise PigaError(f"--resume: {run_dir} is a {found.writer} run (its {CHECKPOINT}), not a {kind.value} run "
                            f"({kind.writer})")
        if checkpoint_kind(run_dir) is kind:  # the record was edited or swapped: the checkpoint is this kind's
            raise PigaError(f"--resume: {run_dir / 'config.json'} names a {recorded} run, but {CHECKPOINT} is a "
                            f"{kind.value} run's; restore its config.json, or delete it to resume from the checkpoint")
        raise PigaError(f"--resume: {run_dir} is a {recorded} run, not a {kind.value} run ({kind.writer})")
    if existing and not overwrite:
        if CHECKPOINT not in existing and _left_before_a_checkpoint(run_dir, existing, kind):
            print(f"removing what a run of {run_dir} stopped before its first checkpoint left ({', '.join(existing)})")
            remove_outputs(run_dir, existing)
            return
        if CHECKPOINT not in existing:  # a run killed before its first checkpoint: nothing to continue
            raise PigaError(f"{run_dir} holds outputs of an earlier run but no checkpoint ({', '.join(existing)}); "
                            "pass --overwrite to replace them")
        if "config.json" not in existing:  # killed between its first checkpoint and its record
            raise PigaError(f"{run_dir} holds a checkpoint without the record of its settings (config.json; the run "
                            "was stopped as it wrote its first checkpoint); continue it with --resume (its settings "
                            "are rebuilt from the checkpoint), or pass --overwrite to start it again")
        raise held_run_error(run_dir, kind)
    if overwrite:  # a run of another kind's outputs too
        replaced.set_aside(run_dir, RUN_OUTPUTS)


#: The record's keys of a PlaNet-style run's data file: its path as the command gave it, and the folder it was given in.
RUN_DATA, RUN_DATA_FOLDER = "data", "data_folder"


def _resumed_record(run_dir: Path, kind: RunKind, args: Any) -> dict[str, Any]:
    """The record (``config.json``) of the run that ``--resume`` continues; where it is missing or unreadable, one
    rebuilt from the checkpoint, as piga-train-model rebuilds its own: the checkpoint holds the run's settings (a
    planet run's training and model sizes and its data file's path; a DDPG or DrQ-v2 run's whole recipe), and the
    rebuilt record says that the command that started the run is unknown. A record that lacks some of the sections
    the checkpoint holds (a planet run's data file, training settings or model sizes; a DDPG run's recipe) takes those
    from it, with a note. An ``--iterative`` planet run's settings of its rounds are only in the record: where the
    record is missing or unreadable, refused, saying so."""
    record, why = read_run_record(run_dir)
    if why is None and not record.get("kind"):  # a JSON object without the record's fields (:func:`_check_run_dir`
        why = "names no run kind (it lacks a run record's fields)"  # found this kind's checkpoint, or none that reads)
    # the sections the checkpoint holds too: a record that lacks some (edited) takes them from it, as a missing one is
    # rebuilt whole (a planet record without its data file's path resumed on any file, unchecked)
    lacking = [name for name in ((RUN_DATA, "train", "rssm") if kind is RunKind.PLANET else ("ddpg",))
               if not isinstance(record.get(name), str if name == RUN_DATA else dict)] if why is None else []
    if why is None and not lacking:
        return record
    from piga.io.checkpoint import read_checkpoint

    where = run_dir / "config.json"
    try:
        ckpt = read_checkpoint(run_dir, kind)
    except (FileNotFoundError, ValueError) as exc:
        raise PigaError(with_flags(str(exc))) from None
    if kind is RunKind.PLANET:
        from agents.planet.iterative import COLLECTED

        if why is not None and ((run_dir / COLLECTED).exists() or args.iterative or args.rounds):
            raise PigaError(f"--resume: {where} {why}, and the checkpoint does not hold the --iterative settings it "
                            "records (the episodes, rounds and steps of each round); restore config.json, or start the "
                            "run again with --overwrite")
        data = ckpt.get("data") if isinstance(ckpt.get("data"), dict) else {}
        rebuilt = {RUN_DATA: data.get("path"), RUN_DATA_FOLDER: data.get("folder"), "train": ckpt.get("train_config"),
                   "rssm": ckpt.get("rssm_config")}
    else:
        rebuilt = {"ddpg": ckpt.get("config")}  # (the data file of --obs latent is the autoencoder's, already trained)
    if why is None:  # only the sections the record lacks
        rebuilt = {name: rebuilt[name] for name in lacking + ([RUN_DATA_FOLDER] if RUN_DATA in lacking else [])}
        why = f"lacks its {', '.join(repr(name) for name in lacking)} settings (edited, or from an older version)"
    if not all(isinstance(section, dict) for name, section in rebuilt.items()
               if name not in (RUN_DATA, RUN_DATA_FOLDER)):
        raise PigaError(f"--resume: {where} {why}, and the checkpoint does not hold the run's settings (an older "
                        "version's); restore config.json, or start the run again with --overwrite")
    if lacking:
        print(f"{PROG}: note: {where} {why}; they are taken from the checkpoint")
        return {**record, **rebuilt}
    print(f"{PROG}: note: {where} {why}; the resumed run rewrites it from the checkpoint, without the command that "
          "started the run")  # on stdout: stderr is kept for the one line of an error that may follow
    return {"command": None, "kind": kind.value, **rebuilt}


def _refuse_record_edits(run_dir: Path, record: dict[str, Any], kind: RunKind,
                         ckpt: dict[str, Any] | None = None) -> None:
    """A record whose recipe differs from its checkpoint's (``ckpt``, read here where None: an edited ``obs`` or
    ``env`` of a DDPG run, an edited ``free_nats`` of a planet run, or another run's checkpoint in the folder) is named
    as such at once: judged first against the command line, it read "trained with --obs pixels, not state" (the
    command line blamed), or "not usable ...; start the run again with --overwrite" (the run thrown away); and a planet
    run trained on the edited value."""
    from piga.io.checkpoint import RESTORE_OR_DELETE, check_record_matches, read_checkpoint

    if ckpt is None:
        try:
            ckpt = read_checkpoint(run_dir, kind)
        except (FileNotFoundError, ValueError) as exc:
            raise PigaError(with_flags(str(exc))) from None
    sections = ([(record.get("train"), ckpt.get("train_config")), (record.get("rssm"), ckpt.get("rssm_config"))]
                if kind is RunKind.PLANET else [(record.get("ddpg"), ckpt.get("config"))])
    # an --iterative run's settings of its rounds are only in its record: deleting it is no way out
    iterative = kind is RunKind.PLANET and record.get("iterative")
    try:
        check_record_matches(run_dir, sections, "restore the record's values" if iterative else RESTORE_OR_DELETE)
    except ValueError as exc:  # (the record's own names: "learning_starts 100 there")
        raise PigaError(str(exc)) from None


def _saved_config(run_dir: Path, record: dict[str, Any], key: str, cls: Any, optional: tuple[str, ...] = ()) -> Any:
    """The dataclass ``cls`` that a run's ``config.json`` records under ``key``, for ``--resume``.

    Raises:
        PigaError: the entry is missing, lacks fields (other than ``optional``, which newer
            versions added), has unknown ones, or holds values ``cls`` refuses.
    """
    where = run_dir / "config.json"
    saved = record.get(key)
    if not isinstance(saved, dict):
        raise PigaError(f"--resume: {where} has no '{key}' settings (not written by piga-baseline, or edited); "
                        f"delete it to resume from the settings that {CHECKPOINT} holds, or start the run again with "
                        "--overwrite")
    names = {f.name for f in dataclasses.fields(cls)}
    missing, unknown = sorted(names - set(saved) - set(optional)), sorted(set(saved) - names)
    if missing or unknown:
        raise PigaError(f"--resume: {where}'s '{key}' settings " + (f"lack {', '.join(missing)}" if missing else "")
                        + (" and " if missing and unknown else "") + (f"have unknown {', '.join(unknown)}" if unknown else "")
                        + f" (edited, or from another version); delete it to resume from the settings that {CHECKPOINT} "
                        "holds, or start the run again with --overwrite")
    for name, kind in typing.get_type_hints(cls).items():  # a number edited into text: the config's checks would compare it
        value = saved.get(name)
        if name in saved and kind in (int, float) and (isinstance(value, bool) or not isinstance(value, (int, kind))):
            raise PigaError(f"--resume: {where}'s '{key}' settings give {name} as {value!r}, not "
                            f"{'an integer' if kind is int else 'a number'} (edited); start the run again with --overwrite")
    try:
        return cls(**{name: tuple(value) if isinstance(value, list) else value for name, value in saved.items()})
    except (TypeError, ValueError) as exc:
        raise PigaError(f"--resume: {where}'s '{key}' settings are not usable ({exc}); start the run again with "
                        "--overwrite") from None


#: Options that ``--resume`` takes besides those naming the run: the run's length and budget, and
#: how this process runs (the device included). Any other option would change the run's recipe, so it is refused.
RESUME_OPTIONS = {"planet": ("steps", "max_minutes", "rounds", "threads", "device", "quiet"),
                  "ddpg": ("steps", "threads", "device", "quiet")}


def _given_options(parser: ArgumentParser, kind: str, argv: Sequence[str] | None) -> set[str]:
    """The destinations of the options written on the command line ``argv`` of ``parser``'s subcommand ``kind``,
    even where the value written is the default."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[kind]
    return given_options(sub, argv)


def _refuse_recipe_changes(args: Any, record: dict[str, Any], run_dir: Path, argv: Sequence[str] | None) -> None:
    """``--resume`` continues a run as it was started, as piga-train-model's does: refuses options
    that would change its recipe (other than :data:`RESUME_OPTIONS`), given with any value but the one the run was
    started with (so the starting command plus ``--resume`` continues it), and another data file. A data file of the
    same contents under another path is the run's: ``record`` is rewritten to name it."""
    kind = args.baseline
    named = [kind, args.data, "--out", args.out] if kind == "planet" else [kind, "--obs", args.obs, "--out", args.out]
    parser = build_parser()
    defaults = vars(parser.parse_args(named))
    skip = {"baseline", "data", "out", "obs", "algo", "resume", "overwrite", "iterative", "quiet", *RESUME_OPTIONS[kind]}
    given = _given_options(parser, kind, argv)
    started = recorded_options(parser, record.get("command")) or {}  # the starting command's values may be repeated
    # and so may the run's own settings, as its record holds them (--seed 0 on a run of seed 0)
    sections = ("rssm", "train", "iterative") if kind == "planet" else ("ddpg",)
    own = {k: v for section in sections if isinstance(record.get(section), dict) for k, v in record[section].items()}
    # a value at its default, where the starting command gave none, is the one the run started with (--encoder-precision
    # auto on a run started without it, which its record holds resolved)
    changed = [name for name, value in vars(args).items()
               if name not in skip and (value != defaults[name] or name in given)
               and not (name in started and started[name] == value) and not (name in own and own[name] == value)
               and not (record.get("command") and name not in started and value == defaults[name])]
    if changed:
        raise PigaError(f"--resume keeps the run's recipe; drop {', '.join('--' + c.replace('_', '-') for c in changed)}")
    recorded = record.get("data")
    if isinstance(recorded, str):  # as its command gave it: from here (a resume in another folder read another path)
        recorded = recorded_path(recorded, record.get("data_folder"))
    if not args.data or "data" not in record:  # a DDPG record rebuilt from its checkpoint, which names no data file
        return
    # a fingerprint that is not a string (edited to null) is none: the file is then known by its path, as a run's from
    # before fingerprints (compared, it read "p.h5 has changed since the run trained on it" of an untouched file)
    if isinstance(record.get("data_fingerprint"), str):  # by contents: a moved or copied file is the same, one written
        from piga.data.schema import has_fingerprint  # over in place, or edited in place, is not

        same = has_fingerprint(args.data, record["data_fingerprint"])
        if same and isinstance(record.get("rewards_fingerprint"), str):  # a PlaNet-style run's reward head learns
            from piga.data.schema import rewards_fingerprint  # from /rewards too

            same = record["rewards_fingerprint"] == rewards_fingerprint(args.data)
        if not same and recorded is not None and os.path.abspath(recorded) == os.path.abspath(args.data):
            raise PigaError(f"--resume: {args.data} has changed since {run_dir} trained on it (its contents are not "
                            "the same); put the trained file back, or start a new run on this one")
        if same and (recorded is None or os.path.abspath(recorded) != os.path.abspath(args.data)):
            # the same contents under another name (a moved or renamed file, or a record's "data" edited): the record
            # names the file the run goes on with, so that it stays true (it kept naming a file the run never saw)
            print(f"{PROG}: note: {run_dir / 'config.json'} named {recorded or 'no data file'}; {args.data} holds the "
                  "same data, and the record now names it")
            record.update({RUN_DATA: args.data, RUN_DATA_FOLDER: os.getcwd()})
    else:  # a run from before fingerprints: the same file by its path
        same = recorded is not None and (os.path.abspath(recorded) == os.path.abspath(args.data) or (
            Path(recorded).exists() and Path(args.data).exists() and os.path.samefile(recorded, args.data)))
    if not same:
        drop = "give that file" if kind == "planet" else "drop --data (the run keeps its autoencoder)"
        raise PigaError(f"--resume: {run_dir} was trained on {recorded or 'no data file'}, not {args.data}; {drop}")


def _refuse_fewer_steps(steps: int | None, planned: int, flag: str = "--steps") -> None:
    """``--resume --steps`` (or ``--rounds``) below the run's plan would be ignored (the run keeps what it trained),
    while its record said otherwise: refused."""
    if steps and steps < planned:
        raise PigaError(f"--resume {flag} {steps}: the run already planned {planned} {flag[2:]}; --resume may raise "
                        f"{flag}, never lower it")


@contextlib.contextmanager
def _nothing_left_unless_checkpointed(run_dir: Path, written: list[int], fresh: bool) -> Iterator[None]:
    """Makes ``run_dir`` and undoes a fresh run that fails or is interrupted before its first
    checkpoint (``written`` empty): removes the outputs it made (TensorBoard's folder, the
    autoencoder) and the folders it made (:func:`~piga.cli.common.made_folder`), so that the same
    command can simply be run again. ``_check_run_dir`` made sure that none of :data:`OUTPUTS` was
    there before."""
    with made_folder(run_dir):
        try:
            yield
        except BaseException:
            if fresh and not written:
                remove_outputs(run_dir, OUTPUTS, ignore_errors=True)
            raise


def _interrupted(run_dir: Path, written: list[int], resume: bool, overwrite: bool) -> None:
    """Raises the line of a run interrupted after a checkpoint, or of a resumed one before its next checkpoint: its
    checkpoint is kept either way ("nothing was written" would read as the run lost). A run given --overwrite is
    continued with --resume in its place (beside it, --resume is refused)."""
    if written:
        raise Interrupted(f"{run_dir / CHECKPOINT} holds step {written[-1]}; continue with "
                          f"{resume_option(overwrite)}") from None
    if resume:
        raise Interrupted(f"{run_dir / CHECKPOINT} is as it was (stopped before the next checkpoint); continue with "
                          "--resume") from None


def check_planet_memory(rssm: Any, config: Any = None) -> None:
    """Refuses model sizes whose weights, gradients and Adam's two moments (4 float32 copies) do not fit
    in memory, before anything is allocated (a --stoch-size of 5e7 otherwise swaps for ever); with the training
    ``config``, also a batch whose frames and the activations of the conv encoder and decoder do not (a --batch-size
    of 1e5 otherwise swaps for ever too). A refusal is a ResourceError, a ValueError: run_cli's one line, in flags."""
    from agents.planet.rssm import parameter_count
    from piga.io.resources import check_memory, check_training_memory

    check_training_memory(parameter_count(rssm), "the PlaNet-style world model of these sizes")
    if config is not None:
        frames = config.batch_size * config.chunk_length  # (B, T) frames of 64 x 64 x C per optimiser step
        # per frame about 32 float32 maps of its size: the input, the activations of the encoder's and the decoder's
        # convolutions, and their gradients (depth 16 at 31x31 down to 2x2, and back)
        check_memory(frames * 32.0 * 4 * 64 * 64 * rssm.channels,
                     f"a batch of {config.batch_size} x {config.chunk_length} frames (--batch-size x --chunk-length)")


def _planet(args: Any, argv: Sequence[str] | None, replaced: ReplacedRun) -> int:
    from agents.planet.config import IterativeConfig, PlanetTrainConfig
    from piga.io.resources import check_run_disk
    from piga.io.atomic import write_json
    from agents.planet.train import check_planet_data, rssm_config_for, train_planet
    from piga.data.schema import fingerprint, inspect_dataset, rewards_fingerprint
    from piga.training.train import TrainingDiverged

    run_dir = Path(args.out)
    info = inspect_dataset(args.data)  # a missing or malformed file: one line, before the run folder is touched
    command = command_line(PROG, argv)
    iterative: IterativeConfig | None = None
    if args.resume:
        _check_run_dir(run_dir, True, args.overwrite, RunKind.PLANET, replaced)
        record = _resumed_record(run_dir, RunKind.PLANET, args)
        from agents.planet.run import load_planet

        try:  # the model's sizes are the checkpoint's: a record may lack them (benchmarks/baselines.py wrote none
            # before) or have been edited
            held, ckpt = load_planet(run_dir)
        except (FileNotFoundError, ValueError) as exc:
            raise PigaError(with_flags(str(exc))) from None
        _refuse_record_edits(run_dir, record, RunKind.PLANET, ckpt)
        _refuse_recipe_changes(args, record, run_dir, argv)
        saved = _saved_config(run_dir, record, "train", PlanetTrainConfig, optional=("device",))  # older runs have none
        _refuse_fewer_steps(args.steps, saved.steps)
        config = replace(saved, steps=args.steps or saved.steps, max_minutes=args.max_minutes or saved.max_minutes,
                         threads=args.threads or saved.threads, device=args.device)
        rssm = None
        record["train"] = config.to_dict()
        for flag, given in (("--iterative", args.iterative), ("--rounds", args.rounds)):
            if given and not record.get("iterative"):
                raise PigaError(f"{flag}: {run_dir} was trained without --iterative; --resume continues a run as it was "
                                "started")
        if record.get("iterative"):
            saved_iterative = _saved_config(run_dir, record, "iterative", IterativeConfig)
            if args.iterative and args.iterative != saved_iterative.episodes:
                raise PigaError(f"--iterative: {run_dir} collects {saved_iterative.episodes} episodes a round; --resume "
                                "keeps the run's recipe")
            _refuse_fewer_steps(args.rounds, saved_iterative.rounds, "--rounds")
            iterative = replace(saved_iterative, rounds=args.rounds or saved_iterative.rounds)
            record["iterative"] = iterative.to_dict()
        record["rssm"] = held.config.to_dict()
        record_resume(record, command)
    else:
        config = PlanetTrainConfig(steps=args.steps or PlanetTrainConfig.steps, batch_size=args.batch_size, chunk_length=args.chunk_length,
                                   max_sequences=args.max_sequences, free_nats=args.free_nats, reward_scale=args.reward_scale,
                                   seed=args.seed,
                                   threads=args.threads, device=args.device, max_minutes=args.max_minutes or 0.0)
        check_planet_data(info, config, args.action_repeat)  # a bad file: one line naming it, before the model's sizes
        rssm = rssm_config_for(info, {"deter_size": args.deter_size, "stoch_size": args.stoch_size, "action_repeat": args.action_repeat,
                                      "reward_alignment": args.reward_alignment, "hidden_size": args.hidden_size,
                                      "depth": args.depth, "reward_layers": args.reward_layers,
                                      "reward_units": args.reward_units})
        check_planet_memory(rssm, config)
        if config.max_sequences > (n_train := info.split_counts["train"]):
            raise PigaError(f"--max-sequences {config.max_sequences}: {args.data} has {n_train} train sequences; give at "
                            f"most {n_train} (0: all)")
        if not args.iterative:  # each refused whenever written, at its default's value too
            given = _given_options(build_parser(), "planet", argv)
            ignored = [f"--{name.replace('_', '-')}" for name in ("rounds", "round_steps", "episode_steps", "exploration_noise")
                       if name in given]
            if ignored:
                raise PigaError(f"{ignored[0]} goes with --iterative EPISODES (PlaNet's collect-then-train loop)")
        else:
            iterative = IterativeConfig(rounds=args.rounds or IterativeConfig.rounds, episodes=args.iterative,
                                        steps_per_round=args.round_steps, episode_steps=args.episode_steps,
                                        noise=args.exploration_noise)
        if iterative is not None:
            from agents.planet.iterative import check_iterative_data

            check_iterative_data(info, iterative)
        _check_run_dir(run_dir, False, args.overwrite, RunKind.PLANET, replaced)
        record = started_record(command, kind=RunKind.PLANET.value, data=str(args.data), data_folder=os.getcwd(),
                                data_fingerprint=fingerprint(args.data), rewards_fingerprint=rewards_fingerprint(args.data),
                                train=config.to_dict(), rssm=rssm.to_dict(),
                                **({"iterative": iterative.to_dict()} if iterative else {}))
    check_planet_data(info, config, record["rssm"].get("action_repeat", 1))
    if iterative is not None:
        from agents.planet.iterative import check_iterative_data, train_planet_iterative

        if config.max_minutes:
            raise PigaError("--max-minutes stops one training; with --iterative, bound the run with --rounds instead")
        check_iterative_data(info, iterative)
    check_run_disk(run_dir, _planet_checkpoint_bytes(run_dir, record["rssm"], args.resume), "the PlaNet-style run",
                   extra=0 if iterative is None else 2 * _collected_bytes(info, iterative), resume=args.resume,
                   overwrite=args.overwrite)
    used = min(info.split_counts["train"], config.max_sequences or info.split_counts["train"])
    # (as piga-train-model says of a file without a test split: on stdout, so that a run that then did not learn says
    # so in one line on stderr)
    unchecked = ("" if info.split_counts["valid"] else "; no valid sequences, so no valid loss is measured, and the "
                 "open-loop check (metrics.json, openloop.png) reads the train split, which is not held out")
    print(f"training the PlaNet-style model on {args.data} ({counted(used, 'train sequence')} x {info.steps} frames"
          f"{unchecked}) -> {run_dir}"
          + (f", then {counted(iterative.rounds, 'round')} of {counted(iterative.episodes, 'planner episode')} + "
             f"{counted(iterative.steps_per_round, 'step')}" if iterative else ""))
    written: list[int] = []

    def on_checkpoint(state: Any) -> None:
        if not written:
            write_json(run_dir / "config.json", record)
            replaced.drop()
        written.append(state.step)

    try:
        with _nothing_left_unless_checkpointed(run_dir, written, fresh=not args.resume):
            if not args.resume:  # before the first checkpoint: a checkpoint is never without the record of its run
                write_json(run_dir / "config.json", record)
            if iterative is not None:
                _, state = train_planet_iterative(args.data, run_dir, config, iterative, rssm, resume=args.resume,
                                                  progress=not args.quiet, on_checkpoint=on_checkpoint, command=command)
            else:
                _, state = train_planet(args.data, run_dir, config, rssm, resume=args.resume, progress=not args.quiet,
                                        on_checkpoint=on_checkpoint)
    except TrainingDiverged as exc:
        if written or args.resume:  # its checkpoint is this run's: the commands that read it say it diverged
            record_divergence(run_dir, f"training diverged: {exc}")
        raise PigaError(f"training diverged: {exc}") from None
    except KeyboardInterrupt:
        _interrupted(run_dir, written, args.resume, args.overwrite)
        raise
    if not written:  # a resume with nothing left to do still records its command
        write_json(run_dir / "config.json", record)
    last = state.history[-1] if state.history else {}
    window = (f"mean loss over steps {last['first_step']:,}..{last['step']:,}" if "first_step" in last and "step" in last
              else "last loss")  # (a mean since the last record: after a resume, over the steps since it)
    print(f"trained {counted(state.step, 'step')} in {state.elapsed / 60:.1f} min; {window} {last.get('loss', float('nan')):.2f} "
          f"(reconstruction {last.get('reconstruction', float('nan')):.2f}, reward {last.get('reward', float('nan')):.4f}, "
          f"KL {last.get('kl', float('nan')):.2f}); wrote {run_dir}/metrics.json")
    from agents.planet.train import did_not_learn

    why = did_not_learn(json.loads((run_dir / "metrics.json").read_text())["open_loop"])
    planned = config.steps + (iterative.rounds * iterative.steps_per_round if iterative is not None else 0)
    cut = state.step < planned  # --max-minutes stopped it: a larger --steps alone would stop it again
    if why is not None:  # its outputs stay (--resume continues it), but no script may take it for a success
        more = (f"--max-minutes stopped it at step {state.step:,} of {planned:,}: continue it with --resume and "
                "a larger --max-minutes" if cut else "continue it with --resume and a larger --steps")
        raise PigaError(f"the run did not learn: {why} after {state.step} steps; {more}, or give it more data; its "
                        f"outputs are in {run_dir}")
    if cut:  # it learned, but did not run its plan: not a finished run
        print(f"{PROG}: warning: --max-minutes stopped the run at step {state.step:,} of {planned:,}; continue it "
              "with --resume and a larger --max-minutes", file=sys.stderr)
        return NOT_CONVERGED
    return 0


def _planet_checkpoint_bytes(run_dir: Path, rssm: dict[str, Any], resume: bool) -> float:
    """A PlaNet-style checkpoint's size: the one there (resuming), or the weights and Adam's two moments."""
    from piga.io.resources import adam_checkpoint_bytes

    if resume:
        return (run_dir / CHECKPOINT).stat().st_size
    from agents.planet.config import RSSMConfig
    from agents.planet.rssm import WorldModel

    return adam_checkpoint_bytes(WorldModel(RSSMConfig(**rssm)))


def _collected_bytes(info: Any, iterative: Any) -> float:
    """``collected.h5`` at the end of an iterative run (frames uncompressed, actions and rewards)."""
    pixels = math.prod(info.image_shape)
    return iterative.rounds * iterative.episodes * iterative.episode_steps * (pixels + 4 * (info.action_dim + 1))


def _ddpg_checkpoint_bytes(config: Any, latent_size: int) -> float:
    """A DDPG checkpoint's size: its replay buffer, pickled at full capacity with observations and
    next observations, and the networks (:data:`piga.io.resources.RUN_DISK_MARGIN` covers them)."""
    per_obs = {"pixels": config.frame_stack * config.frame_pixels, "latent": 4 * config.frame_stack * latent_size, "state": 4 * 3}[config.obs]
    return config.buffer_size * (2 * per_obs + 16)


def _ddpg(args: Any, argv: Sequence[str] | None, replaced: ReplacedRun) -> int:
    from piga.io.atomic import write_json
    from agents.sb3.config import SB3Config, resolve_precision  # it checks --eval-every against the env's episode length
    from agents.sb3.run import AUTOENCODER, MODEL, REPLAY_BUFFERS
    from agents.sb3.train import first_step_reaching, train_sb3
    from piga.io.resources import check_memory, check_run_disk
    from piga.training.train import TrainingDiverged

    run_dir = Path(args.out)
    command = command_line(PROG, argv)
    if args.obs == "latent" and not args.data and not args.resume:
        raise PigaError("--obs latent trains an autoencoder on collected frames: give --data DATA.h5")
    if args.obs != "latent" and args.data:
        raise PigaError(f"--data is for --obs latent (the autoencoder's frames); --obs {args.obs} does not use it")
    from agents.sb3.autoencoder import AutoencoderConfig
    from envs import DMC_PENDULUM

    written = _given_options(build_parser(), "ddpg", argv)  # an option that does not apply is refused at its default value too
    if args.obs != "latent" and "autoencoder_steps" in written:
        raise PigaError(f"--autoencoder-steps is for --obs latent; --obs {args.obs} trains no autoencoder")
    if args.algo != "drqv2" and "encoder_precision" in written:
        raise PigaError(f"--encoder-precision is for --algo drqv2; SB3's {args.algo} trains its own networks in float32: "
                        "drop --encoder-precision")
    if args.env != DMC_PENDULUM and "view" in written:
        raise PigaError(f"--view chooses a view of {DMC_PENDULUM}; {args.env} is seen as it renders: drop --view")
    if args.resume:
        _check_run_dir(run_dir, True, args.overwrite, RunKind.DDPG, replaced)
        record = _resumed_record(run_dir, RunKind.DDPG, args)
        _refuse_record_edits(run_dir, record, RunKind.DDPG)
        # runs from before --algo are DDPG; runs from before --device have none
        saved = _saved_config(run_dir, record, "ddpg", SB3Config, optional=("algo", "device", "env", "encoder_precision", "view"))
        if "encoder_precision" not in record["ddpg"]:  # runs from before the option computed in float32
            saved = replace(saved, encoder_precision="float32")
        if saved.obs != args.obs:
            raise PigaError(f"--resume: {run_dir} was trained with --obs {saved.obs}, not {args.obs}")
        if "algo" not in written:  # the run's own (its default named the run "trained with --algo sac, not ddpg")
            args.algo = saved.algo
        if saved.algo != args.algo:
            raise PigaError(f"--resume: {run_dir} was trained with --algo {saved.algo}, not {args.algo}")
        _refuse_recipe_changes(args, record, run_dir, argv)
        if saved.obs != "latent" and record.get(RUN_DATA) is not None:  # edited: such a run reads no data file
            print(f"{PROG}: note: {run_dir / 'config.json'} named {record[RUN_DATA]} as its data file; --obs "
                  f"{saved.obs} reads none, and the record now names none")
            record[RUN_DATA] = None
        if saved.obs == "latent":  # missing or unreadable: one line before anything is written
            from agents.sb3.autoencoder import load_autoencoder

            try:
                load_autoencoder(run_dir / AUTOENCODER)
            except (FileNotFoundError, ValueError) as exc:
                raise PigaError(f"--resume: {exc}") from None
        _refuse_fewer_steps(args.steps, saved.steps)
        config = replace(saved, steps=args.steps or saved.steps, threads=args.threads, device=args.device)
        record["ddpg"] = config.to_dict()
        record_resume(record, command)
        buffer_bytes = _ddpg_checkpoint_bytes(config, AutoencoderConfig.latent_size)  # (the run's autoencoder: its default size)
        # the next checkpoint's buffer file, at most full, beside the run's present one, which it then replaces
        checkpoint_bytes: float = buffer_bytes + (run_dir / CHECKPOINT).stat().st_size
    else:
        if args.obs == "state" and args.torque_arrow:  # (--resume refuses it with the recipe's other changes)
            raise PigaError("--torque-arrow shows the arrow in the frames; --obs state sees no frames (it observes "
                            "cos θ, sin θ and θ̇): drop --torque-arrow")
        given = {name: value for name, value in (("buffer_size", args.buffer_size), ("learning_starts", args.learning_starts),
                                                 ("noise_std", args.noise_std), ("learning_rate", args.learning_rate),
                                                 ("batch_size", args.batch_size)) if value is not None}  # else the presets'
        config = SB3Config(env=args.env, obs=args.obs, algo=args.algo, steps=args.steps or SB3Config.steps, eval_every=args.eval_every,
                            eval_episodes=args.eval_episodes,
                            torque_arrow=args.torque_arrow, seed=args.seed, threads=args.threads, device=args.device,
                            encoder_precision=args.encoder_precision, view=args.view, **given)
        from piga.io.device import resolve_device

        # the record holds the precision the run computes in, so that --resume continues it on any machine
        config = replace(config, encoder_precision=resolve_precision(config, resolve_device(config.device)))
        ae_config = AutoencoderConfig(steps=args.autoencoder_steps, seed=config.seed)
        if args.data:
            from agents.sb3.autoencoder import check_autoencoder_data
            from envs import PIXEL_PENDULUM
            from piga.data.schema import check_pixel_pendulum_file, fingerprint, inspect_dataset

            info = inspect_dataset(args.data)
            check_autoencoder_data(info)  # blank or ill-sized frames: one line, before --out is touched
            check_pixel_pendulum_file(info, "--obs latent learns its codes from the file's frames and then acts on "
                                      f"{PIXEL_PENDULUM}, whose frames they must be")
        _check_run_dir(run_dir, False, args.overwrite, RunKind.DDPG, replaced)
        record = started_record(command, kind=RunKind.DDPG.value, data=args.data, data_folder=os.getcwd(),
                                ddpg=config.to_dict())
        if args.data:
            record["data_fingerprint"] = fingerprint(args.data)
        checkpoint_bytes = buffer_bytes = _ddpg_checkpoint_bytes(config, ae_config.latent_size)
    what = f"{config.algo.upper()}'s run (a replay buffer of {config.buffer_size})"
    check_run_disk(run_dir, checkpoint_bytes, what, resume=args.resume, rewritten=(REPLAY_BUFFERS,),
                   overwrite=args.overwrite)

    def check_disk_with(policy: int) -> None:
        """Again, with the networks that the built model saves (a pixel CNN's with Adam's moments: about 37 MiB): the
        checkpoint holds them beside the buffer and is written beside the previous one, and model.zip holds them once
        more; so the peak is two buffers and three policies. The first check, without them, let a run start that
        filled its disk at the second checkpoint."""
        check_run_disk(run_dir, buffer_bytes + policy, what, extra=policy, resume=args.resume,
                       rewritten=(REPLAY_BUFFERS, MODEL), overwrite=args.overwrite)
    # SB3 allocates the buffer untouched and fills it as the run goes: a buffer beyond the memory would be killed hours in
    source = f"as {run_dir / 'config.json'} gives it" if args.resume else "--buffer-size"  # a resume takes the record's
    check_memory(buffer_bytes, f"{config.algo.upper()}'s replay buffer of {config.buffer_size} ({source})")
    autoencoder = run_dir / AUTOENCODER if config.obs == "latent" else None
    written: list[int] = []

    def on_checkpoint(step: int) -> None:
        if not written:
            write_json(run_dir / "config.json", record)
            replaced.drop()
        written.append(step)

    try:
        with _nothing_left_unless_checkpointed(run_dir, written, fresh=not args.resume):
            if not args.resume:  # before the first checkpoint (again after it, with the autoencoder's): see planet's
                write_json(run_dir / "config.json", record)
            if autoencoder is not None and not args.resume:
                from agents.sb3.autoencoder import train_autoencoder

                print(f"training the autoencoder on {args.data}'s train frames for {counted(ae_config.steps, 'step')} "
                      f"(batches of {ae_config.batch_size}) -> {autoencoder}", flush=True)
                _, mse = train_autoencoder(args.data, ae_config, autoencoder, progress=not args.quiet,
                                           device=config.device)
                record["autoencoder"] = {**ae_config.__dict__, "train_mse": mse}
                print(f"autoencoder trained on {args.data}: per-pixel MSE {mse:.5f}")
            print(f"training {config.algo.upper()} from {config.obs} for {config.steps} env steps -> {run_dir}")
            metrics = train_sb3(config, run_dir, autoencoder, resume=args.resume, progress=not args.quiet,
                                 on_checkpoint=on_checkpoint, check_disk=check_disk_with)
    except TrainingDiverged as exc:
        if written or args.resume:  # its checkpoint is this run's: the commands that read it say it diverged
            record_divergence(run_dir, f"training diverged: {exc}")
        raise PigaError(f"training diverged: {exc}") from None
    except KeyboardInterrupt:
        _interrupted(run_dir, written, args.resume, args.overwrite)
        raise
    if not written:  # a resume with nothing left to do still records its command (and a rebuilt record)
        write_json(run_dir / "config.json", record)
    reached = first_step_reaching(metrics["learning_curve"], config.learned_return)
    final = metrics["final_eval_mean_return"]
    final_text = f"{final:.1f}" if final is not None else "n/a"
    mark = f"{config.learned_return:g}"
    print(f"trained {counted(metrics['steps'], 'step')} in {metrics['train_seconds'] / 60:.1f} min; final evaluation "
          "mean return "
          + f"{final_text}; "
          + (f"first reached {mark} at step {reached}" if reached is not None else f"never reached {mark}")
          + f"; wrote {run_dir}/metrics.json")
    if reached is None:  # its outputs stay (--resume continues it), but no script may take it for a success
        raise PigaError(f"the run did not learn: its evaluation return never reached {mark} in {metrics['steps']} env "
                        f"steps (final {final_text}); its outputs are in {run_dir}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from piga.io.device import resolve_device

    resolve_device(args.device)  # --device cuda without a GPU: one line, before anything is read or written
    with replacing() as replaced:  # the run that --overwrite replaces: back in place if this one ends before a checkpoint
        return (_planet if args.baseline == "planet" else _ddpg)(args, argv, replaced)


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
