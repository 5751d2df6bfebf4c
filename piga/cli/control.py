"""``piga-control --model RUN_DIR``: control the pixel pendulum from pixels with CEM over the learned physics."""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path

from piga.cli.common import ArgumentParser, PigaError, command_line, nonnegative_int, positive_float, positive_int, run_cli

PROG = "piga-control"


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=PROG, description="Swing up and hold the pixel pendulum with model-predictive control "
                       "(CEM) over a trained piga model, from frames alone.")
    p.add_argument("--model", help="run folder of piga-train-model (not needed with --oracle)")
    p.add_argument("--oracle", action="store_true", help="plan with the true state and true parameters instead")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes (default %(default)s); episode 0 starts hanging down")
    p.add_argument("--steps", type=positive_int, default=200, help="steps per episode (default %(default)s)")
    p.add_argument("--gravity-mult", type=positive_float, default=1.0,
                   help="multiply the environment's gravity; the agent is told and scales its learned g (default 1)")
    p.add_argument("--goal-angle", type=float, default=0.0, help="goal angle in degrees, 0 = upright (default 0)")
    p.add_argument("--goal-image", help="PNG or JPEG of the scene at the goal; the encoder reads the goal angle from it")
    p.add_argument("--write-goal-image", metavar="PATH", help="only write Gymnasium's picture of the pendulum at --angle to PATH, then exit")
    p.add_argument("--angle", type=float, help="with --write-goal-image: the angle in degrees (0 = upright, counter-clockwise)")
    p.add_argument("--horizon", type=positive_int, help="CEM planning horizon (default 20)")
    p.add_argument("--candidates", type=positive_int, help="CEM candidates per iteration (default 200)")
    p.add_argument("--iterations", type=positive_int, help="CEM iterations (default 5)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of start states and planner (default 0)")
    p.add_argument("--torque-arrow", action="store_true",
                   help="show Gymnasium's torque arrow in the frames the agent sees (off by default; see README)")
    p.add_argument("--sweep", metavar="START:STOP:STEP",
                   help="run the piga agent and the oracle at each gravity multiplier of the range (e.g. 0.5:1.8:0.1); "
                   "each agent is told the multiplier. Writes a table and, with --out, OUT.png")
    p.add_argument("--workers", type=positive_int, default=2, help="processes for --sweep (default %(default)s)")
    p.add_argument("--video", help="write episode 0 as .mp4 or .gif: real frames | the model's belief | its plan")
    p.add_argument("--out", help="write the results to OUT.json and a Markdown table to OUT.md (and OUT.png with --sweep)")
    p.add_argument("--overwrite", action="store_true", help="replace existing --out files")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.write_goal_image:
        return _write_goal_image(args)
    if args.angle is not None:
        raise PigaError("--angle goes with --write-goal-image; to set the control goal use --goal-angle or --goal-image")
    if not args.oracle and not args.model:
        raise PigaError("give --model RUN_DIR (or --oracle)")
    if not math.isfinite(args.goal_angle):
        raise PigaError(f"--goal-angle must be a finite number of degrees, got {args.goal_angle}")
    from dataclasses import replace

    import torch

    from agents.mpc import OracleAgent, PigaMPCAgent
    from piga.atomic import check_writable_target, write_json
    from piga.control import EpisodeConfig, run_episodes
    from piga.runs import load_model

    outputs = []
    if args.out:
        outputs = [Path(args.out).with_suffix(s) for s in (".json", ".md", *((".png",) if args.sweep else ()))]
        for path in outputs:
            check_writable_target(path, args.overwrite)
    if args.sweep:
        return _sweep(args, outputs, argv)
    if args.video:
        if Path(args.video).suffix.lower() not in (".mp4", ".gif"):
            raise PigaError(f"--video must end in .mp4 or .gif, got {args.video}")
        if args.oracle:
            raise PigaError("--video shows the model's belief and plan; it needs --model, not --oracle")
        check_writable_target(args.video, args.overwrite)
    torch.set_num_threads(1)  # small tensors: one thread plans fastest
    goal = math.radians(args.goal_angle)
    mpc = _mpc_config(args, goal)
    model = None
    if args.model:
        model, ckpt = load_model(args.model)
        if model.config.system != "pendulum":
            raise PigaError(f"{args.model}: a {model.config.system} model cannot control the pendulum")
    if args.goal_image:
        if model is None:
            raise PigaError("--goal-image needs --model: the goal is read from the image by the model's encoder")
        from piga.goal import goal_from_image

        estimate = goal_from_image(model, ckpt, args.goal_image, gravity_mult=args.gravity_mult)
        for warning in estimate.warnings:
            print(f"{PROG}: warning: {warning}", file=sys.stderr)
        goal = estimate.angle
        args.goal_angle = math.degrees(goal)
        print(f"goal read from {args.goal_image}: {args.goal_angle:.2f} deg (hold torque {estimate.hold_torque:+.2f})")
        mpc = replace(mpc, goal_angle=goal)
    if args.oracle:
        agent = OracleAgent(g=10.0 * args.gravity_mult, a=1.0, config=mpc)
        frames = 4
        label = "oracle"
    else:
        assert model is not None
        agent = PigaMPCAgent(model, mpc, gravity_mult=args.gravity_mult, keep_trace=bool(args.video))
        frames = agent.input_frames
        label = f"piga ({args.model})"
    config = EpisodeConfig(episodes=args.episodes, steps=args.steps, seed=args.seed, gravity_mult=args.gravity_mult,
                           goal_angle=goal, frame_stack=frames, torque_arrow=args.torque_arrow)
    result = run_episodes(agent, config, progress=not args.quiet, record=1 if args.video else 0,
                          on_episode_end=_keep_first_trace(agent) if args.video else None)
    s = result["summary"]
    print(f"{label}, gravity x{args.gravity_mult:g}, goal {args.goal_angle:g} deg: success {100 * s['success_rate']:.0f}% of "
          f"{s['episodes']}, mean return {s['mean_return']:.1f}, final angle error {math.degrees(s['final_angle_error_mean']):.2f} deg, "
          f"plan {s['plan_ms_median']:.1f} ms median / {s['plan_ms_p95']:.1f} ms p95")
    if args.video:
        from piga.video import control_video

        control_video(model, result["recordings"][0]["frames"], agent.first_trace, args.video, overwrite=args.overwrite)
        print(f"wrote {args.video}")
    if outputs:
        from piga.atomic import atomic_output
        from piga.control import summary_markdown

        s = {"agent": label, **s}
        write_json(outputs[0], {"agent": label, **result, "summary": s, "recordings": None}, overwrite=args.overwrite)
        with atomic_output(outputs[1], overwrite=args.overwrite) as tmp:
            tmp.write_text(f"# {PROG}\n\nCommand: `{command_line(PROG, argv)}`\n\n{summary_markdown([s])}")
        print(f"wrote {outputs[0]} and {outputs[1]}")
    return 0


def _sweep(args, outputs: list[Path], argv: Sequence[str] | None) -> int:  # noqa: ANN001
    """--sweep: the piga agent and the oracle at each multiplier, each told the multiplier."""
    from piga.atomic import atomic_output, write_json
    from piga.control import ControlJob, EpisodeConfig, parse_range, run_jobs, summary_markdown
    from piga.runs import load_model

    if args.oracle or not args.model:
        raise PigaError("--sweep compares the piga agent with the oracle: give --model RUN_DIR (without --oracle)")
    if args.goal_image or args.video:
        raise PigaError("--sweep runs upright swing-ups; it does not take --goal-image or --video")
    try:
        multipliers = parse_range(args.sweep)
    except ValueError as exc:
        raise PigaError(f"--sweep: {exc}") from None
    if multipliers[0] <= 0:
        raise PigaError(f"--sweep: gravity multipliers must be > 0, got {args.sweep}")
    model, _ = load_model(args.model)  # fail early, in this process, on a bad folder
    if model.config.system != "pendulum":
        raise PigaError(f"{args.model}: a {model.config.system} model cannot control the pendulum")
    mpc = _mpc_config(args, math.radians(args.goal_angle))
    jobs = [ControlJob(agent, EpisodeConfig(episodes=args.episodes, steps=args.steps, seed=args.seed, gravity_mult=m,
                                            goal_angle=mpc.goal_angle, torque_arrow=args.torque_arrow),
                       mpc, model_dir=args.model if agent == "piga" else None)
            for m in multipliers for agent in ("piga", "oracle")]
    results = run_jobs(jobs, workers=args.workers, progress=not args.quiet)
    summaries = [r["summary"] for r in results]
    table = summary_markdown(summaries)
    print(table, end="")
    if outputs:
        from piga.plots import save_figure, sweep_figure

        write_json(outputs[0], {"model": args.model, "multipliers": multipliers, "results": results}, overwrite=args.overwrite)
        with atomic_output(outputs[1], overwrite=args.overwrite) as tmp:
            tmp.write_text(f"# {PROG} --sweep\n\nCommand: `{command_line(PROG, argv)}`\n\n![sweep]({outputs[2].name})\n\n{table}")
        save_figure(sweep_figure(summaries), outputs[2], overwrite=args.overwrite)
        print(f"wrote {', '.join(map(str, outputs))}")
    return 0


def _mpc_config(args, goal: float):  # noqa: ANN001, ANN202
    """The planner settings from the command line."""
    from dataclasses import replace

    from agents.mpc import MPCConfig

    mpc = MPCConfig(goal_angle=goal, seed=args.seed)
    changes = {k: getattr(args, k) for k in ("horizon", "candidates", "iterations") if getattr(args, k) is not None}
    if changes:
        cem_config = replace(mpc.cem, **changes)
        cem_config = replace(cem_config, elites=max(1, min(cem_config.elites, cem_config.candidates // 10 or 1)))
        mpc = replace(mpc, cem=cem_config)
    return mpc


def _keep_first_trace(agent):  # noqa: ANN001, ANN202
    """Keeps the piga agent's trace of episode 0 (the one recorded for the video)."""
    agent.first_trace = None

    def keep(episode: int) -> None:
        if episode == 0:
            agent.first_trace = list(agent.trace)

    return keep


def _write_goal_image(args) -> int:  # noqa: ANN001
    import imageio.v3 as iio

    from piga.atomic import atomic_output
    from piga.goal import render_goal_image

    if args.angle is None or not math.isfinite(args.angle):
        raise PigaError("--write-goal-image needs a finite --angle in degrees")
    target = Path(args.write_goal_image)
    if target.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise PigaError(f"--write-goal-image: use a .png or .jpg path, got {target.name}")
    picture = render_goal_image(args.angle)
    with atomic_output(target, overwrite=args.overwrite) as tmp:
        iio.imwrite(tmp, picture, extension=target.suffix.lower())
    print(f"wrote {target}: the pendulum at {args.angle:g} deg, {picture.shape[1]}x{picture.shape[0]}")
    return 0


def entry() -> None:
    run_cli(PROG, main)
