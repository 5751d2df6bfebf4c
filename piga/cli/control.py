"""``piga-control --model RUN_DIR``: control the pixel pendulum from pixels with CEM over the learned physics."""

from __future__ import annotations

import argparse
import os
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agents.config import MPCConfig
from envs import DMC_PENDULUM, ENV_IDS, PIXEL_PENDULUM
from envs.effects import EFFECTS, normalize_effects
from envs.fields import number_text
from envs.pendulum import MAX_GRAVITY, MIN_GRAVITY, PixelPendulumConfig
from piga.io.atomic import (atomic_output, check_file_name, check_not_an_input, check_writable_target, write_json,
                             written_together)
from piga.cli.common import (ArgumentParser, PigaError, add_ray_option, check_model_folder, command_line, connect_backend,
                             given_options, int_up_to, positive_float, positive_int, run_cli, seed_int,
                             stem_path, typed_text, warn_if_still_training, warn_if_unconverged, work_finished)
from piga.control.episodes import EpisodeConfig, parse_range, run_episodes
from piga.evaluation.episodes import summary_markdown
from piga.io.checkpoint import RunKind, recorded_data_path
from piga.io.lock import lock_run_folder

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from agents.sb3.run import SB3Agent
    from envs.dmc import DMCPendulumConfig
    from agents.mpc import PigaMPCAgent
    from piga.world.model import PhysicsModel

# torch, the agents and the model are imported once the arguments are checked: a mistyped
# command is answered at once, without the seconds that importing torch takes.

PROG = "piga-control"


def build_parser() -> ArgumentParser:
    episodes, mpc = EpisodeConfig(), MPCConfig()
    cem = mpc.cem
    p = ArgumentParser(prog=PROG, description="Swing up and hold the pixel pendulum with model-predictive control "
                       "(CEM) over a trained piga model, from frames alone.")
    p.add_argument("--model", help="run folder of piga-train-model, or of piga-baseline (planet, ddpg: run as trained, "
                   "no goals); not needed with --oracle")
    p.add_argument("--env", choices=ENV_IDS, default=PIXEL_PENDULUM,
                   help="the env: Gymnasium's pixel pendulum, or dm_control's (needs piga[dmc]): then both the piga "
                   "agent (with --model) and the oracle run 10 episodes of 1000 physics steps with the energy-aware "
                   "swing-up planner, scored in DMC's units (max 1000); it takes --model, --oracle, --episodes, "
                   "--seed, --env-option, --out, --overwrite and --quiet (default %(default)s)")
    p.add_argument("--env-option", action="append", default=[], metavar="KEY=VALUE",
                   help="with --env piga/DMCPendulum-v0: a field of its config, repeatable (mass, length, damping, "
                   "action_repeat, flip, shadows), as for piga-collect")
    p.add_argument("--oracle", action="store_true", help="plan with the true state and true parameters instead")
    p.add_argument("--episodes", type=int_up_to(EpisodeConfig.MAX_EPISODES, "more would run for days"), default=episodes.episodes,
                   help="episodes (default %(default)s); episode 0 starts hanging down")
    p.add_argument("--steps", type=int_up_to(EpisodeConfig.MAX_STEPS, f"success is the goal held for the last "
                                             f"{episodes.hold_steps} steps; the most is 500 times Gymnasium's episode",
                                             least=episodes.hold_steps), default=episodes.steps,
                   help=f"steps per episode, at least {episodes.hold_steps}: success is the goal held for the last "
                   f"{episodes.hold_steps} (default %(default)s)")
    p.add_argument("--gravity-mult", type=positive_float, default=episodes.gravity_mult,
                   help=f"multiply the environment's gravity ({PixelPendulumConfig.gravity:g} m/s²; the product must lie "
                   f"in [{MIN_GRAVITY:g}, {MAX_GRAVITY:g}]); the agent is told and scales its learned g "
                   "(default %(default)s)")
    p.add_argument("--not-told", action="store_true",
                   help="do not tell the piga agent --gravity-mult (nor, with --sweep, each multiplier): the environment's "
                   "gravity changes while the agent plans with its learned g unscaled, as the baselines do (the oracle "
                   "is always told)")
    p.add_argument("--goal-angle", type=float, default=math.degrees(mpc.goal_angle),
                   help="goal angle in degrees, 0 = upright (default %(default)g)")
    p.add_argument("--goal-image", help="PNG or JPEG of the scene at the goal; the encoder reads the goal angle from it "
                   "(refused when no render of the pendulum at any angle comes close to it)")
    p.add_argument("--write-goal-image", metavar="PATH", help="only write Gymnasium's picture of the pendulum at --angle to PATH, then exit")
    p.add_argument("--angle", type=float, help="with --write-goal-image: the angle in degrees (0 = upright, counter-clockwise)")
    p.add_argument("--horizon", type=positive_int, default=cem.horizon, help="CEM planning horizon H (default %(default)s)")
    p.add_argument("--candidates", type=positive_int, default=cem.candidates,
                   help="CEM candidates per iteration, >= 2 (default %(default)s)")
    p.add_argument("--elites", type=positive_int,
                   help=f"CEM elites that refit the sampling distribution, <= --candidates (default: the same share of "
                   f"the candidates as {cem.elites} of {cem.candidates})")
    p.add_argument("--iterations", type=positive_int, default=cem.iterations, help="CEM iterations (default %(default)s)")
    p.add_argument("--warm-start", action=argparse.BooleanOptionalAction, default=mpc.warm_start,
                   help="start each plan from the previous one shifted by a step; PlaNet re-plans from scratch "
                   "(--no-warm-start) (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=episodes.seed, help="seed of start states and planner (default %(default)s)")
    p.add_argument("--torque-arrow", action="store_true",
                   help="show Gymnasium's torque arrow in the frames the agent sees (off by default; see README)")
    p.add_argument("--sweep", metavar="START:STOP:STEP",
                   help="run the piga agent and the oracle at each gravity multiplier of the range (e.g. 0.5:1.8:0.1); "
                   "each agent is told the multiplier (the piga agent not, with --not-told: its rows say 'piga (not told)'). "
                   "Writes a table and, with --out, OUT.png")
    p.add_argument("--workers", type=positive_int, default=2,
                   help="processes for --sweep, and for a baseline run's episodes (split over them, into as many "
                   "parts with --ray; the same episodes and scores as one process) (default %(default)s)")
    add_ray_option(p, "the jobs of --sweep, and the parts of a baseline run's episodes")
    p.add_argument("--video", help="write episode 0 as .mp4 or .gif: real frames | the model's belief | its plan "
                   "(a PlaNet-style run: real frames | its world model's reconstruction; DDPG: the real frames)")
    p.add_argument("--out", type=stem_path,
                   help="write the results to OUT.json and a Markdown table to OUT.md (and OUT.png with --sweep)")
    p.add_argument("--overwrite", action="store_true", help="replace existing --out files")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    given = given_options(parser, argv)  # the options written, at the default's value too
    if args.env == DMC_PENDULUM:
        return _dmc(args, argv, given)
    if args.env_option:
        raise PigaError(f"--env-option is for --env {DMC_PENDULUM}")
    if args.write_goal_image:
        if args.model or args.oracle:
            raise PigaError("--write-goal-image only writes a picture and exits; it takes no --model or --oracle")
        if ignored := _ignored_options(args, given, GOAL_IMAGE_OPTIONS):
            raise PigaError(f"--write-goal-image only writes a picture and exits; drop {', '.join(ignored)}")
        return _write_goal_image(args)
    if args.angle is not None:
        raise PigaError("--angle goes with --write-goal-image; to set the control goal use --goal-angle or --goal-image")
    if not args.oracle and not args.model:
        raise PigaError("give --model RUN_DIR (or --oracle)")
    if args.torque_arrow and args.oracle and not args.model:
        raise PigaError("--torque-arrow shows the arrow in the frames the agent sees; the oracle plans on the true state "
                        "and sees no frames: drop --torque-arrow")
    if args.not_told and args.oracle and not args.sweep:
        raise PigaError("--not-told is for the piga agent; the oracle plans with the environment's true physics")
    check_angle("--goal-angle", args.goal_angle)
    args.goal_angle += 0.0  # -0.0 (-1e-400 underflows to it) is 0: "goal -0 deg" otherwise
    if args.goal_image and "goal_angle" in given:  # --goal-angle 0, the default, too
        raise PigaError("--goal-image sets the goal (the encoder reads its angle); drop --goal-angle")
    _check_env_gravity(f"--gravity-mult {number_text(args.gravity_mult)}", args.gravity_mult)
    mpc = _mpc_config(args, math.radians(args.goal_angle))
    _check_total_work(args, mpc)
    outputs = []
    if args.out:
        stem = Path(args.out)  # OUT.json, OUT.md: appended, so a stem such as "x1.4" keeps its dot
        stem = stem.with_suffix("") if stem.suffix.lower() in (".json", ".md", ".png") else stem
        outputs = [stem.with_name(stem.name + s) for s in (".json", ".md", *((".png",) if args.sweep else ()))]
        _check_out_set(outputs, args)
        # a second command given the same --out is refused now, not after its episodes, when it found these files
        lock_run_folder(stem, "--out")
    kind = _run_kind(args)
    if kind.is_baseline:
        return _baseline(args, kind, mpc, outputs, argv, given)
    if args.model:  # (before --workers is judged by the run's kind; the sweep's loader named a piga-train-model folder)
        check_model_folder(args.model)
    if args.sweep:
        return _sweep(args, mpc, outputs, argv, given)
    if args.not_told and args.gravity_mult == 1.0:  # (a baseline run is refused --not-told above, in its own words)
        at, change = ((f"--gravity-mult {number_text(args.gravity_mult)}", "give another --gravity-mult")
                      if "gravity_mult" in given else ("--gravity-mult 1 (the default)", "give --gravity-mult"))
        raise PigaError(f"--not-told keeps the piga agent's gravity at x1 while the env's changes; at {at} nothing "
                        f"changes: {change}, or drop --not-told")
    if args.ray or "workers" in given:  # --workers 2, the default, too
        raise PigaError(f"{'--ray' if args.ray else '--workers'} runs the jobs of --sweep and a baseline run's episodes; a "
                        "piga or oracle run without --sweep plays its episodes in this process")
    if args.video:
        check_file_name(args.video, "--video", "episode.mp4")
        if Path(args.video).suffix.lower() not in (".mp4", ".gif"):
            raise PigaError(f"--video must end in .mp4 or .gif, got {args.video}")
        check_not_an_input(args.video, {"--goal-image": args.goal_image} if args.goal_image else {}, flag="--video")
        if args.oracle:
            raise PigaError("--video shows the model's belief and plan; it needs --model, not --oracle")
        check_writable_target(args.video, args.overwrite)
        from piga.evaluation.video import check_video_room

        check_video_room(args.video, args.steps)  # before the episode it shows is played
    import torch

    from agents.mpc import OracleAgent, PigaMPCAgent
    from piga.io.runs import load_model

    torch.set_num_threads(1)  # small tensors: one thread plans fastest
    told = 1.0 if args.not_told else args.gravity_mult  # the multiplier the agent believes
    model = None
    if args.model:
        model, ckpt = load_model(args.model)
        check_pendulum_model(model, args.model)
        _check_plannable(model, args.model)  # before the goal image is read and the warnings: the one line
    if args.goal_image:
        if model is None:
            raise PigaError("--goal-image needs --model: the goal is read from the image by the model's encoder")
        from piga.control.goal import goal_from_image

        estimate = goal_from_image(model, ckpt, args.goal_image, gravity_mult=args.gravity_mult, told=told)
        for warning in estimate.warnings:
            print(f"{PROG}: warning: {warning}", file=sys.stderr)
        args.goal_angle = math.degrees(estimate.angle)
        print(f"goal read from {args.goal_image}: {args.goal_angle:.2f} deg (hold torque {estimate.hold_torque:+.2f} by the "
              "model's physics)")
        mpc = replace(mpc, goal_angle=estimate.angle)
    elif args.goal_angle:
        from piga.control.goal import hold_warning

        if (warning := hold_warning(mpc.goal_angle, args.gravity_mult)) is not None:  # the env's, told or not
            print(f"{PROG}: warning: {warning}", file=sys.stderr)
    if args.model:  # after every refusal, so that a refused command prints one line
        warn_if_unconverged(PROG, args.model)
        _warn_if_other_frames(args.model, ckpt)
        _warn_if_other_pixel_physics(ckpt, (args.gravity_mult,), told=not args.not_told)
    config = EpisodeConfig(episodes=args.episodes, steps=args.steps, seed=args.seed, gravity_mult=args.gravity_mult,
                           goal_angle=mpc.goal_angle, torque_arrow=args.torque_arrow)
    agent: OracleAgent | PigaMPCAgent
    first_trace: list[tuple[float, float, np.ndarray]] = []  # the piga agent's beliefs and plans in episode 0
    on_episode_end = None
    if model is None:
        agent = OracleAgent.for_env(config.env_config(), mpc)
        label = "oracle"
    else:
        agent = PigaMPCAgent(model, mpc, gravity_mult=told, keep_trace=bool(args.video))
        config = replace(config, frame_stack=agent.input_frames)
        label = f"piga{' (not told)' if args.not_told else ''} ({typed_text(args.model)})"  # as a sweep's rows say it
        on_episode_end = _keep_first_trace(agent, first_trace) if args.video else None
    result = run_episodes(agent, config, progress=not args.quiet, record=1 if args.video else 0,
                          on_episode_end=on_episode_end)
    s = result.summary
    print(f"{label}, gravity x{args.gravity_mult:g}, goal {args.goal_angle:g} deg: "
          f"success {100 * s.success_rate:.0f}% of {s.episodes}, mean return {s.mean_return:.1f}, final angle error {math.degrees(s.final_angle_error_mean):.2f} deg, "
          f"plan {s.plan_ms_median:.1f} ms median / {s.plan_ms_p95:.1f} ms p95")
    with written_together([*([args.video] if args.video else []), *outputs]):  # the video and --out: all or none
        if args.video:
            from piga.evaluation.video import control_video

            assert model is not None
            control_video(model, result.recordings[0].frames, first_trace, args.video, overwrite=args.overwrite)
        if outputs:
            result = result.labelled(agent=label)
            _write_outputs(outputs, {"agent": label, **result.to_dict(), "recordings": None},
                           f"# {PROG}\n\nCommand: `{command_line(PROG, argv)}`\n\n{summary_markdown([result.summary])}",
                           args.overwrite, model=args.model)
    _say_written(args.video, outputs)
    return 0


def _say_written(video: str | None, outputs: list[Path]) -> None:
    """The lines that name what was written, once all of it is (an interrupt inside :func:`written_together` removes
    the set again, after a "wrote" line had named it)."""
    if video or outputs:
        work_finished()
    if video:
        print(f"wrote {video}")
    if outputs:
        print(f"wrote {outputs[0]} and {outputs[1]}")


def _refuse_sweep_goal_image_and_video(args: argparse.Namespace) -> None:
    """--sweep takes its goal as an angle (--goal-angle, upright by default) and films nothing: a goal image is read
    and judged by a single run, and a video shows one run's episode 0, where a sweep plays many jobs in worker
    processes."""
    if args.goal_image:
        raise PigaError("--sweep gives each job its goal as an angle: give --goal-angle DEG, not --goal-image (a run "
                        "without --sweep reads the goal from an image)")
    if args.video:
        raise PigaError("--sweep plays its jobs in worker processes and films none of them: drop --video, or film one "
                        "multiplier in a run without --sweep (--gravity-mult M --video)")


def _sweep(args: argparse.Namespace, mpc: MPCConfig, outputs: list[Path], argv: Sequence[str] | None,
           given: set[str], kind: RunKind = RunKind.PIGA) -> int:
    """--sweep: the run's agent (``kind``) and the oracle at each multiplier; piga and the oracle are
    told the multiplier, a baseline runs as trained. ``given``: the options written
    (:func:`~piga.cli.common.given_options`)."""
    from piga.control.jobs import ControlJob, run_jobs
    from piga.io.runs import load_model

    if args.oracle or not args.model:
        raise PigaError("--sweep compares the piga agent with the oracle: give --model RUN_DIR (without --oracle)")
    _refuse_sweep_goal_image_and_video(args)
    if "gravity_mult" in given:  # --gravity-mult 1, the default, too
        raise PigaError("--sweep sets the gravity multiplier of each job; drop --gravity-mult")
    try:
        multipliers = parse_range(args.sweep)
    except ValueError as exc:
        raise PigaError(f"--sweep: {exc}") from None
    if multipliers[0] <= 0:
        raise PigaError(f"--sweep: gravity multipliers must be > 0 (at 10 decimals), got {args.sweep}")
    if len(set(multipliers)) < len(multipliers):  # a step below the 10 decimals kept
        raise PigaError(f"--sweep {args.sweep}: its step repeats multipliers at the 10 decimals kept; give a step of "
                        "1e-10 or more")
    for multiplier in (multipliers[0], multipliers[-1]):  # here: in a job it failed after the others had run
        _check_env_gravity("--sweep", multiplier)
    if args.not_told and all(m == 1 for m in multipliers):  # as a single run at x1 is refused --not-told
        raise PigaError(f"--not-told keeps the piga agent's gravity at x1 while the env's changes; at --sweep "
                        f"{args.sweep} (every multiplier x1) nothing changes: give a --sweep that leaves x1, or drop "
                        "--not-told")
    if kind is RunKind.PIGA:
        model, checkpoint = load_model(args.model)  # fail early, in this process, on a bad folder
        check_pendulum_model(model, args.model)
        _check_plannable(model, args.model)
    backend = connect_backend(args.ray)  # before the warning: a refused --ray is the one line on stderr
    from piga.control.goal import hold_warning

    if (warning := hold_warning(mpc.goal_angle, multipliers)) is not None:  # the env's: every agent plays in it
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    if kind is RunKind.PIGA:
        warn_if_unconverged(PROG, args.model)
        _warn_if_other_frames(args.model, checkpoint)
        _warn_if_other_pixel_physics(checkpoint, multipliers, told=not args.not_told, sweep=True)
    else:
        _warn_if_did_not_learn(args.model, kind)
        from piga.control.jobs import agent_name

        print(f"note: the {agent_name(kind.value, args.model)} agent runs as trained: it cannot be told that gravity "
              "changed")
    jobs = [ControlJob(agent, EpisodeConfig(episodes=args.episodes, steps=args.steps, seed=args.seed, gravity_mult=m,
                                            goal_angle=mpc.goal_angle, torque_arrow=args.torque_arrow),
                       mpc, model_dir=args.model if agent != "oracle" else None, told=agent == "oracle" or not args.not_told)
            for m in multipliers for agent in (kind.value, "oracle")]
    results = run_jobs(jobs, workers=args.workers, progress=not args.quiet, backend=backend)
    summaries = [r.summary for r in results]
    table = summary_markdown(summaries)
    print(table, end="")
    if outputs:
        from piga.evaluation.plots import sweep_figure

        # (the planner's settings too: --no-warm-start was said only in the page's command line)
        _write_outputs(outputs, {"model": typed_text(args.model), "command": command_line(PROG, argv),
                                 "planner": asdict(mpc), "multipliers": multipliers,
                                 "results": [r.to_dict() for r in results]},
                       f"# {PROG} --sweep\n\nCommand: `{command_line(PROG, argv)}`\n\n![sweep]({outputs[2].name})\n\n{table}",
                       args.overwrite, figure=lambda: sweep_figure([s.to_dict() for s in summaries]), model=args.model,
                       kind=kind)
        work_finished()
        print(f"wrote {', '.join(map(str, outputs))}")
    return 0


def _check_out_set(outputs: list[Path], args: argparse.Namespace) -> None:
    """Refuses, before the episodes, an ``--out`` set that could not be written: an existing file without
    --overwrite, a missing folder, a file system that stores no files (/proc, /sys: it failed after the episodes,
    as "removed or moved while it ran?"), or one of the command's inputs (the --model run's own files, whose
    metrics.json a control summary replaced, and the goal image)."""
    from piga.io.resources import check_figure_disk

    check_file_name(_stem(outputs), "--out", "results")
    inputs: dict[str, str | os.PathLike[str]] = {"--goal-image": args.goal_image} if args.goal_image else {}
    if args.model and Path(args.model).is_dir():
        inputs.update({f"--model run's {f.name}": f for f in Path(args.model).iterdir() if f.is_file()})
    for path in outputs:
        check_writable_target(path, args.overwrite)
        check_not_an_input(path, inputs)
    check_figure_disk(outputs[0], f"--out {outputs[0]}")


def _write_outputs(outputs: list[Path], record: dict[str, Any], page: str, overwrite: bool,
                   figure: Callable[[], Figure] | None = None, model: str | None = None,
                   kind: RunKind = RunKind.PIGA) -> None:
    """Writes ``--out``'s set: OUT.json (``record``), OUT.md (``page``) and, where there is a third path, OUT.png
    (``figure()``), all or none (:func:`~piga.io.atomic.written_together`): a failure part-way (a full disk) leaves
    nothing that would refuse the rerun. With the ``model`` run's folder, what its records say against it (it did not
    converge, or did not learn) goes into both as ``model_warning``: a success rate of a run that did not converge
    read as any other, the warning only on stderr."""
    if model:
        warning = _model_warning(model, kind)
        record = {**record, "model_warning": warning}
        if warning:
            title, _, rest = page.partition("\n\n")
            page = f"{title}\n\n**Warning:** {warning}\n\n{rest}"
    with written_together(outputs):
        write_json(outputs[0], record, overwrite=overwrite)
        with atomic_output(outputs[1], overwrite=overwrite) as tmp:
            tmp.write_text(page, encoding="utf-8")
        if figure is not None:
            from piga.evaluation.plots import save_figure

            save_figure(figure(), outputs[2], overwrite=overwrite)
    if figure is None and overwrite:  # an earlier sweep's OUT.png would sit beside a set that no longer draws it
        (stem := _stem(outputs)).with_name(stem.name + ".png").unlink(missing_ok=True)


def _model_warning(run_dir: str, kind: RunKind) -> str | None:
    """What the ``run_dir`` run's records say against it, as its warning line says it (None: nothing); the run's name
    as typed (:func:`~piga.cli.common.typed_text`: lone surrogates under a C locale cannot be written as UTF-8)."""
    if kind is RunKind.PIGA:
        from piga.io.runs import convergence_warning

        warning = convergence_warning(run_dir)
        warning = warning.removeprefix("warning: ") if warning else None
    else:
        warning = baseline_unfinished(run_dir)
        if warning is None and (why := baseline_did_not_learn(run_dir, kind)):
            warning = f"the run {run_dir} did not learn: {why}"
    return warning.encode("utf-8", "surrogateescape").decode("utf-8", "replace") if warning else None


def _stem(outputs: list[Path]) -> Path:
    """OUT, of the ``--out`` set OUT.json, OUT.md (, OUT.png)."""
    return outputs[0].with_name(outputs[0].name.removesuffix(".json"))


def _check_total_work(args: argparse.Namespace, mpc: MPCConfig) -> None:
    """Refuses, before anything runs, a command whose episodes, steps, multipliers and planner together would plan
    for days (each within its own cap), naming the total and the options that make it."""
    try:
        runs = 2 * len(parse_range(args.sweep)) if args.sweep else 1  # a sweep: the piga agent and the oracle at each
    except ValueError as exc:
        raise PigaError(f"--sweep: {exc}") from None
    steps = runs * args.episodes * args.steps
    made = (f"{runs} runs (--sweep's multipliers x 2 agents) x " if runs > 1 else "") + \
        f"--episodes {args.episodes} x --steps {args.steps}"
    if steps > EpisodeConfig.MAX_TOTAL_STEPS:
        raise PigaError(f"{made} = {steps:,} control steps, more than {EpisodeConfig.MAX_TOTAL_STEPS:,} (10,000 of "
                        "Gymnasium's episodes; more would plan for days); lower them, or split the work into commands")
    cem = mpc.cem
    imagined = steps * cem.candidates * cem.horizon * cem.iterations
    if imagined > EpisodeConfig.MAX_TOTAL_MODEL_STEPS:
        raise PigaError(f"{made} = {steps:,} plans of --candidates {cem.candidates} x --horizon {cem.horizon} x "
                        f"--iterations {cem.iterations} = {imagined:.3g} imagined model steps, more than "
                        f"{EpisodeConfig.MAX_TOTAL_MODEL_STEPS:.0e} (days of planning); lower them")


def _check_env_gravity(flag: str, gravity_mult: float) -> None:
    """Refuses a gravity multiplier that gives the pixel pendulum a gravity out of its range
    (:class:`PixelPendulumConfig`'s), before a model is read."""
    config = PixelPendulumConfig()
    try:
        replace(config, gravity_mult=gravity_mult)
    except ValueError as exc:  # the env's words ("PixelPendulumConfig: gravity x gravity_mult = ...") in the user's
        effective = config.gravity * gravity_mult
        bound = str(exc).split(" is out of range: ", 1)[-1]
        raise PigaError(f"{flag}: the gravity it gives, {config.gravity:g} x {number_text(gravity_mult)} = {number_text(effective)} m/s², "
                        f"is out of range: {bound}") from None


def _run_kind(args: argparse.Namespace) -> RunKind:
    """The kind of ``--model``'s run (piga for a piga-train-model run, or with --oracle alone)."""
    if not args.model:
        return RunKind.PIGA
    from piga.io.checkpoint import checked_run_kind

    kind = checked_run_kind(args.model)  # the checkpoint's word, before options are judged by the kind
    if args.oracle and kind.is_baseline:
        raise PigaError(f"--oracle: {args.model} is a {kind.writer} run, which runs as trained and knows no "
                        "physics to hand the oracle; drop --oracle to score the run, or drop --model to run the oracle")
    if args.oracle and not args.sweep:
        raise PigaError("give --model RUN_DIR to run the piga agent or --oracle to run the oracle, not both "
                        "(--sweep runs the two side by side)")
    return kind


def baseline_did_not_learn(run_dir: str | Path, kind: RunKind) -> str | None:
    """Why a baseline run did not learn, by the test ``piga-baseline`` exits 1 on, read off its metrics.json (PlaNet-style:
    :func:`agents.planet.train.did_not_learn`; DDPG, SAC, DrQ-v2: its evaluation return never reached its mark); None
    when it learned, or when the record cannot tell (a run stopped before its end has none)."""
    import json
    import warnings

    from piga.io.checkpoint import check_run_file

    check_run_file(Path(run_dir) / "metrics.json")  # a pipe: refused, not read (its open waits for ever)
    try:
        metrics = json.loads((Path(run_dir) / "metrics.json").read_text())
        if kind is RunKind.PLANET:
            from agents.planet.train import did_not_learn

            check = metrics["open_loop"]
            lists = [check[key] for key in ("frame_mse", "mean_frame_mse", "reward_abs_error", "zero_reward_abs_error")]
            numbers = [float(check["context"]), *(float(v) for values in lists for v in values)]
            if not all(lists) or not all(map(math.isfinite, numbers)):  # an edited record: it tells nothing
                return None
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return did_not_learn(check)
        from agents.sb3.train import first_step_reaching

        mark = float(metrics["learned_return"])
        if first_step_reaching(metrics["learning_curve"], mark) is not None:
            return None
        return f"its evaluation return never reached {mark:g} in {metrics['steps']} env steps"
    except (OSError, ValueError, KeyError, TypeError, IndexError, ArithmeticError):  # an edited record tells nothing
        return None


def baseline_unfinished(run_dir: str | Path) -> str | None:
    """The warning (without its "warning: ") for a baseline run with a checkpoint but no metrics.json: piga-baseline
    writes the record at its end, so the run was interrupted or killed (or it diverged, which its record says), and
    never checked for learning; else None."""
    from piga.io.checkpoint import CHECKPOINT, check_run_file, divergence_warning

    check_run_file(Path(run_dir) / "metrics.json")  # a pipe: refused, not tested
    if (Path(run_dir) / "metrics.json").exists() or not (Path(run_dir) / CHECKPOINT).exists():
        return None
    if (diverged := divergence_warning(run_dir)) is not None:  # (--resume would diverge again)
        return diverged
    return (f"the run {run_dir} has no metrics.json: it stopped before its end (interrupted, or killed) and was never "
            "checked for learning; this used its last checkpoint (continue it with piga-baseline --resume)")


def _warn_if_did_not_learn(run_dir: str, kind: RunKind) -> None:
    """One warning line for a baseline run that did not learn (:func:`baseline_did_not_learn`) or stopped before its
    end (:func:`baseline_unfinished`), as for a piga run that did not converge or stopped; after the command's
    refusals, so that a refused command prints one line."""
    if warn_if_still_training(PROG, run_dir):
        return
    if (unfinished := baseline_unfinished(run_dir)) is not None:
        print(f"{PROG}: warning: {unfinished}", file=sys.stderr)
    elif (why := baseline_did_not_learn(run_dir, kind)) is not None:
        print(f"{PROG}: warning: the run {run_dir} did not learn ({why}); these episodes score it all the same",
              file=sys.stderr)


def _baseline(args: argparse.Namespace, kind: RunKind, mpc: MPCConfig, outputs: list[Path], argv: Sequence[str] | None,
              given: set[str]) -> int:
    """A baseline run ("planet" or "ddpg") on the same episodes, starts, seeds and success definition as piga.

    It has no goal input and cannot be told a gravity change: goals are refused, and a gravity
    multiplier runs it as trained, saying so. The PlaNet-style agent plans with PlaNet's CEM settings
    (:class:`agents.planet.config.LatentPlannerConfig`), not with --horizon and the other CEM options. ``given``: the
    options written (:func:`~piga.cli.common.given_options`).
    """
    if kind is RunKind.DDPG:
        from agents.sb3.run import trained_env

        if (env := trained_env(args.model)) != PIXEL_PENDULUM:
            raise PigaError(f"{args.model} was trained on {env}; score it there with --env {env}")
    from piga.control.jobs import agent_name

    name = agent_name(kind.value, args.model)  # a DDPG run's algorithm (sac, drqv2) where its record names one
    why = f"a {name} run has no goal input (it learned to swing up to upright from the env's reward)"
    if args.goal_image:
        raise PigaError(f"--goal-image: {why}, so it cannot be given a goal image; goal images need a piga run")
    if args.goal_angle:
        raise PigaError(f"--goal-angle: {why}; only upright (0) can be scored")
    if args.not_told:
        raise PigaError(f"--not-told is for the piga agent; a {name} run is never told a gravity change (it runs as "
                        "trained)")
    if args.video:
        if args.sweep:
            _refuse_sweep_goal_image_and_video(args)
        check_file_name(args.video, "--video", "episode.mp4")
        if Path(args.video).suffix.lower() not in (".mp4", ".gif"):
            raise PigaError(f"--video must end in .mp4 or .gif, got {args.video}")
        check_writable_target(args.video, args.overwrite)
        from piga.evaluation.video import check_video_room

        check_video_room(args.video, args.steps)  # before the episodes: real frames | reconstruction
    planner = [_flag(args, name) for name in ("horizon", "candidates", "elites", "iterations", "warm_start")
               if name in given]
    if planner:
        raise PigaError(f"{', '.join(planner)}: a {name} run plans with its own settings "
                        f"({'PlaNet' + chr(39) + 's CEM' if kind is RunKind.PLANET else 'a policy, no planner'}); "
                        "the CEM options set the piga agent's and the oracle's planner")
    if kind is RunKind.PLANET:  # after the refusals of the command line: this reads the checkpoint
        check_planet_frames(args.model)
    if args.sweep:
        return _sweep(args, mpc, outputs, argv, given, kind=kind)
    import torch

    from piga.control.registry import baseline_agent

    torch.set_num_threads(1)
    agent = baseline_agent(kind, args.model, seed=args.seed)
    trained = getattr(agent, "config", None)
    trained_arrow = getattr(trained, "torque_arrow", None)
    sees_frames = getattr(trained, "obs", "pixels") != "state"  # a state policy never saw the arrow, shown or not
    if not sees_frames and args.torque_arrow and not args.video:
        raise PigaError(f"--torque-arrow shows the arrow in the frames; {args.model} acts on the state (--obs state) and "
                        "sees none, and no --video is written: drop --torque-arrow")
    split = bool(args.ray) or args.workers > 1 and args.episodes > 1  # latent CEM takes ~0.5 s a step: use the cores
    backend = connect_backend(args.ray) if split else None  # before the warning: a refused --ray is the one line
    _warn_if_did_not_learn(args.model, kind)
    if args.gravity_mult != 1:
        print(f"note: the {name} agent runs as trained: it cannot be told that gravity changed")
    if kind is RunKind.DDPG and sees_frames and trained_arrow is not None and trained_arrow != args.torque_arrow:
        print(f"{PROG}: warning: {args.model} was trained with the torque arrow {'shown' if trained_arrow else 'hidden'}; "
              f"these episodes {'show' if args.torque_arrow else 'hide'} it", file=sys.stderr)
    config = EpisodeConfig(episodes=args.episodes, steps=args.steps, seed=args.seed, gravity_mult=args.gravity_mult,
                           torque_arrow=args.torque_arrow, frame_stack=agent.input_frames)
    if backend is not None:  # over episodes
        from piga.control.jobs import ControlJob, run_split

        result = run_split(ControlJob(kind.value, config, mpc, model_dir=args.model), args.workers, progress=not args.quiet,
                           backend=backend)
    else:
        result = run_episodes(agent, config, progress=not args.quiet, record=1 if args.video else 0)
    s = result.summary
    label = f"{name} ({typed_text(args.model)})"
    print(f"{label}, gravity x{args.gravity_mult:g}, goal 0 deg: success {100 * s.success_rate:.0f}% of {s.episodes}, "
          f"mean return {s.mean_return:.1f}, final angle error {math.degrees(s.final_angle_error_mean):.2f} deg, "
          f"plan {s.plan_ms_median:.1f} ms median / {s.plan_ms_p95:.1f} ms p95")
    with written_together([*([args.video] if args.video else []), *outputs]):  # the video and --out: all or none
        if args.video:
            from piga.control.registry import episode_panels
            from piga.evaluation.video import panels_video

            # episode 0 again in this process when the workers ran it (the same start and seeds: the same episode)
            recording = (result.recordings or run_episodes(agent, replace(config, episodes=1), record=1).recordings)[0]
            panels_video(episode_panels(agent, recording), args.video, overwrite=args.overwrite)
        if outputs:
            result = result.labelled(agent=label)
            _write_outputs(outputs, {"agent": label, "kind": kind.value, **result.to_dict(), "recordings": None},
                           f"# {PROG}\n\nCommand: `{command_line(PROG, argv)}`\n\n{summary_markdown([result.summary])}",
                           args.overwrite, model=args.model, kind=kind)
    _say_written(args.video, outputs)
    return 0


def check_pendulum_model(model: PhysicsModel, run_dir: str) -> None:
    """Refuses a model that cannot plan for Gymnasium's pixel pendulum: another system's, one trained on frames
    of another size or colour than the env renders (its encoder would not read them), or one trained on frames
    of another rate (an imported recording): its physics would step another dt than the env's each frame."""
    config = model.config
    if config.system != "pendulum":
        raise PigaError(f"{run_dir}: a {config.system} model cannot control the pendulum")
    _check_frame_rate(run_dir, config.dt)  # first: a DMC model's line points at --env piga/DMCPendulum-v0
    size = EpisodeConfig().env_config().image_size  # the env the episodes run in renders gray frames of this side
    if config.image_size != size or config.channels != 1:
        frames = f"{config.image_size}x{config.image_size} " + ("gray" if config.channels == 1 else f"{config.channels}-channel")
        default = ", its default" if size == PixelPendulumConfig.image_size else ""
        fix = (f"collect frames of that size (piga-collect --image-size {size}{default}) and train a model on them"
               if config.image_size != size else
               "train a model on gray frames (piga-collect writes them, and piga-import turns a colour recording gray)")
        raise PigaError(f"{run_dir}: the model takes {frames} frames, Gymnasium's pixel pendulum renders {size}x{size} "
                        f"gray ones; {fix}")


def _unplannable(model: PhysicsModel) -> str | None:
    """Why the pendulum planner's engine does not take the model (:meth:`agents.dynamics.PendulumDynamics.of`), or
    None where it does."""
    from agents.dynamics import PendulumDynamics

    try:
        PendulumDynamics.of(model.system, model.integrator)  # type: ignore[arg-type]
    except ValueError as exc:
        return str(exc)
    return None


def _check_plannable(model: PhysicsModel, run_dir: str) -> None:
    """Refuses a model that the pendulum planner's engine would plan wrongly (``--preset continuous``: RK4 within the
    frame, or a learned damping), before anything else is read or warned of; the agent refuses it in the same words
    (:meth:`agents.dynamics.PendulumDynamics.of`), after the goal image and the convergence warning."""
    if (why := _unplannable(model)) is None:
        return
    # the fix: dm_control's env, which plans such a model, where it steps the model's frame rate; else a model
    # trained with the preset that Gymnasium's pendulum is planned with
    if (repeat := _dmc_repeat(model.system.dt)) is not None:
        fix = f"control it with --env {DMC_PENDULUM}" + ("" if repeat == 1 else f" --env-option action_repeat={repeat}")
    else:
        fix = (f"no env plans it at its frames' rate ({model.system.dt:g} s apart): to control {PIXEL_PENDULUM}, "
               "train a model with --preset fast")
    raise PigaError(f"{run_dir}: {why}; {fix}")


def _warn_if_other_frames(run_dir: str, checkpoint: dict) -> None:
    """One warning line when the model learned from frames that piga-collect did not draw from Gymnasium's pixel
    pendulum (an imported recording: its checkpoint names no env), which it controls here from the env's frames:
    of the same size and rate, they are still another camera's picture, which its encoder may misread."""
    data = checkpoint.get("data") or {}
    if "env_id" in data and data["env_id"] != PIXEL_PENDULUM:  # (older checkpoints do not say)
        source = f"from {data['env_id']}" if data["env_id"] else "not collected by piga-collect (an imported recording?)"
        print(f"{PROG}: warning: the model learned from {recorded_data_path(data)}, {source}; it controls {PIXEL_PENDULUM} here "
              "from that env's frames, which its encoder may misread: the success below measures that too",
              file=sys.stderr)


def pixel_physics_difference(trained: dict[str, Any], env: PixelPendulumConfig,
                             believed: float = 1.0) -> tuple[str, str] | None:
    """Where the training file's ``env_config`` (``trained``) had other physics than Gymnasium's pendulum ``env``: the
    gravity (the file's gravity times its multiplier; compared only where it differs from the env's base gravity too,
    and where the agent's belief, it times ``believed``, the multiplier it is told, is not the env's gravity times
    its multiplier), the actuation gain, the effects. The env's values and the trained ones, e.g. ("g = 10 m/s²,
    actuation gain 1", "g = 5 m/s², actuation gain 2"); None where they agree, or where the file does not say."""
    pairs = []
    g = _trained_gravity(trained, env)
    try:
        gain = float(trained.get("actuation_gain", env.actuation_gain))
    except (TypeError, ValueError):  # (a file's attrs written by hand: nothing to compare)
        return None
    if g is None:
        return None
    runs = env.gravity * env.gravity_mult
    if not math.isclose(g, env.gravity, rel_tol=1e-6) and not math.isclose(g * believed, runs, rel_tol=1e-6):
        # told a multiplier, the agent plans with it times the trained g: that, not the trained g, is what differs
        # (a model of g = 14 at --gravity-mult 1.4 read "the env runs g = 14, ... collected at g = 14")
        told = "" if believed == 1 else (f" (told x{number_text(believed)}, the agent plans with g = "
                                         f"{g * believed:.4g} m/s²)")
        pairs.append((f"g = {number_text(runs)} m/s²", f"g = {number_text(g)} m/s²{told}"))
    if not math.isclose(gain, env.actuation_gain, rel_tol=1e-6):
        pairs.append((f"actuation gain {number_text(env.actuation_gain)}", f"actuation gain {number_text(gain)}"))
    effects = trained.get("effects") or []
    try:  # as the env holds them (pairs from JSON, or an object written by hand, which the schema takes)
        effects = normalize_effects(effects)
    except (TypeError, ValueError):  # (not effects piga makes: named as they are)
        pass
    if effects and tuple(effects) != tuple(env.effects):
        try:
            named = ", ".join(f"{name}={number_text(float(value))}" for name, value in effects)
        except (TypeError, ValueError):
            named = str(effects)
        pairs.append(("no effect" if not env.effects else "other effects", f"the effects {named}"))
    if not pairs:
        return None
    return ", ".join(now for now, _ in pairs), ", ".join(then for _, then in pairs)


def _camera_effects_only(trained: dict[str, Any], env: PixelPendulumConfig) -> bool:
    """True where every effect that the training file and ``env`` do not share acts on the frames alone ("vision")."""
    try:
        ours, theirs = dict(normalize_effects(trained.get("effects") or [])), dict(env.effects)
    except (TypeError, ValueError):  # (not effects piga makes)
        return False
    names = {n for n in ours.keys() | theirs.keys() if ours.get(n) != theirs.get(n)}
    return bool(names) and all(EFFECTS[n].kind == "vision" for n in names)


def _trained_gravity(trained: dict[str, Any], env: PixelPendulumConfig) -> float | None:
    """The gravity of the training file's ``env_config`` (its gravity times its multiplier; the env's where it does
    not say); None where a hand-written attribute is no number."""
    try:
        return float(trained.get("gravity", env.gravity)) * float(trained.get("gravity_mult", 1.0))
    except (TypeError, ValueError):
        return None


def _warn_if_other_pixel_physics(checkpoint: dict, multipliers: Sequence[float] = (1.0,), told: bool = True,
                                 sweep: bool = False) -> None:
    """One warning line where the model's training file was collected with other physics than the pixel pendulum
    that the episodes run at the gravity ``multipliers`` (:func:`pixel_physics_difference`; each ``told`` to the agent
    or not): its planner plans with the physics it identified, and a success of 0% would read as a failed
    identification (a model of g = 5, a = 2, read to within 1%, swung up 0 of 2 episodes at g = 10 and gain 1 without
    a word, and 2 of 2 at g = 5). A ``sweep``'s line names the multipliers at which they differ."""
    from piga.io.runs import training_env_config

    trained = training_env_config(checkpoint)
    if not trained:
        return
    env = PixelPendulumConfig()
    found = [(m, d) for m in multipliers
             if (d := pixel_physics_difference(trained, replace(env, gravity_mult=m), m if told else 1.0)) is not None]
    if not found:
        return
    differs = found[0][1]
    mult = (_trained_gravity(trained, env) or env.gravity) / env.gravity
    hinted = "g = " in differs[0] and MIN_GRAVITY <= mult * env.gravity <= MAX_GRAVITY
    # a file that differs by camera effects alone (a blur, a shift) was recorded with the env's physics: its frames,
    # not its physics, are what the env does not make (the warning had called a blur "other physics")
    camera_only = "g = " not in differs[0] and "actuation gain" not in differs[0] and _camera_effects_only(trained, env)
    learned = ("its encoder learned to read frames made with them" if camera_only
               else "its planner plans with the physics it identified there")
    if sweep:
        line = (f"at {', '.join(f'x{number_text(m)}' for m, _ in found)} of the sweep the env runs "
                f"{'another camera' if camera_only else 'other physics'} than the model's training file "
                f"({differs[1]}): {learned}, so the success there measures that mismatch too")
        hint = (f" ({'with --not-told, ' if told else ''}x{number_text(mult)} runs the env at the trained gravity that "
                "the agent plans with)")
    else:
        line = (f"the env runs {differs[0]}, the model's training file was collected at {differs[1]}: {learned}, so "
                "the success below measures that mismatch too")
        hint = f" (--gravity-mult {number_text(mult)} --not-told runs the env at the trained gravity)"
    print(f"{PROG}: warning: {line}{hint if hinted else ''}", file=sys.stderr)


def check_planet_frames(run_dir: str) -> None:
    """Refuses a PlaNet-style run trained on frames that Gymnasium's pixel pendulum does not make: another env's
    (dm_control's: its checkpoint names the env of its data file; older runs name none), or another rate's (an
    imported recording, or dm_control's in an older run)."""
    from agents.planet.run import trained_frames

    data = trained_frames(run_dir)
    env_id, dt = data.get("env_id"), data.get("dt")
    rate = f", {dt:g} s apart" if isinstance(dt, (int, float)) else ""
    if env_id is not None and env_id != PIXEL_PENDULUM:
        raise PigaError(f"{run_dir}: the PlaNet-style model was trained on frames of {env_id}{rate} (from "
                        f"{recorded_data_path(data)}), not of Gymnasium's pixel pendulum ({PIXEL_PENDULUM}), which it would "
                        "control here; train it on a file of that env")
    if isinstance(dt, (int, float)):
        _check_frame_rate(run_dir, dt)


def _check_frame_rate(run_dir: str, dt: float) -> None:
    """Refuses a model trained on frames ``dt`` s apart where the pixel pendulum steps another dt."""
    from envs.constants import PENDULUM_DT

    if abs(dt - PENDULUM_DT) > 1e-9:
        raise PigaError(f"{run_dir}: the model was trained on frames {dt:g} s apart, Gymnasium's pixel pendulum steps "
                        f"{PENDULUM_DT:g} s; it can control only a system filmed at its own rate"
                        + (f" (trained on frames of {DMC_PENDULUM}, it is controlled with --env {DMC_PENDULUM})"
                           if _dmc_repeat(dt) is not None else ""))


def _dmc_repeat(dt: float) -> int | None:
    """The action repeat at which dm_control's pendulum steps frames ``dt`` s apart, or None where none does."""
    from envs.dmc import DMC_PHYSICS_DT, MAX_ACTION_REPEAT

    repeat = round(dt / DMC_PHYSICS_DT)
    return repeat if 1 <= repeat <= MAX_ACTION_REPEAT and abs(repeat * DMC_PHYSICS_DT - dt) <= 1e-9 else None


def check_angle(flag: str, degrees: float) -> None:
    """Refuses an angle outside [-180, 180] degrees (NaN and infinities included): a goal such as
    1e300 degrees means nothing, and reduced modulo a turn it would be an arbitrary angle."""
    if not -180 <= degrees <= 180:
        raise PigaError(f"{flag} must be an angle in degrees from upright within [-180, 180], got {number_text(degrees)}")


def default_elites(candidates: int) -> int:
    """Elites for ``candidates`` when none are given: the default planner's share (at least 1)."""
    cem = MPCConfig().cem
    return max(1, round(candidates * cem.elites / cem.candidates))


def _mpc_config(args: argparse.Namespace, goal: float) -> MPCConfig:
    """The planner settings from the command line."""
    if args.candidates < 2:
        raise PigaError(f"--candidates must be at least 2, got {args.candidates}")
    elites = default_elites(args.candidates) if args.elites is None else args.elites
    if elites > args.candidates:
        raise PigaError(f"--elites ({elites}) must be at most --candidates ({args.candidates})")
    defaults = MPCConfig()
    cem = replace(defaults.cem, horizon=args.horizon, candidates=args.candidates, elites=elites, iterations=args.iterations)
    return replace(defaults, cem=cem, goal_angle=goal, seed=args.seed, warm_start=args.warm_start)


def _keep_first_trace(agent: PigaMPCAgent, into: list[tuple[float, float, np.ndarray]]) -> Callable[[int], None]:
    """Copies the piga agent's trace of episode 0 (the one recorded for the video) into ``into``."""

    def keep(episode: int) -> None:
        if episode == 0:
            into[:] = agent.trace

    return keep


def _write_goal_image(args: argparse.Namespace) -> int:
    from piga.control.goal import GOAL_IMAGE_FORMATS, render_goal_image
    from piga.evaluation.video import encoded_image

    if args.angle is None:
        raise PigaError("--write-goal-image needs --angle in degrees")
    check_angle("--angle", args.angle)
    args.angle += 0.0  # -0.0 is 0, as --goal-angle's: "the pendulum at -0 deg" otherwise
    target = Path(args.write_goal_image)
    check_file_name(target, "--write-goal-image", "goal.png")
    if (suffix := target.suffix.lower()) not in GOAL_IMAGE_FORMATS:
        *most, last = GOAL_IMAGE_FORMATS
        raise PigaError(f"--write-goal-image: use a path ending in {', '.join(most)} or {last}, got {target.name}")
    check_writable_target(target, args.overwrite)
    from piga.io.resources import check_figure_disk

    check_figure_disk(target, f"--write-goal-image {target}", advice="free some space, or write elsewhere")
    picture = render_goal_image(args.angle)
    with atomic_output(target, overwrite=args.overwrite) as tmp:
        tmp.write_bytes(encoded_image(picture, suffix, **GOAL_IMAGE_FORMATS[suffix]))
    print(f"wrote {target}: the pendulum at {args.angle:g} deg, {picture.shape[1]}x{picture.shape[0]}")
    return 0


#: Options of piga-control that the DMC pendulum takes (the rest must keep their defaults there).
DMC_OPTIONS = ("model", "oracle", "episodes", "seed", "env", "env_option", "out", "overwrite", "quiet")
#: Options of piga-control that --write-goal-image takes (the rest must keep their defaults with it).
GOAL_IMAGE_OPTIONS = ("write_goal_image", "angle", "env", "overwrite", "quiet")


def _ignored_options(args: argparse.Namespace, given: set[str], taken: Sequence[str]) -> list[str]:
    """The ``given`` options (:func:`~piga.cli.common.given_options`) outside ``taken`` (destinations), as flags
    (``--episodes``) in the parser's order: options that a mode of the command would ignore."""
    return [_flag(args, k) for k in vars(args) if k in given and k not in taken]


def _flag(args: argparse.Namespace, dest: str) -> str:
    """The flag of option ``dest`` as the user wrote it: ``--no-warm-start`` where --warm-start was turned off."""
    flag = dest.replace("_", "-")
    return f"--no-{flag}" if dest == "warm_start" and not args.warm_start else f"--{flag}"


def _dmc_sb3_agent(run_dir: str, env: DMCPendulumConfig) -> SB3Agent:
    """The policy of an SB3 run trained on the DMC pendulum (``piga-baseline ddpg --env``), for episodes of ``env``
    (a :class:`envs.dmc.DMCPendulumConfig`); a run of another env, or another action repeat, is refused."""
    from agents.sb3.run import SB3Agent, trained_env
    from envs.dmc import DMCPendulumConfig

    if (trained := trained_env(run_dir)) != DMC_PENDULUM:  # from config.json: the checkpoint holds the replay buffer
        raise PigaError(f"{run_dir} was trained on {trained}; --env {DMC_PENDULUM} runs piga models, the oracle "
                        "and SB3 runs trained on it (piga-baseline ddpg --env)")
    if env.action_repeat != DMCPendulumConfig.action_repeat:  # its policy acts once per trained frame
        raise PigaError(f"{run_dir} was trained at action_repeat {DMCPendulumConfig.action_repeat} (DMC's "
                        f"default); drop --env-option action_repeat={env.action_repeat}")
    return SB3Agent.from_run(run_dir)


def _sb3_view(agent: SB3Agent, env: DMCPendulumConfig, given: set[str]) -> DMCPendulumConfig:
    """``env`` seen as the SB3 run was trained to see it (its ``view``: camera, colour, size); an ``--env-option``
    that sets one of those otherwise is refused (the policy reads only the frames it was trained on)."""
    from agents.sb3.config import DMC_VIEWS
    from envs.dmc import DMCPendulumConfig

    view = DMC_VIEWS[agent.config.view]
    for key in sorted(given & {"camera", "camera_distance", "color", "image_size"}):  # the distance: its size in view
        if getattr(env, key) != view.get(key, getattr(DMCPendulumConfig, key)):
            raise PigaError(f"--env-option {key}={getattr(env, key)}: the run was trained on its view "
                            f"{agent.config.view!r}; drop --env-option {key}")
    return replace(env, **view)


def _check_piga_view(run_dir: str, checkpoint: dict, env: DMCPendulumConfig) -> None:
    """A piga model reads gray frames through the camera of the data it was identified on (its training file's,
    face-on where the file is gone): another is refused before an episode runs. Shadows that the training file did not
    have (or the other way round) run, with one warning line: the same view, lit otherwise."""
    from piga.io.runs import training_env_config

    if env.color != "gray":
        raise PigaError("piga's models read gray frames; drop --env-option color=rgb")
    from envs.dmc import DMCPendulumConfig

    own = training_env_config(checkpoint)
    trained = own.get("camera", "face")
    if env.camera != trained:
        raise PigaError(f"{run_dir} was identified through the {trained!r} camera, not {env.camera!r}; "
                        + ("drop --env-option camera" if trained == "face" else f"give --env-option camera={trained}"))
    distance = float(own.get("camera_distance", DMCPendulumConfig.camera_distance))
    if abs(env.camera_distance - distance) > 1e-9:  # the pendulum another size in the frames than the model draws it
        raise PigaError(f"{run_dir} was identified with the camera at camera_distance={distance:g}, not "
                        f"{env.camera_distance:g}; " + ("drop --env-option camera_distance"
                                                        if distance == DMCPendulumConfig.camera_distance
                                                        else f"give --env-option camera_distance={distance:g}"))
    trained_shadows = own.get("shadows", DMCPendulumConfig.shadows)
    if isinstance(trained_shadows, bool) and env.shadows != trained_shadows:
        # the same camera and physics, frames lit otherwise: a fair test of the vision, said (the nominal model, 922
        # with its own frames, scored 0 with shadows on without a word; piga-diagnose reads a vision gap of 33-37x)
        print(f"{PROG}: warning: the env renders {'with' if env.shadows else 'without'} shadows, the model's training "
              f"file {'had none' if env.shadows else 'had them'}: its encoder reads frames lit otherwise than those it "
              "was trained on, so the score below measures that too", file=sys.stderr)


#: The DMC pendulum's config fields that change its physics: an env that differs from the model's training file in them
#: is a fair test of a model identified on other physics (sim-to-real), so it runs, with a warning.
DMC_PHYSICS_FIELDS = ("mass", "length", "damping", "flip")


def physics_difference(trained: dict[str, Any], env: DMCPendulumConfig) -> tuple[str, str] | None:
    """Where the DMC pendulum ``env`` differs in its physics (:data:`DMC_PHYSICS_FIELDS`) from ``trained``, the
    ``env_config`` of the model's training file (a field it lacks, from an older file, at its default): the env's values
    and the trained ones, e.g. ("flip=motor", "flip=none"); None where they agree."""
    from envs.dmc import DMCPendulumConfig

    pairs = []
    for name in DMC_PHYSICS_FIELDS:
        now, then = getattr(env, name), trained.get(name, getattr(DMCPendulumConfig, name))
        same = (now == then if isinstance(now, str) or isinstance(then, str)
                else math.isclose(float(now), float(then), rel_tol=1e-9, abs_tol=0.0))
        if not same:
            pairs.append((f"{name}={now if isinstance(now, str) else number_text(now)}",
                          f"{name}={then if isinstance(then, str) else number_text(then)}"))
    if not pairs:
        return None
    return ", ".join(now for now, _ in pairs), ", ".join(then for _, then in pairs)


def _warn_if_other_physics(checkpoint: dict[str, Any], env: DMCPendulumConfig) -> None:
    """One warning line where the DMC pendulum ``env`` has other physics than the piga model's training file: a
    fair test of a model identified on other physics, which its planner does not know. Where the file's config is
    not known (an older checkpoint whose file is gone), against DMC's defaults, saying so; nothing for a model of an
    imported recording."""
    from piga.io.runs import training_env_config

    if trained := training_env_config(checkpoint):
        if (differs := physics_difference(trained, env)) is not None:
            print(f"{PROG}: warning: the env differs from the model's training file in {differs[0]} (trained on "
                  f"{differs[1]}): the planner's physics will not match", file=sys.stderr)
        return
    if (checkpoint.get("data") or {}).get("env_id", DMC_PENDULUM) != DMC_PENDULUM:  # (None: an imported recording)
        return
    if (differs := physics_difference({}, env)) is not None:  # (every field at its default)
        print(f"{PROG}: warning: the env differs from DMC's default pendulum in {differs[0]} (default {differs[1]}), "
              "and the model's training file, which would say what it was trained on, is not found: the planner's "
              "physics may not match", file=sys.stderr)


def _check_dmc_rate(run_dir: str, checkpoint: dict, dt: float, env: DMCPendulumConfig,
                    model: PhysicsModel | None = None) -> None:
    """Refuses a piga model trained on frames ``dt`` s apart where the DMC pendulum ``env`` steps another dt, saying
    what would match: the action repeat that gives ``dt``, where one does; else the env of the model's frames, where
    its planner takes the ``model`` (:func:`_unplannable`: one semi-implicit Euler step per frame, no damping; a
    ``--preset continuous`` model of Gymnasium's frames is planned by neither env)."""
    from envs.dmc import DMC_PHYSICS_DT
    from envs.constants import PENDULUM_DT

    if abs(dt - env.dt) <= 1e-9:
        return
    if (repeat := _dmc_repeat(dt)) is not None:
        raise PigaError(f"{run_dir}: the model was trained on frames {dt:g} s apart, the env steps {env.dt:g} s; give "
                        f"--env-option action_repeat={repeat} (physics steps of {DMC_PHYSICS_DT:g} s per frame)")
    frames = f"frames {dt:g} s apart"
    if (trained := _training_env_id(checkpoint)) is not None:
        frames = f"frames of {trained} ({dt:g} s apart)"
    elif abs(dt - PENDULUM_DT) <= 1e-9:  # the file is gone, or names no env: its rate is the pixel pendulum's
        frames, trained = f"{frames} ({PIXEL_PENDULUM}'s rate)", PIXEL_PENDULUM
    euler = model is None or _unplannable(model) is None
    elsewhere = (f"control it with --env {trained}, or " if trained and trained != DMC_PENDULUM
                 and (euler or trained != PIXEL_PENDULUM) else "")
    if not euler and trained == PIXEL_PENDULUM:
        raise PigaError(f"{run_dir}: the model was trained on {frames} with --preset continuous, which no env plans at "
                        f"that rate: to control {PIXEL_PENDULUM}, train a model with --preset fast; to control "
                        f"{DMC_PENDULUM}, train one on its frames (piga-collect --env {DMC_PENDULUM})")
    raise PigaError(f"{run_dir}: the model was trained on {frames}, and no action_repeat of {DMC_PENDULUM} (physics "
                    f"steps of {DMC_PHYSICS_DT:g} s) makes that rate; {elsewhere}train one on frames of "
                    f"{DMC_PENDULUM} (piga-collect --env {DMC_PENDULUM})")


def _training_env_id(checkpoint: dict) -> str | None:
    """The env id of the file the model was trained on, where the file is still there and names one."""
    from piga.data.schema import open_data_file
    from piga.io.runs import training_data_path

    if (path := training_data_path(checkpoint)) is None:
        return None
    try:
        with open_data_file(path) as f:
            env_id = f.attrs.get("env_id")
    except (OSError, ValueError):
        return None
    return env_id if isinstance(env_id, str) and env_id else None


def _dmc(args: argparse.Namespace, argv: Sequence[str] | None, given: set[str]) -> int:
    """``--env piga/DMCPendulum-v0``: the piga agent and/or the oracle, scored in DMC's units."""
    from piga.cli.collect import dmc_config, parse_env_option

    if ignored := _ignored_options(args, given, DMC_OPTIONS):
        raise PigaError(f"{ignored[0]} is not an option of --env piga/DMCPendulum-v0; it takes "
                        + ", ".join(f"--{k.replace('_', '-')}" for k in DMC_OPTIONS))
    if not args.model and not args.oracle:  # as on the pixel env: nothing is run that was not asked for
        raise PigaError("give --model RUN_DIR (or --oracle, or both)")
    if args.model:  # as on the pixel env, before the env is made
        check_model_folder(args.model)
    import argparse as _argparse

    try:
        pairs = [parse_env_option(text) for text in args.env_option]
    except _argparse.ArgumentTypeError as exc:
        raise PigaError(f"--env-option: {exc}") from None
    from piga.control.dmc import DMCControlConfig, OracleSwingUp, PigaSwingUp, dmc_markdown, dmc_record, run_dmc_episodes

    episodes = args.episodes if "episodes" in given else DMCControlConfig.episodes
    config = DMCControlConfig(episodes=episodes, seed=args.seed, env=dmc_config(pairs))
    outputs = []
    if args.out:
        stem = Path(args.out)
        stem = stem.with_suffix("") if stem.suffix.lower() in (".json", ".md") else stem
        outputs = [stem.with_name(stem.name + s) for s in (".json", ".md")]
        _check_out_set(outputs, args)
        lock_run_folder(stem, "--out")  # as on the pixel env
    import torch

    torch.set_num_threads(1)
    from envs.dmc import DMCPendulumEnv

    DMCPendulumEnv(config.env).close()  # a renderer that cannot start here: its one line before a model's warnings
    results, kind = [], None
    if args.model:
        from piga.io.checkpoint import checked_run_kind
        from piga.io.runs import load_model

        if (kind := checked_run_kind(args.model)) is RunKind.DDPG:
            sb3 = _dmc_sb3_agent(args.model, config.env)
            config = replace(config, env=_sb3_view(sb3, config.env, {key for key, _ in pairs}))
            _warn_if_did_not_learn(args.model, kind)  # after the refusals, so that a refused command prints one line
            results.append(run_dmc_episodes(sb3, sb3.config.algo, config, progress=not args.quiet))
        elif kind.is_baseline:
            raise PigaError(f"{args.model} is a {kind.value} run; --env {DMC_PENDULUM} runs piga models, the oracle and "
                            "SB3 runs trained on it")
        else:
            model, checkpoint = load_model(args.model)
            if model.config.system != "pendulum":  # before its frames' rate, whose advice would not help
                raise PigaError(f"{args.model}: a {model.config.system} model cannot control the pendulum")
            _check_piga_view(args.model, checkpoint, config.env)
            _check_dmc_rate(args.model, checkpoint, model.config.dt, config.env, model)
            # rendered at the size of the frames the model was identified on (piga-collect --image-size): a 32 px
            # model was fed 64 px frames ("encode takes frames of ... got (1, 64, 64)"), with no option to change it
            config = replace(config, env=replace(config.env, image_size=model.config.image_size))
            _warn_if_other_physics(checkpoint, config.env)  # after the refusals, so that a refused command prints one
            warn_if_unconverged(PROG, args.model)  # line
            agent = PigaSwingUp(model, config.planner)
            results.append(run_dmc_episodes(agent, "piga", config, model.config.input_frames, progress=not args.quiet))
    if args.oracle:
        results.append(run_dmc_episodes(OracleSwingUp(config.env, config.planner), "oracle", config, progress=not args.quiet))
    command = command_line(PROG, argv)
    text = dmc_markdown(results, config, command)
    print(text)
    if outputs:
        record = {"episodes": config.episodes, "seed": config.seed, "env": config.env.to_dict()}
        if args.oracle or kind is not RunKind.DDPG:  # as in the table: an SB3 policy plans nothing
            record["planner"] = asdict(config.planner)
        _write_outputs(outputs, {"command": command, "config": record, "results": [dmc_record(r) for r in results]},
                       text, args.overwrite)
    return 0


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
