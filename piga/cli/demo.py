"""``piga-demo``: the main job on small defaults, for a fresh machine.

Four stages, each printed as it starts (``[1/4]`` ...), then one summary:

1. collect a small pixel-pendulum data set (``piga-collect``'s defaults);
2. save a strip of its frames (``piga-show``);
3. train the world model with the fast preset (``piga-train-model``) and read the learned g and a
   with their errors against the truth;
4. control the pixel pendulum from pixels with the learned model: upright at gravity x1.0, upright
   at x1.4 (the agent is told the multiplier, no retraining), and to a goal given as an image that
   it writes with Gymnasium's renderer and reads back with the trained encoder.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from envs.fields import counted
from piga.cli import show, train
from piga.cli.common import (ArgumentParser, Interrupted, PigaError, command_line, int_up_to, made_folder, positive_int,
                             resume_option, run_cli, seed_int, thread_count)
from piga.data.collect import CollectConfig, collect, fewest_filling
from piga.data.schema import inspect_dataset, open_data_file
from piga.io.atomic import check_folder_target, remove_stale_partials
from piga.io.checkpoint import CHECKPOINT, DEMO_RUN
from piga.io.lock import lock_run_folder
from piga.io.replaced import replacing
from piga.training.convergence import Need

PROG = "piga-demo"


@dataclass(frozen=True)
class DemoConfig:
    """The demo's own settings (data and training use :class:`CollectConfig` and the fast preset)."""

    out: str = "demo"
    """Output folder."""
    sequences: int = CollectConfig.sequences
    """Sequences to collect."""
    episodes: int = 3
    """Control episodes per task."""
    control_steps: int = 200
    """Steps per control episode."""
    goal_angle: float = 15.0
    """Angle of the goal image, degrees from upright."""
    seed: int = 0
    """Seed of data, training and control."""
    threads: int = 0
    """torch CPU threads for training (0: torch's choice)."""


#: The demo's largest --epochs, --episodes and --control-steps: it is the small default job, and larger
#: values (1e9 was tried) only make it run for days; piga-train-model and piga-control take any.
DEMO_LIMITS = {"epochs": 200, "episodes": 100, "control_steps": 5000}
_DEMO_WHY = "piga-demo is the small default job; piga-train-model and piga-control run larger ones"


def build_parser() -> ArgumentParser:
    d = DemoConfig()
    p = ArgumentParser(
        prog=PROG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run piga's main job on small defaults (4.5 minutes on 2 idle cores, measured).\n"
        "Four stages, then one summary:\n"
        "  [1/4] collect: pixel-pendulum sequences with random actions into\n"
        "        OUT/pendulum.h5 (piga-collect)\n"
        "  [2/4] show: a strip of their frames, OUT/frames.png (piga-show)\n"
        "  [3/4] train: the world model, fast preset, into OUT/model\n"
        "        (piga-train-model)\n"
        "  [4/4] control from pixels with the learned model (piga-control): upright\n"
        "        at gravity x1.0, upright at x1.4 told to the agent, and to a goal\n"
        "        image at --goal-angle (OUT/goal.png) that it writes with Gymnasium's\n"
        "        renderer and reads with the encoder; the table goes to OUT/control.md\n"
        "The summary: the learned g and a with their errors, the training minutes,\n"
        "and each control task's success rate, final angle error and plan time.")
    p.add_argument("--out", default=d.out, help="output folder (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=d.sequences, help="sequences to collect (default %(default)s)")
    p.add_argument("--epochs", type=int_up_to(DEMO_LIMITS["epochs"], _DEMO_WHY),
                   help="training epochs (default: the fast preset's)")
    p.add_argument("--episodes", type=int_up_to(DEMO_LIMITS["episodes"], _DEMO_WHY), default=d.episodes,
                   help="control episodes per task (default %(default)s)")
    from piga.control.episodes import EpisodeConfig

    hold = EpisodeConfig.hold_steps  # as piga-control: with fewer steps a success held for a step or two meant nothing
    p.add_argument("--control-steps", type=int_up_to(DEMO_LIMITS["control_steps"], f"success is the goal held for the "
                                                     f"last {hold} steps; {_DEMO_WHY}", least=hold),
                   default=d.control_steps,
                   help="steps per control episode (default %(default)s)")
    p.add_argument("--goal-angle", type=float, default=d.goal_angle,
                   help="angle of the goal image, degrees from upright (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=d.seed, help="seed of data, training and control (default %(default)s)")
    p.add_argument("--threads", type=thread_count, default=d.threads,
                   help="torch CPU threads for training (default %(default)s: torch's choice); control plans on one "
                   "thread per worker")
    p.add_argument("--overwrite", action="store_true", help="replace files of an earlier demo in --out")
    p.add_argument("--resume", action="store_true",
                   help="continue an earlier demo in --out (one that was interrupted): keep its data (give the same "
                   "--sequences and --seed; other values are refused), continue its training (piga-train-model "
                   "--resume), and redo the frames and the control")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars (the stages, a line per training checkpoint and the summary are still printed)")
    return p


def _written_by_demo(path: Path) -> bool:
    """Whether ``path`` may be the data file piga-demo collected: an HDF5 file whose ``command`` attribute names
    piga-demo, or one too damaged to read it (a demo's, cut short: --resume and --overwrite say what to do)."""
    try:
        with open_data_file(path) as f:
            command = f.attrs.get("command")
    except (OSError, ValueError):
        with open(path, "rb") as f:
            return f.read(8) == b"\x89HDF\r\n\x1a\n"  # HDF5's signature
    return isinstance(command, str) and command.startswith(PROG)


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    check_folder_target(out)
    if (out / CHECKPOINT).exists():  # its lock would have called that run "still being trained" while the demo ran
        raise PigaError(f"--out {out} holds a run of its own ({CHECKPOINT}); a demo writes its data, pictures and run "
                        "(in --out/model) into a folder of its own: give another --out")
    collect_config = replace(CollectConfig(), sequences=args.sequences, seed=args.seed)
    from piga.cli.control import check_angle

    # the values first: a wrong one is the line, whatever the folder holds (not "exists from an earlier demo")
    check_angle("--goal-angle", args.goal_angle)
    _check_enough_sequences(collect_config)
    data, strip, run_dir = out / "pendulum.h5", out / "frames.png", out / DEMO_RUN
    goal_png, control_md = out / "goal.png", out / "control.md"
    outputs = (data, strip, run_dir / CHECKPOINT, goal_png, control_md)
    lock_run_folder(out)  # a second command on this folder is refused until this one ends
    if (settled := _settle_demo(out, data, run_dir)) is not None:  # an --overwrite killed outright: before its checks
        print(settled)
    for name in DEMO_FILES:  # a killed demo's half-written files: a demo that keeps its data never writes them again
        remove_stale_partials(out / name)
    if not args.overwrite and not args.resume:  # before the disk: an earlier demo's files would count as taken there
        _check_not_the_users(data)
        for path in outputs:
            if path.exists():
                raise PigaError(f"{path} exists from an earlier demo; pass --resume to continue that demo or "
                                "--overwrite to replace it")
    check_demo_disk(out, collect_config, args.resume, args.overwrite)  # /proc, /sys: "removed or moved while it ran?"
    if args.resume and args.overwrite:
        raise PigaError("--resume continues the demo in --out and --overwrite replaces it; give one of them")
    if args.resume and not any(path.exists() for path in outputs):
        raise PigaError(f"--resume: {out} holds no earlier demo to continue; run without --resume")
    if args.resume and (run_dir / CHECKPOINT).exists():  # before anything is made again: not this demo's kind of run
        from piga.io.checkpoint import RunKind, checked_run_kind

        try:
            kind = checked_run_kind(run_dir)
        except ValueError as exc:
            raise PigaError(f"--resume: {' '.join(str(exc).split())}; pass --overwrite (not --resume) to start the demo "
                            "over") from None
        if kind is not RunKind.PIGA:
            raise PigaError(f"--resume: {run_dir} holds a {kind.writer} run, not the piga-train-model run of a demo; "
                            "pass --overwrite (not --resume) to start the demo over")
    if args.overwrite or args.resume:  # (without either, checked above; with one, after what their checks say)
        _check_not_the_users(data)
    # (a demo that kept only its pictures continues from the start: they are made again)
    before = {path: path.exists() and path.stat().st_mtime_ns for path in outputs}
    checkpoint = run_dir / CHECKPOINT

    def trained() -> bool:  # this demo's model has a checkpoint of its own
        return checkpoint.exists() and checkpoint.stat().st_mtime_ns != before[checkpoint]

    removed: list[str] = []  # the earlier demo's control pages, removed once this demo has a model of its own
    try:
        with made_folder(out), replacing() as replaced:
            if args.overwrite:  # the earlier demo's files wait in --out/.replaced until this demo's first checkpoint
                replaced.set_aside(out, DEMO_FILES)  # (its run in model/: piga-train-model --overwrite does the same)
            try:
                return _run(args, argv, out, collect_config, data, strip, run_dir, goal_png, control_md)
            except BaseException as exc:
                if trained():  # the data stays with the model, for --resume; an earlier demo is given up
                    replaced.drop()
                    for path in (goal_png, control_md):  # an earlier model's control table: not this model's
                        if before[path] is not False and path.exists() and path.stat().st_mtime_ns == before[path]:
                            path.unlink()
                            removed.append(path.name)
                elif not isinstance(exc, KeyboardInterrupt) or replaced.moved:
                    # refused before a model, the files this demo made would make the rerun refuse for them; an
                    # earlier demo that it replaces comes back (replacing) as it was, without them
                    for path in (out / name for name in DEMO_FILES):
                        if before[path] is False and path.exists():
                            path.unlink()
                raise
    except KeyboardInterrupt:  # say what this demo kept (a step's own message would name its own command): all of it
        # where it was resumed (its data file, kept from the run it continues, was left out), else what this run made
        kept = [str(path.relative_to(out)) for path in outputs
                if path.exists() and (args.resume or path.stat().st_mtime_ns != before[path])]
        if kept:
            raise Interrupted(f"{out} keeps {', '.join(kept)} from this demo{_removed(removed)}; run the same command "
                              f"with {resume_option(args.overwrite)} to continue it, or with --overwrite to start "
                              "over") from None
        if args.overwrite and any(before[path] is not False for path in outputs):
            raise Interrupted(f"nothing was written; {out} holds the earlier demo as it was") from None
        raise KeyboardInterrupt from None
    except PigaError as exc:
        if trained() and _kept(out) not in str(exc):  # (a training that did not learn said it, with its fix)
            raise PigaError(f"{' '.join(str(exc).split())}; {out} keeps this demo's data and model"
                            f"{_removed(removed)}: run it with --resume to continue it (and a larger --epochs where "
                            "the training used all its planned steps), or with --overwrite to start over") from None
        if removed:
            raise PigaError(f"{' '.join(str(exc).split())}{_removed(removed)}") from None
        raise


def _removed(names: list[str]) -> str:
    """Says which of the earlier demo's control pages (goal.png, control.md) a resumed demo removed: they described
    the model it replaced, and its own control stage did not run."""
    if not names:
        return ""
    were = "was" if len(names) == 1 else "were"
    return f" ({' and '.join(names)} of the earlier demo, made with its model, {were} removed)"


def _kept(out: Path) -> str:
    return f"{out} keeps this demo's data and model"


def _longer(out: Path, planned: int, steps: int, need: Need = "length", epochs: int = 0) -> str:
    """The demo's way to train its model longer than the ``planned`` steps in ``epochs`` epochs, said where the
    training did not converge in place of piga-train-model's (--max-minutes and --budget-steps are not the demo's
    options). As ``need`` says: where it did not learn the motion at all, more --sequences comes first; where its file
    had no test split, more --sequences alone. Where the run planned the demo's most epochs or more, a larger --epochs
    is piga-train-model's, on the demo's run."""
    more = "--overwrite and more --sequences"
    if need == "split":  # (the default split's fractions: what the demo collects)
        fewest = fewest_filling(CollectConfig().split)
        return f"run the demo again with --overwrite and --sequences {fewest} or more, which leave it a test split"
    cap = DEMO_LIMITS["epochs"]
    if epochs >= cap:  # (the fast preset plans a tiny file past it: 2 sequences, 2000 epochs of a step each)
        return (f"run the demo again with {more} (its training took {steps} of {planned} planned steps in "
                f"{counted(epochs, 'epoch')}, and the demo's --epochs is at most {cap}), or train it longer with "
                f"piga-train-model {out / 'pendulum.h5'} --out {out / DEMO_RUN} --resume --epochs {2 * epochs} and "
                f"then run the demo again with --resume; {_kept(out)}")
    longer = f"--resume and a larger --epochs, up to {cap} (its training took {steps} of {planned} planned steps)"
    first, then = (more, longer) if need == "data" else (longer, more)
    return f"run the demo again with {first}, or with {then}; {_kept(out)}"


#: The demo's own files in --out, beside its run (model/): what an --overwrite sets aside until its first checkpoint.
DEMO_FILES = ("pendulum.h5", "frames.png", "goal.png", "control.md")


def _settle_demo(out: Path, data: Path, run_dir: Path) -> str | None:
    """Settles the earlier demo that an ``--overwrite`` killed outright (SIGKILL) left in ``out/.replaced``: its run's
    own first (:func:`piga.io.replaced.settle_replaced`); then the earlier demo's files are deleted where the run in
    ``run_dir`` has a checkpoint trained on the new data file and not on theirs (the new demo got that far), and put
    back otherwise. Returns a line that says which, or None where there was nothing to settle."""
    from piga.io.checkpoint import REPLACED_ASIDE
    from piga.io.replaced import settle_replaced, settle_set_aside

    aside = out / REPLACED_ASIDE
    if not aside.is_dir() or aside.is_symlink():
        return None
    settle_replaced(run_dir)
    new = ((run_dir / CHECKPOINT).is_file() and data.is_file() and _trained_on(run_dir, data, strict=True)
           and not ((aside / data.name).is_file() and _trained_on(run_dir, aside / data.name, strict=True)))
    return settle_set_aside(out, DEMO_FILES, new, "the earlier demo", "demo")


def _check_resumed_epochs(run_dir: Path, data: Path, epochs: int) -> None:
    """Refuses a resumed demo's --epochs below the epochs its run planned, as piga-train-model --resume does, before
    the demo's earlier stages run again; a run trained on other data (trained anew) or that does not read is left to
    the training."""
    from piga.io.checkpoint import RunKind, read_checkpoint

    if not ((run_dir / CHECKPOINT).is_file() and _trained_on(run_dir, data, strict=True)):
        return
    try:
        planned = read_checkpoint(run_dir, RunKind.PIGA).get("plan") or {}
    except (OSError, ValueError):
        return
    if isinstance(planned.get("epochs"), int) and epochs < planned["epochs"]:
        raise PigaError(f"--resume --epochs {epochs}: the run already planned {planned['epochs']} epochs "
                        f"({planned['epochs'] * planned.get('steps_per_epoch', 0)} steps); --resume may raise --epochs, "
                        "never lower them")


def _trained_on(run_dir: Path, data: Path, strict: bool = False) -> bool:
    """Whether the run in ``run_dir`` trained on the contents of ``data`` (its checkpoint's fingerprint of its file).
    A checkpoint without one, or one that does not read, counts as True (piga-train-model --resume then says what is
    wrong), or as False where ``strict``; so does a data file that does not read."""
    from piga.data.schema import has_fingerprint
    from piga.io.checkpoint import RunKind, read_checkpoint

    try:
        trained = read_checkpoint(run_dir, RunKind.PIGA).get("data", {}).get("fingerprint")
        if trained is None:
            return not strict
        return has_fingerprint(data, trained)
    except (OSError, ValueError):
        return not strict


def _check_not_the_users(data: Path) -> None:
    """Refuses a --out whose pendulum.h5 is a file of the user's, which --overwrite would destroy."""
    if data.exists() and not _written_by_demo(data):
        raise PigaError(f"{data} exists and is not a piga-demo's data file; give another --out (a demo writes "
                        "pendulum.h5, frames.png, model/, goal.png and control.md into it)")


def check_demo_disk(out: Path, config: CollectConfig, resume: bool, overwrite: bool = False) -> None:
    """Refuses, before anything is made, a --out whose disk cannot hold the whole demo: its data file (about
    :func:`piga.data.collect.disk_need`'s size, and the room the writer keeps free as it writes it), the fast preset's
    training run (:func:`piga.io.resources.run_disk_need`) and the pictures and table
    (:data:`piga.io.resources.FIGURE_DISK_BYTES`); a resumed demo less what its data file and checkpoint already take,
    one that replaces an earlier demo (``overwrite``) less its checkpoint (its data file is written beside the old one).

    Raises:
        piga.io.resources.ResourceError: the whole need, its parts, and the free space.
    """
    import torch

    from piga.data.collect import disk_need
    from piga.data.schema import write_room
    from piga.io.resources import FIGURE_DISK_BYTES, adam_checkpoint_bytes, check_disk, format_bytes, run_disk_need
    from piga.training.train import PRESETS
    from piga.world.variants import build_model

    data, run_dir = out / "pendulum.h5", out / DEMO_RUN
    file_bytes, slice_bytes, sequences = disk_need(config)
    kept = resume and data.is_file()  # the earlier demo's data: kept, not written again
    collecting = 0.0 if kept else file_bytes + write_room(slice_bytes, sequences)
    with torch.device("meta"):  # its size only: no memory taken
        checkpoint_bytes = adam_checkpoint_bytes(build_model(PRESETS["fast"].model))
    run_bytes, _ = run_disk_need(run_dir, checkpoint_bytes, resume=resume, overwrite=overwrite)
    replaced = (resume or overwrite) and (run_dir / CHECKPOINT).is_file()
    data_part = f"the data file, about {format_bytes(file_bytes)}; " if not kept else ""
    check_disk(data, max(collecting, (0.0 if kept else file_bytes) + run_bytes + FIGURE_DISK_BYTES), f"--out {out}",
               advice="free some space" if resume else "free some space, or give another --out",
               detail=f" for the whole demo ({data_part}the training run, {format_bytes(run_bytes)} for its "
                      f"checkpoints of {format_bytes(checkpoint_bytes)}, metrics and figures"
                      f"{', less the checkpoint it replaces' if replaced else ''}; "
                      f"and {format_bytes(FIGURE_DISK_BYTES)} kept free for its pictures and table)")


def _check_enough_sequences(config: CollectConfig) -> None:
    """Refuses, before anything is collected, a --sequences whose train split holds fewer training windows than
    the fast preset's one batch (piga-train-model would refuse the file, and piga-demo has no --batch-size)."""
    from piga.data.collect import split_counts
    from piga.training.train import PRESETS

    recipe = PRESETS["fast"]
    n_train = split_counts(config.sequences, config.split)[0]
    per_sequence = max(0, config.steps - recipe.model.window + 1)
    if n_train * per_sequence < recipe.train.batch_size:
        least = next(n for n in range(config.sequences, 10**6)
                     if split_counts(n, config.split)[0] * per_sequence >= recipe.train.batch_size)
        raise PigaError(f"--sequences {config.sequences} gives {counted(n_train, 'train sequence')}, "
                        f"{counted(n_train * per_sequence, 'training window')}, fewer than one batch of "
                        f"{recipe.train.batch_size}; give --sequences {least} or more")


def _check_kept_data(data: Path, config: CollectConfig) -> None:
    """Refuses to continue on a kept data file that another --sequences or --seed collected, or that is damaged."""
    from piga.data.schema import DataFormatError

    try:
        info = inspect_dataset(data)
    except DataFormatError as exc:  # (its own line named no way out)
        raise PigaError(f"--resume: {exc}; pass --overwrite (not --resume) to start the demo over") from None
    seed = info.attrs.get("seed")
    if info.system != "pendulum" or info.n_sequences != config.sequences or seed != config.seed:
        raise PigaError(f"--resume: {data} holds {info.n_sequences} {info.system} sequences collected with seed {seed}, "
                        f"not this command's --sequences {config.sequences} --seed {config.seed}: give the earlier "
                        "demo's values, or pass --overwrite (not --resume) to start over")


def _run(args: argparse.Namespace, argv: Sequence[str] | None, out: Path, config: CollectConfig, data: Path, strip: Path,
         run_dir: Path, goal_png: Path, control_md: Path) -> int:
    """The demo's four steps, into the folder ``out`` (made by the caller); ``config`` collects the data."""
    redo = ["--overwrite"] if args.overwrite or args.resume else []  # the strip: made again from the data
    if args.resume and data.exists():
        _check_kept_data(data, config)
        if args.epochs is not None:  # before the strip is drawn again: piga-train-model --resume refuses fewer
            _check_resumed_epochs(run_dir, data, args.epochs)
        print(f"[1/4] keeping the {args.sequences} sequences in {data} (collected by the earlier demo)", flush=True)
    else:
        print(f"[1/4] collecting {args.sequences} sequences into {data}", flush=True)
        collect(config, data, overwrite=args.overwrite, command=command_line(PROG, argv), progress=not args.quiet)
    print(f"[2/4] saving a strip of frames to {strip}", flush=True)
    show.main([str(data), "--out", str(strip), *redo])
    if args.resume and (run_dir / CHECKPOINT).exists() and not _trained_on(run_dir, data):
        # an --overwrite with another --seed, stopped after its collection and before its first checkpoint, left the
        # earlier demo's run beside the new data: piga-train-model --resume refuses it, so it is trained anew
        print(f"[3/4] training the world model into {run_dir} anew (fast preset): the run there trained on an earlier "
              f"demo's data, not on {data}", flush=True)
        how = ["--overwrite"]
    elif args.resume and (run_dir / CHECKPOINT).exists():
        print(f"[3/4] continuing the training in {run_dir} (piga-train-model --resume)", flush=True)
        how = ["--resume"]
    else:  # (an earlier demo interrupted before its first checkpoint left no run to continue)
        print(f"[3/4] training the world model into {run_dir} (fast preset)", flush=True)
        how = ["--overwrite"] if args.overwrite or args.resume else []
    trained = train.main([str(data), "--out", str(run_dir), "--seed", str(args.seed), *how,
                          *(["--epochs", str(args.epochs)] if args.epochs else []),
                          *(["--threads", str(args.threads)] if args.threads else []),
                          *(["--quiet"] if args.quiet else [])], prog=PROG,
                         longer=lambda planned, steps, need, epochs: _longer(out, planned, steps, need, epochs))
    import json

    from piga.evaluation.evaluate import true_and_error

    metrics = json.loads((run_dir / "metrics.json").read_text())
    info = inspect_dataset(data)
    errs = metrics["parameter_errors"]
    print(f"[4/4] control from pixels with the learned model: upright, gravity x1.4, goal image at {args.goal_angle:g} deg",
          flush=True)
    rows = _control(run_dir, goal_png, control_md, args)
    print("summary: " + ", ".join(f"{n}: learned {e['learned']:.4f}, {true_and_error(e)}"
                                  for n, e in errs.items())
          + f"; {info.n_sequences} sequences, {metrics['training']['seconds'] / 60:.1f} min of training")
    for label, s in rows:
        print(f"summary: {label}: success {100 * s['success_rate']:.0f}% of {s['episodes']}, final angle error "
              f"{s['final_angle_error_deg']:.2f} deg, plan {s['plan_ms_median']:.1f} ms/step")
    print(f"summary: see {out}/ (frames.png, model/*.png, goal.png, control.md)")
    return trained  # a model that did not converge: its warning above, and its exit status


def _control(run_dir: Path, goal_png: Path, control_md: Path, args) -> list[tuple[str, dict]]:  # noqa: ANN001
    """Upright at x1.0 and x1.4, and to the goal image; writes goal.png and control.md."""
    import math
    from dataclasses import replace as dc_replace

    from agents.mpc import MPCConfig
    from piga.io.atomic import atomic_output
    from piga.cli import control as control_cli
    from piga.control.episodes import EpisodeConfig
    from piga.evaluation.episodes import summary_markdown, summary_row
    from piga.control.jobs import ControlJob, run_jobs
    from piga.control.goal import goal_from_image
    from piga.io.runs import load_model

    redo = args.overwrite or args.resume  # the goal image and the table: made again from the model
    control_cli.main(["--write-goal-image", str(goal_png), "--angle", str(args.goal_angle),
                      *(["--overwrite"] if redo else [])])
    model, ckpt = load_model(run_dir)
    estimate = goal_from_image(model, ckpt, goal_png)
    for warning in estimate.warnings:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    mpc = MPCConfig(seed=args.seed)
    episodes = EpisodeConfig(episodes=args.episodes, seed=args.seed, steps=args.control_steps)
    jobs = [
        ControlJob("piga", episodes, mpc, str(run_dir), tags=(("task", "upright, gravity x1.0"),)),
        ControlJob("piga", dc_replace(episodes, gravity_mult=1.4), mpc, str(run_dir), tags=(("task", "upright, gravity x1.4"),)),
        ControlJob("piga", dc_replace(episodes, goal_angle=math.radians(args.goal_angle)),
                   dc_replace(mpc, goal_angle=estimate.angle), str(run_dir),
                   tags=(("task", f"goal image at {args.goal_angle:g} deg (read {math.degrees(estimate.angle):.2f})"),)),
    ]
    summaries = [r.summary for r in run_jobs(jobs, workers=2, progress=False)]
    with atomic_output(control_md, overwrite=redo) as tmp:
        tmp.write_text("# piga-demo: control from pixels\n\n" + summary_markdown(summaries, extra=[("task", "task")]), encoding="utf-8")
    return [(s.labels["task"], summary_row(s)) for s in summaries]


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
