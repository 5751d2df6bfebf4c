"""``piga-diagnose --model RUN_DIR --data REAL.h5 --out REPORT_DIR``: diagnose a sim-to-real gap."""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path

from piga.cli.common import (ArgumentParser, Interrupted, PigaError, check_model_folder, command_line, int_up_to,
                             number_type, run_cli, seed_int, thread_count, warn_if_unconverged)
from piga.io.lock import lock_run_folder

PROG = "piga-diagnose"


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=PROG, description="Diagnose the gap between an identified piga model and video + actions of "
                       "a 'real' system: its size per horizon, where it lies (vision or dynamics; residuals over the state "
                       "and the actions), which unmodelled effect causes it, and how far it shrinks once that effect is "
                       "added. Reads /frames, /actions and dt, and of the other attributes only what says which simulator or "
                       "recording made it (env_id, env_config, source); never /states, nor the params or effects that "
                       "made the file (--env only checks its effects against them).")
    p.add_argument("--model", required=True, help="run folder of piga-train-model (the identified model)")
    p.add_argument("--data", required=True, help="HDF5 file of the real system (piga-collect --effect, or piga-import)")
    p.add_argument("--out", required=True, help="report folder: report.md, report.json and plots")
    p.add_argument("--training-data", metavar="FILE",
                   help="the HDF5 file the model was trained on, where it is not found at the path its run recorded (nor "
                        "beside the run folder): a gain or gravity error is judged against the same effects' reading of "
                        "it (checked to be that file by its content)")
    p.add_argument("--env", metavar="EFFECTS",
                   help="the data come from a simulated real system with these effects (e.g. 'damping=0.2,delay=2', or "
                   "'none'): also run MPC on it with the nominal and with the corrected physics, and compare")
    import inspect

    from piga.control.closed_loop import compare_control
    from piga.control.episodes import EpisodeConfig
    from piga.diagnostics.diagnose import DiagnoseConfig

    episodes = inspect.signature(compare_control).parameters["episodes"].default
    p.add_argument("--episodes", type=int_up_to(EpisodeConfig.MAX_EPISODES, "more would run for days"),
                   help=f"MPC episodes per model with --env (default {episodes})")
    p.set_defaults(default_episodes=episodes)

    d = DiagnoseConfig()
    p.add_argument("--bootstrap", type=number_type(int, lambda v: v == 0 or d.MIN_BOOTSTRAP <= v <= d.MAX_BOOTSTRAP,
                                                    f"0 (no intervals) or an integer in [{d.MIN_BOOTSTRAP}, "
                                                    f"{d.MAX_BOOTSTRAP}]"), default=d.bootstrap,
                   help=f"bootstrap replicates for the physics effects' intervals: 0 (none: a gain error is then named on "
                   f"its estimate alone, untested) or {d.MIN_BOOTSTRAP} to {d.MAX_BOOTSTRAP} (default %(default)s); "
                   "the camera effects' intervals come from their own fit, with or without it")
    p.add_argument("--seed", type=seed_int, default=d.seed,
                   help="seed of the bootstrap, of the frames the camera stage fits on and of the twin's sensor noise "
                   "(default %(default)s)")
    p.add_argument("--fit-starts", action=argparse.BooleanOptionalAction, default=d.fit_starts,
                   help="refit the chosen effects' values with each fitting window's two start angles fitted too "
                        "(errors in the read angles then bias no damping); the selection is unchanged "
                        "(default %(default)s)")
    p.add_argument("--matched-angles", action=argparse.BooleanOptionalAction, default=d.matched_angles,
                   help="read the chosen effects' values, and the model's own training file that a gain is judged "
                        "against, on angles matched to the decoder's renders instead of the encoder's; the selection "
                        "is unchanged (default %(default)s). A camera that the camera stage accepts (named, or under the "
                        "sizes that are named), a vision gap in what is drawn with the action, or an actuation sign "
                        "that only the matched angles show puts every step on matched angles, with this option or "
                        "without, and a note says which")
    p.add_argument("--threads", type=thread_count, default=0,
                   help="torch CPU threads (default %(default)s: torch's choice, at most 2; small fits gain little from more)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing report in --out")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def _too_short_recording(frames: int, steps: int) -> str:
    """What to add where a recording of ``frames`` frames cannot make the diagnosis's sequences of ``steps`` frames
    however it is imported (its import in sequences of 13 was then refused for their number)."""
    from piga.diagnostics.observe import MIN_SEQUENCES as sequences

    if frames >= sequences * steps:
        return ""
    return (f"; but its {frames} frames make {frames // steps} such sequences, and the diagnosis needs {sequences} "
            f"({sequences * steps} frames): record a longer video")


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from piga.io.checkpoint import require_piga_run
    from piga.data.schema import check_frames_have_signal, inspect_dataset
    from piga.diagnostics import DiagnoseConfig, diagnose
    from piga.diagnostics.report import check_report_target, closure_line, write_report
    from piga.io.runs import load_model, with_training_file

    # Everything is checked before any work, and the report folder is only created at the end
    # (atomically): a refusal leaves nothing behind.
    effects = _parse_env(args.env) if args.env is not None else None
    if args.episodes is not None and effects is None:
        raise PigaError("--episodes sets the MPC episodes of --env; without --env nothing is run, so drop it")
    config = DiagnoseConfig(bootstrap=args.bootstrap, seed=args.seed, fit_starts=args.fit_starts,
                            matched_angles=args.matched_angles)
    if Path(args.out).resolve() == Path(args.model).resolve():  # its report would sit among the run's files
        raise PigaError(f"--out {args.out} is the model's run folder; give another folder for the report")
    out = check_report_target(args.out, args.overwrite)
    lock_run_folder(out)  # a second diagnosis into the same folder is refused at once, not after its work
    # the model before the data: a missing model, a file or another kind of run was otherwise hidden behind the data's
    # refusal ("sequences of 12 frames are too short"), and found only after collecting again
    check_model_folder(args.model, "piga-train-model")
    require_piga_run(args.model, "piga-diagnose compares the physics a piga model identified with the data")
    model, ckpt = load_model(args.model)
    if model.config.system != "pendulum":
        raise PigaError(f"{args.model}: piga-diagnose is for pendulum models; this one is a {model.config.system} model")
    try:
        ckpt = with_training_file(ckpt, args.model, args.training_data)
    except ValueError as error:
        raise PigaError(f"--training-data {error}") from None
    info = inspect_dataset(args.data)  # the data's schema errors, with the file's name
    if info.system != "pendulum":  # before its length, whose advice would not help
        raise PigaError(f"{args.data}: piga-diagnose is for pendulum data; this file holds {info.named} data")
    from piga.diagnostics.fit import min_frames

    if info.steps < (need := min_frames(config.fit_horizon)):  # found after the encoding otherwise (half a minute)
        raise PigaError(f"{args.data}: sequences of {info.steps} frames are too short to diagnose: the fit needs "
                        f"{need} (windows of {config.fit_horizon} steps after {need - config.fit_horizon - 1} frames); "
                        + (f"collect sequences of {need} frames or more (piga-collect --steps {need})"
                           if info.attrs.get("env_id") is not None else  # (a recording imported: no env to collect)
                           f"import the recording in sequences of {need} frames or more (piga-import --steps {need})"
                           + _too_short_recording(info.n_sequences * info.steps, need)))
    check_frames_have_signal(args.data)  # blank video: the diagnosis would divide by its zero variance
    if effects is not None:  # MPC on Gymnasium's pendulum with the model's physics
        from envs.constants import PENDULUM_DT
        from piga.cli.control import check_pendulum_model

        if abs(model.config.dt - PENDULUM_DT) > 1e-9:  # (control's own line would send the user to its --env)
            raise PigaError(f"--env runs MPC episodes on Gymnasium's pixel pendulum, which steps {PENDULUM_DT:g} s, and "
                            f"{args.model} was trained on frames {model.config.dt:g} s apart: drop --env (the "
                            "diagnosis itself runs no episodes)")
        check_pendulum_model(model, args.model)
        # after the model's own checks: its advice ("give --env 'none'") is then one that runs
        _check_env_agrees(effects, info.attrs.get("effects"), args.data)
        _check_env_physics(info.attrs.get("env_config"), args.data)
    import torch

    torch.set_num_threads(args.threads or max(1, min(2, torch.get_num_threads())))
    diagnosis = diagnose(model, args.data, config, checkpoint=ckpt, progress=not args.quiet)
    if effects is not None:
        from piga.control.closed_loop import compare_control

        diagnosis.control = compare_control(args.model, diagnosis, effects, episodes=args.episodes or args.default_episodes,
                                            seed=args.seed,
                                            progress=not args.quiet)
    from piga.io.runs import convergence_warning

    warning = convergence_warning(args.model)  # (its line on stderr comes below)
    report = write_report(diagnosis, out, args.model, args.data, command_line(PROG, argv), overwrite=args.overwrite,
                          model_warning=warning.removeprefix("warning: ").rstrip(".") if warning else None)
    try:  # the report is complete from here: an interrupt says so (a rerun needs --overwrite)
        warn_if_unconverged(PROG, args.model)  # after the work: a refusal of the model stays the one line on stderr
        print(f"verdict: {diagnosis.verdict}")
        for line in diagnosis.exclusions:
            print(line)
        for note in diagnosis.notes:
            print(f"note: {note}")
        print(closure_line(diagnosis))
        if diagnosis.control:
            for row in diagnosis.control["rows"]:
                print(f"MPC on the simulated real system, {row['physics']} physics: success {100 * row['success_rate']:.0f}% of "
                      f"{row['episodes']}, mean return {row['mean_return']:.1f}")
        print(f"wrote {report} and its plots")
    except KeyboardInterrupt:
        raise Interrupted(f"the report {report} and its plots are complete") from None
    return 0


def _parse_env(text: str) -> tuple[tuple[str, float], ...]:
    """'damping=0.2,delay=2' (or 'none') -> checked effects."""
    from envs.effects import normalize_effects

    if text.strip().lower() in ("", "none"):
        return ()
    parts = [part.strip() for part in text.split(",")]
    if not all(parts):
        raise PigaError(f"--env: an empty item in {text!r}; give NAME=VALUE items separated by single commas, "
                        "e.g. 'damping=0.2,delay=2'")
    from piga.control.episodes import EpisodeConfig

    try:  # the env that the MPC comparison runs, checked here: damping=50 was refused after the whole diagnosis
        effects = normalize_effects(parts)
        EpisodeConfig(episodes=1, effects=effects).env_config()
    except (ValueError, TypeError) as exc:
        raise PigaError(f"--env: {exc}") from None
    return effects


def _check_env_physics(config: object, data: str) -> None:
    """Refuses --env for a file whose ``env_config`` says it was collected at another gravity or actuation gain than
    Gymnasium's pendulum's, which the MPC comparison simulates (a file at gravity x1.5 was compared on g = 10: its
    corrected physics, g = 14.9, looked worse than the nominal). A file without the attribute is taken at its word."""
    from piga.control.episodes import EpisodeConfig

    if not isinstance(config, dict):
        return
    env = EpisodeConfig(episodes=1).env_config()  # the system that the comparison simulates
    try:
        g = float(config.get("gravity", env.gravity)) * float(config.get("gravity_mult", 1.0))
        gain = float(config.get("actuation_gain", env.actuation_gain))
    except (TypeError, ValueError):
        return
    simulated = env.gravity * env.gravity_mult
    if not (math.isclose(g, simulated, rel_tol=1e-6) and math.isclose(gain, env.actuation_gain, rel_tol=1e-6)):
        raise PigaError(f"--env simulates Gymnasium's pendulum at g = {simulated:g} m/s² and actuation gain "
                        f"{env.actuation_gain:g}, but {data} was collected at g = {g:.4g} m/s² and gain {gain:.4g} (its "
                        "env_config): the MPC comparison would run on another system than the data's; leave --env out")


def _check_env_agrees(effects: tuple[tuple[str, float], ...], recorded: object, data: str) -> None:
    """Refuses an --env whose effects differ from those the data file says it was collected with (its ``effects``
    attribute, written by piga-collect): the MPC comparison would run on another system than the data's. A file
    without the attribute (a recording) is taken at its word."""
    if not isinstance(recorded, dict):
        return
    try:
        truth = {str(name): float(value) for name, value in recorded.items()}
    except (TypeError, ValueError):
        return
    given = {name: float(value) for name, value in effects}
    same = truth.keys() == given.keys() and all(math.isclose(truth[k], given[k], rel_tol=1e-6, abs_tol=1e-12) for k in truth)
    if not same:
        from envs.effects import format_effects

        raise PigaError(f"--env {format_effects(list(given.items()))}: {data} was collected with effects "
                        f"{format_effects(list(truth.items()))} (its effects attribute); give --env "
                        f"'{format_effects(list(truth.items())).replace(' ', ',')}' or leave --env out")


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
