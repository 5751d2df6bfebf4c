"""``piga-collect``: pendulum videos with random actions (Gymnasium's or dm_control's), or a scene of the paper, written to one HDF5 file."""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from envs import DMC_PENDULUM, ENV_IDS, PIXEL_PENDULUM
from envs.constants import PENDULUM_MAX_SPEED
from envs.dmc import MAX_SPEED_TEXT, DMCPendulumConfig
from envs.effects import EFFECTS, format_effects, parse_effect
from envs.fields import counted
from envs.pendulum import MAX_ACTUATION_GAIN, MAX_GRAVITY, MIN_ACTUATION_GAIN, MIN_GRAVITY, PixelPendulumConfig
from envs.scenes import HALF_SPEED, SCENES, SceneConfig, aliasing_warning, scene_config
from piga.cli.common import (H5_SUFFIXES, ArgumentParser, PigaError, add_preset_option, any_float, command_line,
                             format_default, given_options, h5_path, positive_float, positive_int, run_cli, seed_int,
                             split_type)
from piga.data.collect import (PAPER_MAX_SPEED, PRESETS, CollectConfig, buried_noise_warning, collect,
                               empty_split_warning)
from piga.data.collect_scenes import SCENE_PRESETS, SCENE_STEPS, collect_scene
from piga.data.schema import inspect_dataset, load_states
from piga.io.lock import lock_run_folder

PROG = "piga-collect"
#: Options of Gymnasium's pendulum only: the DMC pendulum refuses them when they are written.
GYMNASIUM_ONLY = {"gravity": "--gravity", "gravity_mult": "--gravity-mult", "actuation_gain": "--actuation-gain",
                  "no_torque_arrow": "--no-torque-arrow", "effects": "--effect"}


def _effect(text: str) -> tuple[str, int | float]:
    import argparse

    try:
        return parse_effect(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _color(text: str) -> tuple[float, float, float]:
    """A colour as matplotlib reads it (a name, '#rrggbb', 'tab:blue', ...) -> RGB in [0, 1]; an opaque one only."""
    import argparse

    from matplotlib.colors import to_rgba

    try:
        *rgb, alpha = to_rgba(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a colour: {text!r} (use a name such as 'gold', or '#ffd91a')") from None
    if alpha != 1:  # the scene draws opaque balls: a see-through colour would be silently drawn solid
        raise argparse.ArgumentTypeError(f"{text!r} is {'transparent' if alpha == 0 else 'see-through'} (alpha "
                                         f"{alpha:g}); the balls are drawn opaque: give an opaque colour")
    return tuple(float(c) for c in rgb)  # type: ignore[return-value]


def parse_env_option(text: str) -> tuple[str, str]:
    import argparse

    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE (e.g. mass=1.2), got {text!r}")
    return key.strip().replace("-", "_"), value.strip()


#: DMCPendulumConfig's fields that piga-collect sets through its own options, not through --env-option.
NOT_ENV_OPTIONS = ("image_size", "frame_stack", "max_angle", "max_speed", "episode_length")
#: What to give instead of each of them.
OWN_OPTION = {
    "image_size": "the frame side is piga-collect's own option: give --image-size",
    "max_angle": "the reset angle's range is piga-collect's own option: give --max-angle",
    "max_speed": "the reset speed's range is piga-collect's own option: give --max-speed",
    "episode_length": "the sequences' length is piga-collect's own option: give --steps",
    "frame_stack": "a file stores one frame per step; the commands that read it stack frames as their models need",
}


def env_option_keys() -> list[str]:
    """The keys ``--env-option`` takes: DMCPendulumConfig's fields but those of :data:`NOT_ENV_OPTIONS`."""
    import dataclasses

    return sorted(f.name for f in dataclasses.fields(DMCPendulumConfig) if f.name not in NOT_ENV_OPTIONS)


def dmc_config(options: Sequence[tuple[str, str]], own: Mapping[str, str] | None = None,
               **fields: object) -> DMCPendulumConfig:
    """A :class:`DMCPendulumConfig` from ``--env-option KEY=VALUE`` pairs (converted to each field's type) and ``fields``;
    ``own``: for a field of :data:`NOT_ENV_OPTIONS`, the command's own option that sets it (:data:`OWN_OPTION`)."""
    import dataclasses

    known = {f.name: f for f in dataclasses.fields(DMCPendulumConfig)}
    values: dict[str, object] = dict(fields)
    given: dict[str, str] = {}
    for key, text in options:
        if key in given:  # as --effect: the last would silently win
            raise ValueError(f"--env-option {key} is given twice ({given[key]}, then {text}): give it once")
        given[key] = text
        if own is not None and key in own:  # quoted: the key as given (unquoted, the message would show it as its flag)
            raise ValueError(f"--env-option '{key}={text}': {own[key]}")
        if key not in known or key in NOT_ENV_OPTIONS:
            raise ValueError(f"--env-option {key}: unknown for piga/DMCPendulum-v0; known: {', '.join(env_option_keys())}")
        kind = type(getattr(DMCPendulumConfig(), key))
        try:
            if kind is bool:
                if text.lower() not in ("0", "1", "true", "false", "on", "off"):
                    raise ValueError(text)
                values[key] = text.lower() in ("1", "true", "on")
            else:
                values[key] = kind(text)
        except ValueError:
            what = {bool: "true or false (1, 0, on, off)", int: "an integer", float: "a number"}.get(kind, f"a {kind.__name__}")
            raise ValueError(f"--env-option {key}={text}: expected {what}") from None
    try:
        return DMCPendulumConfig(**values)  # type: ignore[arg-type]
    except ValueError as exc:  # the config's words ("DMCPendulumConfig.flip='sideways' ...") in the command's
        message = str(exc)
        named = re.match(r"DMCPendulumConfig\.(\w+)=", message)
        if named and named.group(1) in fields:  # set by the command's own option: "max_speed=...", shown as its flag
            raise ValueError(message.removeprefix("DMCPendulumConfig.")) from None
        raise ValueError(message.replace("DMCPendulumConfig.", "--env-option ")) from None


#: How far above pi a --max-angle is still pi rounded up (3.142, 3.1416), and taken as pi.
PI_ROUNDED = 5e-4


def angle_up_to_pi(text: str) -> float:
    """argparse type of --max-angle: a number, or 'pi'; pi rounded up to a few digits (3.142, 3.1416, as it is often
    written) is taken as pi, where the env refuses anything above it (3.142 was refused, as out of range)."""
    if text.strip().lower() in ("pi", "π"):
        return math.pi
    value = any_float(text)
    return math.pi if math.pi < value <= math.pi + PI_ROUNDED else value


def build_parser() -> ArgumentParser:
    defaults = CollectConfig()
    env = defaults.env
    p = ArgumentParser(
        prog=PROG,
        description="Collect pixel-pendulum sequences with random actions u ~ U(-2, 2) into an HDF5 file "
        "(schema: README, 'Data files').",
    )
    p.add_argument("--out", required=True, type=h5_path,
                   help=f"output {' or '.join(H5_SUFFIXES)} file (written atomically)")
    p.add_argument("--system", choices=SYSTEM_CHOICES, default="pendulum",
                   help="what to collect: the actuated pixel pendulum, or one of the paper's unactuated scenes "
                   "(README, 'Systems') (default %(default)s)")
    for flag, what in SCENE_PARAMETERS.items():
        p.add_argument(flag, type=positive_float, default=None,
                       help=f"{what} (default the scene's; {_scene_defaults(flag)})")
    p.add_argument("--radius", type=positive_float, default=None,
                   help="a scene's ball radius in pixels, or half a digit's side (default the scene's; "
                   f"{', '.join(f'{k} {v}' for k, v in _scene_values('radius').items())})")
    p.add_argument("--colors", type=_color, nargs="+", default=None, metavar="COLOR",
                   help="a scene's object colours, one per object, as matplotlib names them (red, tab:orange, "
                   "'#ffd91a', ...) (default the scene's; blue, green, red for balls, red, green for digits)")
    p.add_argument("--background", type=_color, default=None, metavar="COLOR",
                   help="a ball scene's background colour, as --colors (default the scene's; black)")
    p.add_argument("--half", action="store_true", default=None,
                   help="spring only, the paper's unseen-region data (its Appendix D): the balls stay wholly in the top "
                   "half of the image in every frame of the train and valid sequences and in the first "
                   f"{SceneConfig.half_frames} frames (L + T_pred) of the test sequences, whose later frames take a ball "
                   f"wholly into the bottom half; starts at speed {HALF_SPEED:g} px/s, rejected until they comply")
    p.add_argument("--env", choices=ENV_IDS, default=PIXEL_PENDULUM,
                   help="the env: Gymnasium's pixel pendulum, or dm_control's MuJoCo pendulum through a face-on camera "
                   "(needs piga[dmc]; actions u ~ U(-1, 1), frame dt = action_repeat x 0.02) (default %(default)s)")
    p.add_argument("--env-option", action="append", type=parse_env_option, default=[], metavar="KEY=VALUE",
                   help=f"a field of the DMC pendulum's config, repeatable: {', '.join(env_option_keys())} "
                   "(their meanings and ranges: envs/dmc.py, DMCPendulumConfig)")
    paper = PRESETS["paper"]
    p.add_argument("--preset", choices=sorted(PRESETS), default="default",
                   help=f"'default': small, about a minute on 2 cores; 'paper': {paper.sequences} sequences x "
                   f"{paper.steps} frames, split {format_default(paper.split)}, reset speeds up to "
                   f"{format_default(paper.env.max_speed)}; for a scene, 'default' is {SCENE_PRESETS['default'].sequences} "
                   f"sequences and 'paper' {format_default(SCENE_PRESETS['paper'].split)}, of "
                   f"{', '.join(f'{k} {v}' for k, v in SCENE_STEPS.items())} frames. Explicit options override the preset; "
                   "with --sequences alone, a preset's split in counts is kept as proportions.")
    add_preset_option(p, "--sequences", type=positive_int, default=defaults.sequences, help="number of sequences N")
    add_preset_option(p, "--steps", type=positive_int, default=defaults.steps, help="frames per sequence T, >= 2")
    p.add_argument("--gravity", type=positive_float, default=env.gravity,
                   help="gravity g in m/s² (default %(default)s)")
    p.add_argument("--gravity-mult", type=positive_float, default=env.gravity_mult,
                   help=f"multiplier on gravity; the env simulates gravity x mult, which must lie in [{MIN_GRAVITY:g}, "
                   f"{MAX_GRAVITY:g}] m/s² (default %(default)s)")
    p.add_argument("--actuation-gain", type=positive_float, default=env.actuation_gain,
                   help=f"applied torque = gain x u, gain in [{MIN_ACTUATION_GAIN:g}, {MAX_ACTUATION_GAIN:g}] "
                   "(default %(default)s)")
    add_preset_option(p, "--max-speed", type=any_float, default=env.max_speed,
                      shown=f"{env.max_speed:g} on {PIXEL_PENDULUM}, Gymnasium's; {DMCPendulumConfig.max_speed:g} on "
                      f"{DMC_PENDULUM}, at rest as DMC's; the paper preset uses {PAPER_MAX_SPEED:g} on either",
                      help=f"reset draws theta_dot ~ U(-s, s), s in [0, {PENDULUM_MAX_SPEED:g}] on {PIXEL_PENDULUM} "
                      f"(Gymnasium's speed clip), [0, {MAX_SPEED_TEXT}] on {DMC_PENDULUM} (half a turn per physics step)")
    p.add_argument("--max-angle", type=angle_up_to_pi, default=env.max_angle,
                   help="reset draws theta ~ U(-a, a), a in [0, pi] (default pi; 'pi', or pi rounded up such as "
                   "3.142 or 3.1416, is taken as pi)")
    add_preset_option(p, "--image-size", type=positive_int, default=env.image_size,
                      shown=f"{env.image_size}; a scene's own: {', '.join(f'{k} {v}' for k, v in _scene_sizes().items())}",
                      help="frame side in pixels")
    p.add_argument("--no-torque-arrow", action="store_true", help="hide Gymnasium's torque arrow in the frames")
    p.add_argument("--seed", type=seed_int, default=defaults.seed, help="root seed (default %(default)s)")
    p.add_argument("--workers", type=positive_int, default=defaults.workers,
                   help="parallel env processes (default %(default)s); the data do not depend on it")
    add_preset_option(p, "--split", type=split_type, default=defaults.split,
                      help="train,valid,test as fractions (0.8,0.1,0.1) or counts (5000,500,500)")
    p.add_argument("--effect", dest="effects", action="append", type=_effect, default=[], metavar="NAME=VALUE",
                   help="an unmodelled effect, repeatable (e.g. --effect damping=0.2 --effect delay=2). It changes the "
                   "frames and states; the stored actions stay the commanded u, and the file's attr 'effects' records it. "
                   f"Names: {', '.join(EFFECTS)} (equations: envs/effects.py)")
    p.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _given(args: argparse.Namespace, preset_split: Sequence[float], keys: Sequence[str]) -> dict[str, Any]:
    """The options given explicitly, which override the preset. ``--sequences`` without ``--split`` keeps a
    preset's split in counts (the paper's 5000,500,500) as its proportions of the new number."""
    given = {key: getattr(args, key) for key in keys if getattr(args, key) is not None}
    if "sequences" in given and "split" not in given and sum(preset_split) not in (1, given["sequences"]):
        given["split"] = tuple(x / sum(preset_split) for x in preset_split)
    return given


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    lock_run_folder(args.out)  # a second command writing the same file is refused until this one ends
    written = given_options(parser, argv)  # an option that does not apply is refused at its default value too
    if args.system != "pendulum":
        return _collect_scene(args, argv, written)
    given = [flag for flag in (*SCENE_PARAMETERS, *SCENE_LOOK, "--half") if getattr(args, flag.lstrip("-")) is not None]
    if given:
        scenes = "the spring scene (--system spring)" if given == ["--half"] else \
            f"the scenes (--system {'/'.join(SYSTEM_CHOICES[1:])})"
        raise PigaError(f"{', '.join(given)} {'is' if len(given) == 1 else 'are'} for {scenes}; the pendulum takes "
                        + ("--env-option (mass, length, damping, ...) on the DMC pendulum" if args.env == DMC_PENDULUM
                           else "--gravity and --actuation-gain"))
    preset = PRESETS[args.preset]
    given = _given(args, preset.split, ("sequences", "steps", "split"))
    # explicit options override the preset; the preset's reset speed, where it sets one, applies to either env
    preset_speed = preset.env.max_speed if preset.env.max_speed != PixelPendulumConfig.max_speed else None
    speed = args.max_speed if args.max_speed is not None else preset_speed
    if args.env == DMC_PENDULUM:
        for key, flag in GYMNASIUM_ONLY.items():
            if key in written:
                raise PigaError(f"{flag} is an option of piga/PixelPendulum-v0 only; the DMC pendulum takes --env-option")
        env: PixelPendulumConfig | DMCPendulumConfig = dmc_config(
            args.env_option, OWN_OPTION, image_size=args.image_size or DMCPendulumConfig.image_size, max_angle=args.max_angle,
            **({} if speed is None else {"max_speed": float(speed)}))  # type: ignore[arg-type]
    elif args.env_option:
        raise PigaError(f"--env-option is for --env {DMC_PENDULUM}")
    else:
        env = _pixel_config(args, PixelPendulumConfig.max_speed if speed is None else speed)
    config = replace(preset, env=env, seed=args.seed, workers=args.workers, **given)
    path = collect(config, args.out, overwrite=args.overwrite, command=command_line(PROG, argv),
                   progress=not args.quiet)
    info = inspect_dataset(path)
    effects = getattr(env, "effects", ())
    print(f"wrote {path}: {counted(info.n_sequences, 'sequence')} x {info.steps} frames of {info.image_shape}, "
          f"split {info.split_counts}, g={info.params['g']:g}, actuation_gain={info.params['actuation_gain']:g}"
          + (f", damping={info.params['damping']:g}" if "damping" in info.params else "")
          + (f", effects {format_effects(effects)}" if effects else ""))
    _warn_empty_split(config.split, info.split_counts, args, preset.split)
    if (warning := buried_noise_warning(env)) is not None:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    return 0


def _warn_empty_split(split: Sequence[float], counts: dict[str, int], args: argparse.Namespace,
                      preset_split: Sequence[float]) -> None:
    """:func:`empty_split_warning`, naming a split the user did not give as the preset's (the paper preset's
    5000,500,500 of 6 sequences read "the split 0.833333,0.0833333,0.0833333", which no option had said)."""
    named = None if args.split is not None else (
        f"the {args.preset} preset's split {','.join(f'{x:g}' for x in preset_split)}"
        + ("" if tuple(split) == tuple(preset_split) else f" (as proportions, {','.join(f'{x:.3g}' for x in split)})"))
    if (warning := empty_split_warning(split, counts, named=named)) is not None:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)


def _pixel_config(args: argparse.Namespace, max_speed: float) -> PixelPendulumConfig:
    return PixelPendulumConfig(
        image_size=args.image_size or PixelPendulumConfig.image_size,
        gravity=args.gravity,
        gravity_mult=args.gravity_mult,
        actuation_gain=args.actuation_gain,
        max_angle=args.max_angle,
        max_speed=float(max_speed),
        draw_torque_arrow=not args.no_torque_arrow,
        effects=tuple(args.effects),
    )


#: Scene parameter options -> what they set.
SCENE_PARAMETERS = {"--k": "spring constant k, 1/s^2 (spring, digits-spring)",
                    "--l": "half the spring's rest length l, pixels (spring, digits-spring)",
                    "--g": "gravitational constant g, pixels^3/s^2 (gravity)",
                    "--m": "mass m of every ball (gravity)"}
SYSTEM_CHOICES = ["pendulum", *SCENES]
#: Scene appearance options (a look unlike the default scene's, for held-out checks).
SCENE_LOOK = ("--radius", "--colors", "--background")


def _scene_defaults(flag: str) -> str:
    name = flag.lstrip("-")
    return ", ".join(f"{scene} {values['params'][name]:g}" for scene, values in SCENES.items() if name in values["params"])


def _scene_values(name: str) -> dict[str, Any]:
    """Scene -> its default of a :class:`envs.scenes.SceneConfig` field, e.g. ``radius``."""
    return {scene: format_default(values[name]) for scene, values in SCENES.items()}


def _scene_sizes() -> dict[str, int]:
    return {scene: int(values["image_size"]) for scene, values in SCENES.items()}


def _collect_scene(args: argparse.Namespace, argv: Sequence[str] | None, written: set[str]) -> int:
    """``--system SCENE``: refuses the pendulum's options (those ``written``), builds the scene and collects it."""
    pendulum_only = [GYMNASIUM_ONLY.get(name, f"--{name.replace('_', '-')}")  # (--effect's dest is "effects")
                     for name in ("gravity", "gravity_mult", "actuation_gain", "max_angle", "no_torque_arrow", "effects",
                                  "max_speed", "env", "env_option")
                     if name in written]
    if pendulum_only:
        own_g = "--gravity" in pendulum_only and "g" in SCENES[args.system]["params"]  # the scene's own g is --g
        raise PigaError(f"{', '.join(pendulum_only)}: pendulum option(s), not for --system {args.system}"
                        + (f"; its gravitational constant is --g (default {format_default(SCENES[args.system]['params']['g'])})"
                           if own_g else ""))
    params = {flag.lstrip("-"): getattr(args, flag.lstrip("-")) for flag in SCENE_PARAMETERS
              if getattr(args, flag.lstrip("-")) is not None}
    own = SCENES[args.system]["params"]
    foreign = [f"--{name}" for name in params if name not in own]
    if foreign:  # in the command's words (the scene's own check names parameters, not flags)
        takes = ", ".join(f"--{name}" for name in own) or "none of --k, --l, --g, --m"
        raise PigaError(f"{', '.join(foreign)}: not a parameter of --system {args.system}; it takes {takes}")
    overrides: dict[str, object] = {"params": params}
    if args.image_size is not None:
        overrides["image_size"] = args.image_size
    if args.radius is not None:
        overrides["radius"] = args.radius
    if args.colors is not None:
        if len(args.colors) != SCENES[args.system]["n_objects"]:
            raise PigaError(f"--colors: {args.system} has {SCENES[args.system]['n_objects']} objects; "
                            f"got {len(args.colors)} colour(s)")
        overrides["colors"] = tuple(args.colors)
    if args.background is not None:
        if args.system == "digits-spring":  # black too: the scene's config cannot tell it from its default
            raise PigaError("--background: digits-spring draws its digits over a texture; a background colour is for "
                            "the balls")
        overrides["background"] = args.background
    if args.half:
        overrides["half"] = True
    scene = scene_config(args.system, **overrides)
    given = _given(args, SCENE_PRESETS[args.preset].split, ("sequences", "split"))
    config = replace(SCENE_PRESETS[args.preset], scene=scene, seed=args.seed, workers=args.workers,  # explicit options win
                     steps=SCENE_STEPS[args.system] if args.steps is None else args.steps, **given)
    path = collect_scene(config, args.out, overwrite=args.overwrite, command=command_line(PROG, argv),
                         progress=not args.quiet)
    info = inspect_dataset(path)
    shown = ", ".join(f"{k}={v:g}" for k, v in info.params.items())
    print(f"wrote {path}: {args.system}, {counted(info.n_sequences, 'sequence')} x {info.steps} frames of {info.image_shape}, "
          f"split {info.split_counts}" + (f", {shown}" if shown else ""))
    _warn_empty_split(config.split, info.split_counts, args, SCENE_PRESETS[args.preset].split)
    if (warning := aliasing_warning(scene, load_states(path, "train"))) is not None:  # motion too fast for the frames
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    return 0


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
